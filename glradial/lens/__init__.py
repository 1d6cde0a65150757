"""The lens model and its conventions: `Lens` (width-normalised k1, k2, principal point, pixel
aspect), the NumPy twins of the GLSL lens functions, the inverse series, the paper's metrics."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from . import lensfuncs
    from .inverse_series import SERIES_DEGREE, fit_inverse_series
    from .lens import NO_SOURCE, Lens, as_lens, corner_radius, frame_size, lens_to_pixels, pixels_to_lens
    from .metrics import CORNER_RADIUS_16_9, PAPER_SIZE, REPORT_WIDTH, distortion_loss, manifold_k2, max_displacement, max_displacement_px, median_interval
    from .options import (
        BACKENDS,
        DIRECTIONS,
        DISTORTION_MODELS,
        FITS,
        INTERPOLATIONS,
        INVERSES,
        LAYOUTS,
        METHODS,
        ORIGINS,
        SENSORS,
        SOURCES,
        Backend,
        Direction,
        DistortionModel,
        Fit,
        Interpolation,
        InverseMethod,
        Layout,
        Method,
        Origin,
        check_choice,
        check_positive,
        real_number,
    )

__getattr__, __dir__, __all__ = attach(__name__, __file__)
