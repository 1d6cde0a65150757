"""The allowed values of glradial's string options, in one place: the API checks them with
:func:`check_choice`, the command line offers them as ``choices``."""

from __future__ import annotations

import math
import numbers
from typing import Literal, Union

import numpy as np

InverseMethod = Literal["exact", "drap"]
Fit = Union[Literal["same", "crop", "full"], float]
Direction = Literal["undistort", "distort"]
Interpolation = Literal["nearest", "linear", "cubic"]
Backend = Literal["auto", "gl", "cpu"]
Method = Literal["auto", "net", "lines"]
Alpha = Literal["straight", "premultiplied"]
FieldOrder = Literal["auto", "progressive", "tff", "bff"]
Layout = Literal["nuke", "unreal"]
Origin = Literal["bottom-left", "top-left"]
DistortionModel = Literal["U-D", "D-U"]
ChromaSiting = Literal["left", "center"]

#: how an inverse radial map is computed: bounded Newton ("exact") or the paper's series ("drap")
INVERSES: tuple[str, ...] = ("exact", "drap")
#: the named output scales of a correction (a number is taken as the scale)
FITS: tuple[str, ...] = ("same", "crop", "full")
#: which way a map runs
DIRECTIONS: tuple[str, ...] = ("undistort", "distort")
#: sampling of the source frame
INTERPOLATIONS: tuple[str, ...] = ("nearest", "linear", "cubic")
#: where frames are remapped: GLSL on EGL, cv2.remap, or chosen per process
BACKENDS: tuple[str, ...] = ("auto", "gl", "cpu")
#: values of the estimators' ``method`` argument
METHODS: tuple[str, ...] = ("auto", "net", "lines")
#: values of ``LensEstimate.method`` (which method produced the numbers): the CNN, the line fit, or the
#: joint camera fit to the pitch template (``method="auto"`` where the template fits: glradial.camera.estimator)
SOURCES: tuple[str, ...] = ("net", "lines", "pitch")
#: how a 4-channel frame stores alpha (glradial.remapping.alpha)
ALPHAS: tuple[str, ...] = ("straight", "premultiplied")
#: a video's field order: the stream's ("auto"), or forced (glradial.remapping.fields)
FIELD_ORDERS: tuple[str, ...] = ("auto", "progressive", "tff", "bff")
#: channel layouts of an ST map: Nuke's (RGB, S T in R G) or Unreal Engine's (RGBA, undistort RG, distort BA)
LAYOUTS: tuple[str, ...] = ("nuke", "unreal")
#: pixel origins of an ST map's T (v) coordinate
ORIGINS: tuple[str, ...] = ("bottom-left", "top-left")
#: named camera sensors (``--sensor``); their sizes in mm are glradial.export.opentrackio.SENSOR_PRESETS
SENSORS: tuple[str, ...] = ("2/3-inch",)
#: directions of an OpenLensIO Brown-Conrady model: U-D (undistorted to distorted, glradial's own,
#: exact) or D-U (distorted to undistorted, fitted); the model strings are glradial.export.engines.MODEL_NAMES
DISTORTION_MODELS: tuple[str, ...] = ("U-D", "D-U")
#: horizontal siting of subsampled chroma samples: co-sited with the even luma columns ("left":
#: MPEG-2, H.264, HEVC, BT.601/709 4:2:2) or midway between two ("center": JPEG/MJPEG)
CHROMA_SITINGS: tuple[str, ...] = ("left", "center")
#: what a live stream's shot gets until its lens is sure (glradial.video.live_lens): passed through
#: uncorrected ("pass") or the last sure lens of an earlier shot ("last"); flagged doubtful either way
UNTIL_SURE: tuple[str, ...] = ("pass", "last")
#: where live --auto's shot evidence and fit run: a separate process or a thread
LIVE_WORKERS: tuple[str, ...] = ("process", "thread")


def real_number(name: str, value: object) -> float:
    """Validate a finite real scalar (``bool`` refused) and return it as ``float``; the error names
    ``name`` and the received value."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {number}")
    return number


def check_choice(name: str, value: object, allowed: tuple[str, ...]) -> str:
    """``value`` if it is one of ``allowed``, else ``ValueError`` naming ``name`` and the choices."""
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f"{name} must be one of {', '.join(repr(a) for a in allowed)}, got {value!r}")
    return value


def check_positive(name: str, value: object) -> float:
    """``value`` as a positive finite float, else ``TypeError``/``ValueError`` naming ``name``."""
    number = real_number(name, value)
    if number <= 0.0:
        raise ValueError(f"{name} must be positive, got {number:g}")
    return number
