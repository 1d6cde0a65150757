"""A lens written for other tools: ST maps (Nuke, Resolve, Unreal's layout), graphics-engine conventions
(OpenLensIO/OpenTrackIO, Unreal, 3DEqualizer), overscan, OpenTrackIO samples (files, UDP)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from . import engines, opentrackio, opentrackio_udp, overscan
    from .engines import MODEL_DU, MODEL_NAMES, MODEL_UD, lens_from_openlensio, openlensio_du_fit, openlensio_radial, tde4_radial_deg4, unreal_spherical
    from .opentrackio import SENSOR_PRESETS, TrackingCamera, encode_sample, lens_object, require_cbor2, track_samples, validate_sample, write_samples
    from .opentrackio_udp import ENCODING_CBOR, ENCODING_JSON, parse_address, send_payloads
    from .overscan import distort_overscanned, overscan_factor, overscan_size, track_overscan, uv_maps
    from .stmap import check_stmap_path, lens_stmap, read_stmap, unreal_stmap, write_stmap

__getattr__, __dir__, __all__ = attach(__name__, __file__)
