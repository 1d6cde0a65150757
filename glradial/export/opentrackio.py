"""OpenTrackIO samples (SMPTE RIS-OSVP, protocol 1.0.1) of glradial lenses: one sample per video
frame, checked against the standard's JSON schema (shipped in ``glradial/data`` with its BSD-3
licence), written as JSON lines (or a CBOR sequence) atomically.

A sample carries:

* ``lens.distortion[0]``: the model string (``"Brown-Conrady U-D"``, exact; or a fitted
  ``"Brown-Conrady D-U"``), six ``radial`` coefficients in mm units and ``overscan``
  (:mod:`glradial.export.engines`, :mod:`glradial.export.overscan`);
* ``lens.pinholeFocalLength`` (mm, from the caller: glradial measures distortion, not the field of
  view), ``lens.projectionOffset`` (the principal point, mm) and ``lens.distortionOffset`` (0: the
  distortion is centred on the principal point);
* ``timing``: ``sampleRate`` and ``timecode`` from the video's frame rate and timecode tag (the
  timecode is left out when the video has none), ``sequenceNumber`` = frame index, ``mode``
  ``"external"`` (no PTP clock);
* ``static``: the camera's active sensor size (mm) and resolution (px), its frame rate, the clip's
  duration and ``lens.distortionOverscanMax`` (the largest per-frame overscan);
* ``tracker.status`` and the top-level ``custom.glradial`` object: glradial's own numbers
  (width-normalised k1, k2, the estimate's stated uncertainty in px at 1920 wide, whether its shot
  is doubtful, the shot, the D-U fit error in px).
"""

from __future__ import annotations

import json
import math
import os
import uuid
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..lens.lens import Lens, frame_size
from ..lens.options import SENSORS, real_number
from .engines import MODEL_DU, MODEL_UD, openlensio_du_fit, openlensio_radial, projection_offset_mm
from .overscan import overscan_factor

__all__ = [
    "PROTOCOL", "SENSOR_PRESETS", "TrackingCamera", "lens_object", "track_samples", "validate_sample", "encode_sample",
    "write_samples", "parse_timecode", "timecode_at", "require_cbor2", "frame_sample", "camera_transform",
    "camera_frame_sample",
]

PROTOCOL = {"name": "OpenTrackIO", "version": [1, 0, 1]}

#: named sensors: active area (width, height) in mm. "2/3-inch": the 16:9 image area of a 2/3-inch
#: broadcast camera sensor (11 mm diagonal)
SENSOR_PRESETS = dict(zip(SENSORS, [(9.59, 5.39)], strict=True))


@dataclass(frozen=True)
class TrackingCamera:
    """What a sample says about the camera: frame ``size`` (W, H) px, the active sensor's width (and
    height; default ``width · H / W``) in mm, the pinhole focal length in mm, the frame ``rate``
    (frames per second, exact) and the ``timecode`` of frame 0 (``HH:MM:SS:FF``, ``;`` before FF
    for drop-frame) when known."""

    size: tuple[int, int]
    sensor_width_mm: float
    focal_mm: float
    sensor_height_mm: float | None = None
    rate: Fraction | None = None
    timecode: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", frame_size(self.size))
        for name in ("sensor_width_mm", "focal_mm", "sensor_height_mm"):
            value = getattr(self, name)
            if value is None:
                continue
            if real_number(name, value) <= 0.0:
                raise ValueError(f"{name} must be positive, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.sensor_height_mm is None:
            object.__setattr__(self, "sensor_height_mm", self.sensor_width_mm * self.size[1] / self.size[0])
        if self.rate is not None:
            rate = Fraction(self.rate)
            if rate <= 0:
                raise ValueError(f"rate must be positive, got {self.rate!r}")
            object.__setattr__(self, "rate", rate)
        if self.timecode is not None:
            if self.rate is None:
                raise ValueError("a timecode needs the frame rate (rate)")
            parse_timecode(self.timecode, self.rate)


def _rational(value: Fraction) -> dict:
    return {"num": value.numerator, "denom": value.denominator}


def parse_timecode(text: str, rate: Fraction) -> tuple[int, bool]:
    """``HH:MM:SS:FF`` (``;`` or ``.`` before FF: drop-frame) at ``rate`` -> (frame count from
    00:00:00:00, drop-frame). ``ValueError`` for a malformed timecode or a field out of range."""
    parts = text.replace(";", ":").replace(".", ":").split(":")
    nominal = round(Fraction(rate))
    try:
        hours, minutes, seconds, frames = (int(p) for p in parts)
    except ValueError:
        raise ValueError(f"timecode must be HH:MM:SS:FF, got {text!r}") from None
    if not (0 <= hours < 24 and 0 <= minutes < 60 and 0 <= seconds < 60 and 0 <= frames < max(nominal, 1)):
        raise ValueError(f"timecode {text!r} has a field out of range at {float(rate):g} frames per second")
    drop = ";" in text or "." in text
    count = (hours * 3600 + minutes * 60 + seconds) * nominal + frames
    if drop:
        dropped = nominal // 15  # 2 at 29.97, 4 at 59.94
        total_minutes = 60 * hours + minutes
        count -= dropped * (total_minutes - total_minutes // 10)
    return count, drop


def timecode_at(start: str, index: int, rate: Fraction) -> dict:
    """The OpenTrackIO ``timecode`` object of frame ``index`` of a clip whose frame 0 has timecode
    ``start`` (SMPTE drop-frame counting when ``start`` is drop-frame; wraps at 24 h)."""
    count, drop = parse_timecode(start, rate)
    nominal = round(Fraction(rate))
    count += index
    if drop:
        dropped = nominal // 15
        per_ten, per_minute = nominal * 600 - dropped * 9, nominal * 60 - dropped
        tens, rest = divmod(count, per_ten)
        count += dropped * 9 * tens + (dropped * ((rest - dropped) // per_minute) if rest > dropped else 0)
    count %= nominal * 86400
    seconds, frames = divmod(count, nominal)
    value = {"hours": seconds // 3600, "minutes": seconds // 60 % 60, "seconds": seconds % 60, "frames": frames,
             "frameRate": _rational(Fraction(rate))}
    if drop:
        value["dropFrame"] = True
    return value


def lens_object(lens: Lens, camera: TrackingCamera, *, model: str = MODEL_UD, overscan: float | None = None) -> tuple[dict, float | None]:
    """The sample's ``lens`` object for ``lens`` (``model``: :data:`MODEL_UD` exact or
    :data:`MODEL_DU` fitted) and the fit's largest error in px (None for U-D). ``overscan``: the
    factor to state (default: :func:`overscan_factor` of the lens)."""
    width = camera.sensor_width_mm
    if model == MODEL_UD:
        radial, error = openlensio_radial(lens, width), None
    elif model == MODEL_DU:
        fit = openlensio_du_fit(lens, camera.size, width)
        radial, error = list(fit.coefficients), fit.max_error_px
    else:
        raise ValueError(f"model must be {MODEL_UD!r} or {MODEL_DU!r}, got {model!r}")
    dx, dy = projection_offset_mm(lens, width)
    factor = overscan_factor(lens, camera.size) if overscan is None else float(overscan)
    distortion = {"model": model, "radial": [float(v) for v in radial], "tangential": [0.0, 0.0], "overscan": factor}
    return {
        "distortion": [distortion],
        "distortionOffset": {"x": 0.0, "y": 0.0},
        "pinholeFocalLength": camera.focal_mm,
        "projectionOffset": {"x": dx, "y": dy},
    }, error


def _static(camera: TrackingCamera, n_frames: int | None, overscan_max: float) -> dict:
    width, height = camera.size
    block: dict = {
        "camera": {
            "activeSensorPhysicalDimensions": {"width": camera.sensor_width_mm, "height": camera.sensor_height_mm},
            "activeSensorResolution": {"width": width, "height": height},
        },
        "lens": {"distortionOverscanMax": overscan_max},
    }
    if camera.rate is not None:
        block["camera"]["captureFrameRate"] = _rational(camera.rate)
        if n_frames:
            block["duration"] = _rational(Fraction(n_frames) / camera.rate)
    return block


def _timing(camera: TrackingCamera, index: int) -> dict:
    timing: dict = {"mode": "external", "sequenceNumber": index}
    if camera.rate is not None:
        timing["sampleRate"] = _rational(camera.rate)
    if camera.timecode is not None:
        timing["timecode"] = timecode_at(camera.timecode, index, camera.rate)
    return timing


def _number(values: Sequence[float] | None, index: int) -> float | None:
    if values is None:
        return None
    value = float(values[index])
    return value if np.isfinite(value) else None


def track_samples(
    lenses: np.ndarray | Sequence[Lens],
    camera: TrackingCamera,
    *,
    model: str = MODEL_UD,
    uncertainty_px: Sequence[float] | None = None,
    doubtful: Sequence[bool] | None = None,
    shots: Sequence[int] | None = None,
    source_id: str | None = None,
) -> list[dict]:
    """One validated sample per frame (0, 1, ...) of ``lenses``: :class:`Lens` objects or rows
    ``(k1, k2)`` (centred width-normalised lenses, e.g. a lens track's), with the per-frame
    ``uncertainty_px`` (NaN: unknown), ``doubtful`` flags and ``shots`` where known.
    ``source_id``: a ``urn:uuid:`` shared by the samples (default a new one)."""
    lenses = [row if isinstance(row, Lens) else Lens(*(float(v) for v in row)) for row in lenses]
    if not lenses:
        raise ValueError("lenses must hold at least one frame's lens")
    source_id = source_id or uuid.uuid4().urn
    objects: dict[Lens, tuple[dict, float | None]] = {}
    for lens in lenses:
        if lens not in objects:
            objects[lens] = lens_object(lens, camera, model=model)
    overscan_max = max(obj["distortion"][0]["overscan"] for obj, _ in objects.values())
    static = _static(camera, len(lenses), overscan_max)
    samples = []
    for i, glradial_lens in enumerate(lenses):
        extra = {"uncertainty_px": _number(uncertainty_px, i), "doubtful": bool(doubtful[i]) if doubtful is not None else None,
                 "shot": int(shots[i]) if shots is not None else None}
        samples.append(_sample(glradial_lens, objects[glradial_lens], static, _timing(camera, i), source_id,
                               estimated=uncertainty_px is not None, **extra))
    return samples


def _sample(glradial_lens: Lens, lens_and_error: tuple[dict, float | None], static: dict, timing: dict, source_id: str, *,
            estimated: bool, uncertainty_px: float | None, doubtful: bool | None, shot: int | None) -> dict:
    """One validated sample (``estimated``: the status says the lens is estimated, DOUBTFUL or not)."""
    lens, fit_error = lens_and_error
    extra = {"k1": glradial_lens.k1, "k2": glradial_lens.k2, "uncertainty_px": uncertainty_px, "doubtful": doubtful,
             "shot": shot, "fit_max_error_px": fit_error}
    status = "lens given" if not estimated else ("lens estimated: DOUBTFUL" if doubtful else "lens estimated")
    sample = {
        "protocol": PROTOCOL, "sampleId": uuid.uuid4().urn, "sourceId": source_id, "sourceNumber": 1,
        "static": static, "timing": timing,
        "tracker": {"notes": "glradial lens (custom.glradial: width-normalised k1, k2; uncertainty_px at 1920 wide, "
                             "~p90 of the maximum displacement error)", "recording": False, "status": status},
        "lens": lens, "custom": {"glradial": {k: v for k, v in extra.items() if v is not None}},
    }
    validate_sample(sample)
    return sample


def frame_sample(lens: Lens, camera: TrackingCamera, index: int, source_id: str, *, model: str = MODEL_UD,
                 uncertainty_px: float | None = None, doubtful: bool | None = None, shot: int | None = None,
                 timestamp_s: float | None = None, lens_and_error: tuple[dict, float | None] | None = None) -> dict:
    """The validated sample of one frame of a stream (a live source: no duration, the overscan its
    own lens's), frame ``index`` counted from the stream's first (its ``sequenceNumber`` and, with
    ``camera.timecode`` the first frame's, its timecode). ``timestamp_s``: the frame's presentation
    time on the input's clock (seconds, >= 0), stated as ``timing.sampleTimestamp`` (the stream's
    clock, not PTP time). ``uncertainty_px`` (px at 1920) given: the lens is estimated (status
    "lens estimated", "...: DOUBTFUL" with ``doubtful``). ``lens_and_error``: :func:`lens_object`
    of ``lens`` when the caller caches it (a stream keeps one lens for many frames)."""
    lens_and_error = lens_and_error or lens_object(lens, camera, model=model)
    static = _static(camera, None, lens_and_error[0]["distortion"][0]["overscan"])
    timing = _timing(camera, int(index))
    if timestamp_s is not None:
        timing["sampleTimestamp"] = _timestamp(timestamp_s)
    known = uncertainty_px is not None and math.isfinite(uncertainty_px)
    return _sample(lens, lens_and_error, static, timing, source_id, estimated=uncertainty_px is not None,
                   uncertainty_px=float(uncertainty_px) if known else None,
                   doubtful=None if doubtful is None else bool(doubtful), shot=None if shot is None else int(shot))


def camera_transform(position_m: Sequence[float], pan_tilt_roll_deg: Sequence[float]) -> dict:
    """The OpenTrackIO ``transforms`` entry (id ``"camera"``) of a glradial camera at ``position_m``
    (pitch metres: :mod:`glradial.pitch.template`'s axes, z up) with glradial's pan, tilt, roll
    (degrees, :class:`glradial.camera.model.Camera`). OpenTrackIO: Z up, Y forward at pan = tilt =
    roll = 0, pan counter-clockwise seen from above, tilt up: glradial's pan (toward +x) and tilt
    (down) change sign."""
    x, y, z = (float(v) for v in position_m)
    pan, tilt, roll = (float(v) for v in pan_tilt_roll_deg)
    return {"translation": {"x": x, "y": y, "z": z}, "rotation": {"pan": -pan, "tilt": -tilt, "roll": roll}, "id": "camera"}


def camera_frame_sample(fields: dict, camera: TrackingCamera, index: int, source_id: str, *, model: str = MODEL_UD,
                        timestamp_s: float | None = None, lens_objects: dict | None = None) -> dict:
    """The validated sample of one frame of a stream whose whole camera is tracked: ``fields`` the
    frame's fields as ``glradial calibrate --json`` writes them (``k1``, ``k2``, ``focal`` in image
    widths, ``position_m``, ``pan_deg``/``tilt_deg``/``roll_deg``, ``homography``, ``doubtful``,
    ``reason``, ``uncertainty_px``; without ``k1`` the frame has no camera), ``camera`` the sensor,
    rate and timecode (its ``focal_mm`` is replaced by the measured one). The sample carries the
    transform, ``lens.pinholeFocalLength`` (mm) and the distortion where the frame has a camera,
    the timing as :func:`frame_sample`'s, ``tracker.status`` ``"camera tracked"`` or ``"camera
    tracked: DOUBTFUL (reason)"``, and ``fields`` whole in ``custom.glradial``. ``lens_objects``: a
    dict the caller keeps to cache the lens objects (a stream keeps one lens for many frames)."""
    timing = _timing(camera, int(index))
    if timestamp_s is not None:
        timing["sampleTimestamp"] = _timestamp(timestamp_s)
    doubtful = bool(fields.get("doubtful", True))
    sample: dict = {
        "protocol": PROTOCOL, "sampleId": uuid.uuid4().urn, "sourceId": source_id, "sourceNumber": 1, "timing": timing,
        "tracker": {"notes": "glradial camera tracked from the pitch markings (custom.glradial: calibrate --json fields; "
                             "uncertainty_px at 1280 wide, ~p90 of the keypoint RMS)", "recording": False,
                    "status": f"camera tracked: DOUBTFUL ({fields.get('reason')})" if doubtful else "camera tracked"},
        "custom": {"glradial": {k: v for k, v in fields.items() if v is not None}},
    }
    if "k1" in fields:
        lens = Lens(fields["k1"], fields["k2"])
        cache = lens_objects if lens_objects is not None else {}
        if (lens, model) not in cache:
            cache[(lens, model)] = lens_object(lens, camera, model=model)[0]
        sample["lens"] = {**cache[(lens, model)], "pinholeFocalLength": float(fields["focal"]) * camera.sensor_width_mm}
        sample["static"] = _static(camera, None, sample["lens"]["distortion"][0]["overscan"])
        sample["transforms"] = [camera_transform(fields["position_m"], (fields["pan_deg"], fields["tilt_deg"], fields["roll_deg"]))]
    validate_sample(sample)
    return sample


def _timestamp(seconds_in: float) -> dict:
    """OpenTrackIO ``sampleTimestamp`` of a presentation time (s >= 0, the stream's clock)."""
    if not seconds_in >= 0:
        raise ValueError(f"timestamp_s must be >= 0 seconds, got {seconds_in!r}")
    seconds = int(seconds_in)
    return {"seconds": seconds, "nanoseconds": min(int(round((seconds_in - seconds) * 1e9)), 999_999_999)}


@lru_cache(maxsize=1)
def _validator():
    from importlib import resources

    import jsonschema

    schema = json.loads(resources.files("glradial.data").joinpath("opentrackio_schema.json").read_text())
    return jsonschema.Draft202012Validator(schema)


def validate_sample(sample: dict) -> None:
    """``ValueError`` naming the first place where ``sample`` breaks the OpenTrackIO schema."""
    error = next(iter(_validator().iter_errors(sample)), None)
    if error is not None:
        where = "/".join(str(p) for p in error.absolute_path) or "(the sample)"
        raise ValueError(f"OpenTrackIO sample breaks the schema at {where}: {error.message}")


def require_cbor2():
    """The ``cbor2`` module, or ``RuntimeError`` saying how to install it."""
    try:
        import cbor2
    except ImportError:
        raise RuntimeError("CBOR output needs the cbor2 package: pip install cbor2 (or write JSON, without --cbor)") from None
    return cbor2


def encode_sample(sample: dict, cbor: bool = False) -> bytes:
    """A sample's payload: compact UTF-8 JSON, or CBOR (cbor2, an optional dependency)."""
    if cbor:
        return require_cbor2().dumps(sample)
    return json.dumps(sample, separators=(",", ":"), allow_nan=False).encode("utf-8")


def write_samples(path: str | os.PathLike, samples: Iterable[dict], cbor: bool = False) -> Path:
    """Write samples atomically: JSON lines (one sample per line), or with ``cbor`` a CBOR sequence
    (RFC 8742: the samples' CBOR items one after another)."""
    from ..media.atomic import atomic_write_bytes, check_output_folder

    target = check_output_folder(path)
    separator = b"" if cbor else b"\n"
    return atomic_write_bytes(target, b"".join(encode_sample(s, cbor) + separator for s in samples))
