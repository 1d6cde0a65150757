"""Lens correction and distortion of whole frames: GLSL shaders (``correct.frag``,
``distort.frag``) or the same maps through ``cv2.remap``.

Convention (docs/DESIGN.md): a lens is ``(k1, k2)`` in width-normalised lens units, principal point at the
frame centre ``((W-1)/2, (H-1)/2)``, forward model ``p_d = p_u (1 + k1 r_u² + k2 r_u⁴)``; a
:class:`glradial.Lens` may move the principal point and set a pixel aspect (``cx``, ``cy``,
``pixel_aspect``; lens points and the fit scale are then taken about the principal point).

* The lens: a :class:`glradial.Lens` (or any subclass, e.g. an estimate) as ``correct(frame, lens)``,
  or the coefficients as ``correct(frame, k1, k2)`` (``k2`` defaults to 0 then). A Lens together with
  ``k2`` is a ``TypeError``.

* :func:`correct` (undistortion): output pixel ``q`` shows the undistorted point ``p_u = s q`` and
  samples the input at ``p_d = P(p_u)``; no inverse is needed. With ``fit="same"`` it equals
  ``cv2.undistort(frame, K, (k1, k2, 0, 0))`` with ``K = [[W, 0, (W-1)/2], [0, W, (H-1)/2], [0, 0, 1]]``.
* :func:`distort`: output pixel ``q`` is the distorted point ``p_d = q`` and samples the undistorted
  input at ``P⁻¹(q) / s`` (``inverse="exact"``: bounded Newton, or ``"drap"``: the paper's
  polynomial). ``distort`` with scale ``s`` is the inverse of ``correct`` with the same ``s``.
* ``s`` is :func:`fit_scale` (see :meth:`glradial.Lens.fit_scale`): ``"same"`` -> 1, ``"crop"`` ->
  every output pixel has a source, ``"full"`` -> the whole input stays visible, or a positive number
  taken as ``s``. A distortion's "crop" is a correction's "full": ``correct(distort(x, fit="crop"),
  fit="full") ≈ x``.
* Frames: NumPy ``H×W`` or ``H×W×C`` with ``C`` in (1, 3, 4); dtype uint8, uint16, float32 or
  float64; the result has the same shape and dtype, channels in the same order (nothing is swapped).
  float64 frames are computed in float32 on both backends (GL textures are float32; the CPU path
  does the same so both agree) and returned as float64: values keep float32's ~7 significant
  digits, and values beyond float32's range are a ``ValueError``. A batch ``N×H×W×C`` (4-D) is
  corrected frame by frame with the same lens in one call (the result has the batch's shape);
  a batch of single-channel frames is ``N×H×W×1`` (a 3-D array is always one ``H×W×C`` frame).
* ``fill``: the value of output pixels with no source, a scalar or one value per channel, in the
  frame's units. No source: the source position lies outside the input's area (pixel coordinates
  outside ``[-0.5, W-0.5] × [-0.5, H-0.5]``) or, for distortion, no undistorted point maps there.
  Such pixels get ``fill`` exactly; every other pixel is interpolated with taps beyond the edge
  repeating the edge pixel (``BORDER_REPLICATE``), so the fill never bleeds into valid pixels
  (OpenCV's ``cv2.undistort`` instead blends the outermost ring with black).
* ``alpha``: a 4-channel frame is RGBA with alpha last; ``"straight"`` (default) frames are
  interpolated premultiplied and returned straight, ``"premultiplied"`` frames (and 4 channels that
  are not colour and alpha) are resampled channel by channel (:mod:`glradial.remapping.alpha`). Textures given
  to :meth:`Remapper.render_texture` are resampled as stored: give it premultiplied ones.
* A lens and fit that would leave most of the output empty (under :data:`MIN_COVERAGE` of its pixels
  with a source) is a ``ValueError`` naming the lens, on every backend (:func:`check_coverage`).
* ``interpolation``: ``"nearest"``, ``"linear"`` (bilinear) or ``"cubic"`` (Keys, a = -0.75, the
  kernel of OpenCV's ``INTER_CUBIC``).
* ``backend``: ``"gl"`` (the shaders, through :class:`Remapper` on the thread's EGL context),
  ``"cpu"`` (:meth:`glradial.Lens.maps`, cached, then ``cv2.remap``: integer frames from OpenCV's
  fixed-point maps, positions rounded to 1/32 px; float frames with ``"linear"`` from the float32
  maps themselves, exact bilinear at the float32 position), ``"auto"``: ``"cpu"`` when the GL renderer is a software rasteriser (Mesa llvmpipe,
  softpipe, ...), when no EGL context can be made, or when the frame exceeds the GL texture limit;
  ``"gl"`` otherwise. A CPU round trip through llvmpipe is slower than ``cv2.remap`` on the same cores.
"""

from __future__ import annotations

import functools
import math
import numbers
import os
import threading
from typing import Sequence

import cv2
import moderngl
import numpy as np

from ..gl import egl
from ..gl.shaderlib import TEXTURE_FORMATS as _TEXTURE_DTYPES
from ..gl.shaderlib import build_program
from ..lens import doubt, lensfuncs
from ..lens.lens import Lens, Plane, frame_size
from ..lens.options import (
    BACKENDS,
    DIRECTIONS,
    INTERPOLATIONS,
    INVERSES,
    Backend,
    Direction,
    Fit,
    Interpolation,
    InverseMethod,
    check_choice,
    check_positive,
)
from .alpha import Alpha, remap_with_alpha

#: OpenCV's interpolation flag of each ``interpolation`` name (the CPU paths of RGB frames and planes)
CV_INTERPOLATION = {"nearest": cv2.INTER_NEAREST, "linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}
_GLSL_INTERPOLATION = {"nearest": "SAMPLING_NEAREST", "linear": "SAMPLING_LINEAR", "cubic": "SAMPLING_CUBIC"}
#: cv2.remap writes at most SHRT_MAX - 1 pixels per side.
CPU_MAX_SIDE = 32766
#: maps kept by the CPU backend (a 1080p entry is ~12 MB with fixed-point maps, ~17 MB with float
#: maps; a YUV frame's lens takes one entry per distinct plane lattice: 2 for 4:2:0).
CPU_MAP_CACHE_SIZE = 8
#: the shaders compute in float32: the largest finite value and the smallest normal one
FLOAT32_MAX = float(np.finfo(np.float32).max)
FLOAT32_TINY = float(np.finfo(np.float32).tiny)


# -- validation ---------------------------------------------------------------------------------
def _check_frame(frame: object) -> tuple[int, int, int]:
    """Validate a frame and return ``(H, W, C)``."""
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"frame must be a NumPy array, got {type(frame).__name__}")
    if frame.dtype not in _TEXTURE_DTYPES:
        raise TypeError(f"frame dtype must be uint8, uint16 or float32, got {frame.dtype}")
    if frame.ndim == 2:
        height, width = frame.shape
        channels = 1
    elif frame.ndim == 3:
        height, width, channels = frame.shape
    else:
        raise ValueError(f"frame must be H×W or H×W×C with C in (1, 3, 4), got a {frame.ndim}-D array of shape {frame.shape}")
    if height == 0 or width == 0:
        raise ValueError(f"frame is empty: shape {frame.shape}")
    if channels not in (1, 3, 4):
        raise ValueError(f"frame must be H×W×C with C in (1, 3, 4), got shape {frame.shape} ({channels} channels)")
    if frame.dtype.kind == "f":
        low, high = float(frame.min()), float(frame.max())  # NaN or ±inf anywhere shows up here
        if not (math.isfinite(low) and math.isfinite(high)):
            raise ValueError(
                f"frame contains NaN or infinite pixels (min {low}, max {high}); interpolation would spread "
                f"them to their neighbours: replace them first (e.g. np.nan_to_num)"
            )
    return height, width, channels


def _check_fill(fill: object, channels: int, dtype: np.dtype) -> tuple[float, ...]:
    """Fill value(s) in frame units -> a tuple of ``channels`` floats."""
    values = fill if isinstance(fill, (list, tuple, np.ndarray)) else [fill]
    values = list(np.asarray(values).ravel()) if isinstance(values, np.ndarray) else list(values)
    if len(values) == 1:
        values = values * channels
    if len(values) != channels:
        raise ValueError(f"fill must be a scalar or {channels} values (one per channel), got {fill!r}")
    out = []
    for value in values:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.integer, np.floating)):
            raise TypeError(f"fill must be real numbers, got {fill!r}")
        number = float(value)
        if not math.isfinite(number):
            raise ValueError(f"fill must be finite, got {fill!r}")
        if dtype.kind == "u" and not 0 <= number <= np.iinfo(dtype).max:
            raise ValueError(f"fill {fill!r} is outside the range of {dtype} (0..{np.iinfo(dtype).max})")
        if abs(number) > FLOAT32_MAX:
            raise ValueError(f"fill {fill!r} is beyond float32 range (±{FLOAT32_MAX:.4g})")
        out.append(number)
    return tuple(out)


def _lens(lens: object, k2: object = None) -> Lens:
    """The lens of ``correct(frame, lens)`` or ``correct(frame, k1, k2)`` (``k2`` None -> 0)."""
    if isinstance(lens, Lens):
        if k2 is not None:
            raise TypeError(
                f"give a Lens or the coefficients k1, k2, not both: got {type(lens).__name__} "
                f"{lens!r} and k2={k2!r}"
            )
        return lens
    if not isinstance(lens, (numbers.Real, np.floating, np.integer)) or isinstance(lens, (bool, np.bool_)):
        raise TypeError(f"k1 must be a real number (or lens a glradial.Lens), got {type(lens).__name__} {lens!r}")
    return Lens(lens, 0.0 if k2 is None else k2)  # type: ignore[arg-type]


def check_numeric_policy(lens: Lens, size: tuple[int, int], direction: str, scale: float, scale_name: str = "fit") -> None:
    """The numeric policy both backends share, so that they give the same answer or the same error.

    The shaders compute in float32, the CPU maps in float64. Refused with a ``ValueError`` naming
    the argument: a coefficient beyond float32 range; a scale outside float32's normal range; a lens
    and scale whose map overflows float32 on the frame, i.e. where ``r_max (1 + 5 |k1| r_max² +
    5 |k2| r_max⁴) W`` (a bound on the source position in pixels and on the Newton slope, with
    ``r_max`` the largest undistorted radius the frame uses) or a Drap-Lefevre inverse coefficient
    (the Newton seed) exceeds float32's largest value. Real lenses are many orders of magnitude
    inside these bounds (|k| < 10, scales 0.1..10). Results are cached per lens, size, direction
    and scale (a video repeats them; the inverse costs ~60 µs).
    """
    problem = _numeric_problem(lens.k1, lens.k2, lens.frame_radius(size), size, direction, scale, scale_name)
    if problem is not None:
        raise ValueError(problem)


@functools.lru_cache(maxsize=64)
def _numeric_problem(k1: float, k2: float, corner: float, size: tuple[int, int], direction: str, scale: float,
                     scale_name: str) -> str | None:
    """The message of :func:`check_numeric_policy`'s error, or None (``corner``: the largest radius
    of the frame, measured from the principal point, in lens units)."""
    lens = Lens(k1, k2)
    try:
        _check_numbers(lens, corner, size, direction, scale, scale_name)
    except ValueError as err:
        return str(err)
    return None


def _check_numbers(lens: Lens, corner: float, size: tuple[int, int], direction: str, scale: float, scale_name: str) -> None:
    for name, value in (("k1", lens.k1), ("k2", lens.k2)):
        if abs(value) > FLOAT32_MAX:
            raise ValueError(f"{name}={value:g} is beyond float32 range (±{FLOAT32_MAX:.4g}), in which the GL shaders compute")
    if not FLOAT32_TINY <= scale <= FLOAT32_MAX:
        raise ValueError(f"{scale_name} scale {scale:g} is outside float32's normal range [{FLOAT32_TINY:.4g}, {FLOAT32_MAX:.4g}]")
    width, _ = size
    if direction == "undistort":
        r_max = scale * corner
    else:
        for index, b in enumerate(lensfuncs.drap_coefficients(lens.k1, lens.k2), start=1):
            if not abs(b) <= FLOAT32_MAX:
                raise ValueError(
                    f"lens k1={lens.k1:g}, k2={lens.k2:g}: its inverse's coefficient b{index}={b:g} overflows float32; "
                    f"the coefficients are far outside any real lens"
                )
        r_u = float(lens.inverse_radius(corner))
        r_max = (r_u if math.isfinite(r_u) else lens.fold_radius()) / scale
    bound = r_max * (1.0 + 5.0 * (abs(lens.k1) * r_max * r_max + abs(lens.k2) * r_max**4 if r_max < 1e60 else math.inf)) * width
    if not bound <= FLOAT32_MAX:
        raise ValueError(
            f"{scale_name} scale {scale:g} with lens k1={lens.k1:g}, k2={lens.k2:g} on a {size[0]}×{size[1]} frame "
            f"overflows float32 (source positions up to ~{bound:.3g} pixels): use a smaller {scale_name} or smaller coefficients"
        )


def checked_scale(lens: Lens, size: tuple[int, int], direction: str, fit: Fit, scale: float | None = None) -> float:
    """The scale a remap of a ``size`` frame uses (``lens.fit_scale`` of ``fit``, or ``scale`` when
    given), after the checks every backend makes: :func:`check_numeric_policy` and the fold-over
    (:meth:`Lens.check_frame`)."""
    if scale is not None:
        s = check_positive("scale", scale)
    elif isinstance(fit, str):  # "crop"/"full" solve for the lens's inverse: cached like the policy
        s = _fit_scale(lens.k1, lens.k2, lens.cx, lens.cy, lens.pixel_aspect, size, fit, direction)
    else:
        s = lens.fit_scale(size, fit, direction)
    check_numeric_policy(lens, size, direction, s, "fit" if scale is None else "scale")
    lens.check_frame(size, s)
    check_coverage(lens, size, direction, s, fit if scale is None else s)
    return s


#: the smallest fraction of a remap's output pixels that must have a source. Below it the output
#: is mostly ``fill``: a lens far outside any real one (``k1=5``: 47% on a 16:9 frame with fit
#: "same", ``k1=1e6``: 0%). Real lenses keep far more: 68% or more on every fit across the
#: estimator's training range (k1 in [-0.7, 0.3], k2 up to 0.2), 100% with fit "crop".
MIN_COVERAGE = 0.5
#: the output is sampled on a grid this many points wide (the fraction is then known to ~1%)
COVERAGE_GRID = 96


def check_coverage(lens: Lens, size: tuple[int, int], direction: str, scale: float, fit: object = "same") -> float:
    """The fraction of the output of a ``size`` frame whose pixels have a source; ``ValueError``
    naming the lens and ``fit`` when it is below :data:`MIN_COVERAGE` (mostly empty output)."""
    covered = _coverage(lens.k1, lens.k2, lens.cx, lens.cy, lens.pixel_aspect, size, direction, scale)
    if covered < MIN_COVERAGE:
        raise ValueError(
            f"lens k1={lens.k1:g}, k2={lens.k2:g} with fit={fit!r} leaves {1 - covered:.0%} of the {size[0]}×{size[1]} "
            f"output with no source (at least {MIN_COVERAGE:.0%} must show the input): the coefficients are far "
            f"outside a real lens (width-normalised: image width = 1; broadcast lenses have |k1| < 1)"
        )
    return covered


@functools.lru_cache(maxsize=64)
def _coverage(k1: float, k2: float, cx: float, cy: float, pixel_aspect: float, size: tuple[int, int], direction: str,
              scale: float) -> float:
    """:func:`check_coverage`'s fraction, on a grid of at most :data:`COVERAGE_GRID` points wide with
    the frame's aspect (lens units do not depend on the resolution)."""
    width, height = size
    grid_w = min(width, COVERAGE_GRID)
    grid = (grid_w, max(1, round(height * grid_w / width)))
    map_x, map_y = Lens(k1, k2, cx, cy, pixel_aspect).maps(grid, direction, scale=scale)
    inside = (map_x >= -0.5) & (map_x <= grid[0] - 0.5) & (map_y >= -0.5) & (map_y <= grid[1] - 0.5)
    return float(np.mean(inside))


@functools.lru_cache(maxsize=64)
def _fit_scale(k1: float, k2: float, cx: float, cy: float, pixel_aspect: float, size: tuple[int, int], fit: str,
               direction: str) -> float:
    """:meth:`Lens.fit_scale` of a named fit, cached by the lens's numbers: a video or a batch asks
    for the same scale every frame, and ``"crop"``/``"full"`` cost a Newton inverse (~0.1 ms)."""
    return Lens(k1, k2, cx, cy, pixel_aspect).fit_scale(size, fit, direction)


def fit_scale(
    lens: Lens | tuple[float, float],
    size: tuple[int, int],
    fit: Fit = "same",
    direction: Direction = "undistort",
) -> float:
    """The scale ``s`` a fit uses on a ``(W, H)`` frame (closed form, see
    :meth:`glradial.Lens.fit_scale`): correction shows ``p_u = s q`` at output lens point ``q``,
    distortion samples the input at ``P⁻¹(q) / s``. ``s > 1`` zooms out, ``s < 1`` zooms in.

    Args:
        lens: a :class:`glradial.Lens` or ``(k1, k2)`` (width-normalised).
        size: the frame's ``(W, H)`` in pixels.
        fit: ``"same"`` (1), ``"crop"`` (no empty border), ``"full"`` (the whole frame kept) or a number.
        direction: ``"undistort"`` (what :func:`correct` uses) or ``"distort"``.

    Returns:
        The scale ``s`` (dimensionless, > 0).

    Raises:
        TypeError: ``lens`` is neither a Lens nor a pair of numbers.
        ValueError: a bad size, fit or direction, or a lens that folds over inside the frame.

    Example:
        >>> import glradial
        >>> glradial.fit_scale((-0.2, 0.0), (1920, 1080))
        1.0
        >>> round(glradial.fit_scale((-0.2, 0.0), (1920, 1080), "full"), 4)  # the whole input shown
        1.0838
    """
    if not isinstance(lens, Lens):
        try:
            k1, k2 = lens  # type: ignore[misc]
        except (TypeError, ValueError):
            raise TypeError(f"lens must be a Lens or (k1, k2), got {lens!r}") from None
        lens = _lens(k1, k2)
    return lens.fit_scale(size, fit, direction)


# -- GL backend -----------------------------------------------------------------------------------
class Remapper:
    """Owns the GL programs, textures and framebuffer that correct and distort frames.

    ``Remapper()`` makes its own headless EGL context (released with it); ``Remapper(ctx)`` works on
    a caller's moderngl context (left alone on release), e.g. to embed in a graphics pipeline with
    :meth:`render_texture`, which never leaves the GPU. Programs are compiled on first use per
    (direction, interpolation, inverse); the source/target textures and framebuffer are kept while
    the frame size, channel count and dtype stay the same, and frames are read back into a NumPy
    array (``out=`` to reuse one). Use on the thread that made the context; ``release()`` or
    ``with Remapper() as r:`` frees everything.

    Args:
        ctx: a caller's ``moderngl.Context`` to work on, or ``None`` (default) for its own headless
            EGL context.

    Raises:
        TypeError: ``ctx`` is neither ``None`` nor a moderngl context.
        glradial.GLUnavailableError: no OpenGL 3.3 context can be made (``ctx=None``).

    Example:
        >>> import numpy as np, glradial
        >>> frame = np.full((36, 64, 3), 200, np.uint8)
        >>> with glradial.Remapper() as remapper:
        ...     out = remapper.correct(frame, glradial.Lens(-0.2, 0.0))
        >>> out.shape, out.dtype, int(out[18, 32, 0])  # the centre does not move
        ((36, 64, 3), dtype('uint8'), 200)
    """

    def __init__(self, ctx: moderngl.Context | None = None) -> None:
        if ctx is not None and not isinstance(ctx, moderngl.Context):
            raise TypeError(f"ctx must be a moderngl.Context or None, got {type(ctx).__name__} {ctx!r}")
        self._owns_context = ctx is None
        self.ctx: moderngl.Context = egl.create_context() if ctx is None else ctx
        self._owner = egl.GLOwner("Remapper", self.ctx)
        self._owner.enter()
        self.max_texture_size = egl.max_texture_size(self.ctx)
        self._programs: dict[tuple[str, str, str], tuple[moderngl.Program, moderngl.VertexArray]] = {}
        self._frame_key: tuple[int, int, int, np.dtype] | None = None
        self._source: moderngl.Texture | None = None
        self._target: moderngl.Texture | None = None
        self._fbo: moderngl.Framebuffer | None = None
        self._released = False

    # -- public API ------------------------------------------------------------------------------
    def correct(
        self,
        frame: np.ndarray,
        lens: Lens | float,
        k2: float | None = None,
        *,
        fit: Fit = "same",
        interpolation: Interpolation = "linear",
        fill: float | Sequence[float] = 0,
        out: np.ndarray | None = None,
        alpha: Alpha = "straight",
    ) -> np.ndarray:
        """Undistort one ``frame`` (uint8, uint16 or float32) on the GPU with a :class:`Lens` or
        ``k1, k2``; see the module docstring. ``out``: an array of the frame's shape and dtype to read
        the result into (returned). ``alpha``: the convention of a 4-channel frame
        (:mod:`glradial.remapping.alpha`). Batches and float64: :func:`correct`."""
        return self._remap_alpha(frame, _lens(lens, k2), "undistort", fit, interpolation, fill, "exact", out, alpha)

    def distort(
        self,
        frame: np.ndarray,
        lens: Lens | float,
        k2: float | None = None,
        *,
        fit: Fit = "same",
        interpolation: Interpolation = "linear",
        fill: float | Sequence[float] = 0,
        inverse: InverseMethod = "exact",
        out: np.ndarray | None = None,
        alpha: Alpha = "straight",
    ) -> np.ndarray:
        """Apply the lens (a :class:`Lens` or ``k1, k2``) to one undistorted ``frame`` on the GPU;
        see the module docstring (``alpha``: :mod:`glradial.remapping.alpha`)."""
        return self._remap_alpha(frame, _lens(lens, k2), "distort", fit, interpolation, fill, inverse, out, alpha)

    def render_texture(
        self,
        source: moderngl.Texture,
        target: moderngl.Framebuffer,
        lens: Lens | float,
        k2: float | None = None,
        *,
        direction: Direction = "undistort",
        fit: Fit = "same",
        scale: float | None = None,
        interpolation: Interpolation = "linear",
        fill: Sequence[float] = (0.0, 0.0, 0.0, 0.0),
        inverse: InverseMethod = "exact",
        viewport: tuple[int, int, int, int] | None = None,
        texture_unit: int = 0,
    ) -> None:
        """Draw ``source`` corrected (``direction="undistort"``) or distorted into ``target``,
        both on this Remapper's context; nothing goes through the CPU.

        ``source`` is a normalized or float 2-D texture (``sampler2D``; not an integer texture).
        Convention: texture row 0 is the top of the image and is drawn to framebuffer row 0
        (``gl_FragCoord.y = 0.5``), no flip; a window's default framebuffer shows row 0 at the
        bottom. ``viewport = (x, y, width, height)`` in ``target`` pixels (default: all of it) is
        the output frame; its size sets the fit and the fold-over check. ``fill`` is RGBA in
        texture units (0..1 for normalized textures). Texels are interpolated as stored: a key and
        fill must be premultiplied to keep their edges free of fringes. ``scale`` overrides ``fit``. The caller's
        blend, scissor and other state apply; the sampler state of ``source`` is ignored (taps
        are texelFetch).
        """
        self._check_alive()
        if not isinstance(source, moderngl.Texture):
            raise TypeError(f"source must be a moderngl.Texture, got {type(source).__name__} {source!r}")
        if not isinstance(target, moderngl.Framebuffer):
            raise TypeError(f"target must be a moderngl.Framebuffer, got {type(target).__name__} {target!r}")
        lens = _lens(lens, k2)
        direction = check_choice("direction", direction, DIRECTIONS)
        interpolation = check_choice("interpolation", interpolation, INTERPOLATIONS)
        inverse = check_choice("inverse", inverse, INVERSES)
        units = int(self.ctx.info["GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS"])
        if isinstance(texture_unit, (bool, np.bool_)) or not isinstance(texture_unit, (numbers.Integral, np.integer)):
            raise TypeError(f"texture_unit must be an integer, got {type(texture_unit).__name__} {texture_unit!r}")
        if not 0 <= texture_unit < units:
            raise ValueError(f"texture_unit must be in 0..{units - 1} (GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS), got {texture_unit}")
        if viewport is None:
            viewport = (0, 0, target.width, target.height)
        try:
            x0, y0, width, height = (v for v in viewport)
        except (TypeError, ValueError):
            raise TypeError(f"viewport must be (x, y, width, height) integers, got {viewport!r}") from None
        for name, value in (("x", x0), ("y", y0)):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
                raise TypeError(f"viewport {name} must be an integer, got {value!r}")
        size = frame_size((width, height))
        x0, y0, width, height = int(x0), int(y0), size[0], size[1]
        s = checked_scale(lens, size, direction, fit, scale)
        rgba = _check_fill(fill, 4, np.dtype(np.float32))
        self._draw(source, target, (x0, y0, width, height), lens, direction, s, interpolation, inverse, rgba, texture_unit)

    def release(self) -> None:
        """Free every GL object (and the context if this Remapper made it). Idempotent. Only on the
        thread that made it (``RuntimeError`` elsewhere)."""
        if self._released:
            return
        self._owner.enter()
        self._release_frame_objects()
        for program, vao in self._programs.values():
            egl.release_objects(self.ctx, vao, program)
        self._programs.clear()
        if self._owns_context:
            egl.destroy_context(self.ctx)
        self._released = True

    def __enter__(self) -> "Remapper":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    @property
    def texture_ids(self) -> tuple[int, int] | None:
        """GL names of the current source and target textures (None before the first frame)."""
        if self._source is None or self._target is None:
            return None
        return self._source.glo, self._target.glo

    # -- internals -------------------------------------------------------------------------------
    def _remap_alpha(self, frame, lens, direction, fit, interpolation, fill, inverse, out, alpha) -> np.ndarray:
        """:meth:`_remap` in ``alpha``'s convention (:func:`glradial.remapping.alpha.remap_with_alpha`)."""
        result = remap_with_alpha(frame, fill, alpha, lambda work, fill_values: self._remap(
            work, lens, direction, fit, interpolation, fill_values, inverse, out if work is frame else None))
        if out is not None and result is not out:
            if not (isinstance(out, np.ndarray) and out.shape == result.shape and out.dtype == result.dtype):
                raise ValueError(f"out must be a C-contiguous {result.dtype} array of shape {result.shape}")
            out[...] = result
            return out
        return result

    def _check_alive(self) -> None:
        """``RuntimeError`` once released or off the owning thread; then make this Remapper's
        context the thread's current one (:meth:`egl.GLOwner.enter`): creating another context on
        the thread (e.g. a second ``Remapper()``) switches EGL's current context, and drawing with a
        non-current context reads back garbage with GL_INVALID_OPERATION."""
        if self._released:
            raise RuntimeError("this Remapper has been released")
        self._owner.enter()

    def _program(self, direction: str, interpolation: str, inverse: str) -> tuple[moderngl.Program, moderngl.VertexArray]:
        key = (direction, interpolation, inverse)
        entry = self._programs.get(key)
        if entry is None:
            defines: dict[str, object] = {"SAMPLING_INTERPOLATION": _GLSL_INTERPOLATION[interpolation]}
            if direction == "distort":
                defines["LENS_INVERSE_EXACT"] = int(inverse == "exact")
            fragment = "correct.frag" if direction == "undistort" else "distort.frag"
            program = build_program(self.ctx, "fullscreen.vert", fragment, defines)
            entry = (program, self.ctx.vertex_array(program, []))
            self._programs[key] = entry
        return entry

    def _release_frame_objects(self) -> None:
        egl.release_objects(self.ctx, self._fbo, self._target, self._source)
        self._fbo = self._target = self._source = None
        self._frame_key = None

    def _frame_objects(self, width: int, height: int, channels: int, dtype: np.dtype) -> None:
        key = (width, height, channels, dtype)
        if key == self._frame_key:
            return
        self._release_frame_objects()
        texture_dtype = _TEXTURE_DTYPES[dtype][0]
        self._source = self.ctx.texture((width, height), channels, dtype=texture_dtype, alignment=1)
        self._target = self.ctx.texture((width, height), channels, dtype=texture_dtype, alignment=1)
        try:
            self._fbo = self.ctx.framebuffer(color_attachments=[self._target])
        except Exception:
            # GL 3.3 does not require 3-component formats to be renderable: render to RGBA and
            # read back 3 components (glReadPixels converts).
            if channels != 3:
                raise
            egl.release_objects(self.ctx, self._target)
            self._target = self.ctx.texture((width, height), 4, dtype=texture_dtype, alignment=1)
            self._fbo = self.ctx.framebuffer(color_attachments=[self._target])
        self._frame_key = key

    def _draw(
        self,
        source: moderngl.Texture,
        target: moderngl.Framebuffer,
        rect: tuple[int, int, int, int],
        lens: Lens,
        direction: str,
        scale: float,
        interpolation: str,
        inverse: str,
        fill_rgba: tuple[float, ...],
        texture_unit: int,
    ) -> None:
        program, vao = self._program(direction, interpolation, inverse)
        x0, y0, width, height = rect
        source.use(location=texture_unit)
        program["u_source"] = texture_unit
        program["u_k"] = (lens.k1, lens.k2)
        program["u_centre"] = (lens.cx, lens.cy)
        program["u_pixel_aspect"] = lens.pixel_aspect
        program["u_scale"] = scale
        program["u_out_rect"] = (float(x0), float(y0), float(width), float(height))
        program["u_aspect_out"] = height / width
        program["u_aspect_in"] = source.height / source.width
        program["u_fill"] = tuple(fill_rgba) + (0.0,) * (4 - len(fill_rgba))
        target.use()
        target.viewport = (x0, y0, width, height)
        vao.render(mode=moderngl.TRIANGLES, vertices=3)

    def _remap(
        self,
        frame: np.ndarray,
        lens: Lens,
        direction: str,
        fit: str,
        interpolation: str,
        fill: object,
        inverse: str,
        out: np.ndarray | None,
    ) -> np.ndarray:
        self._check_alive()
        height, width, channels = _check_frame(frame)
        interpolation = check_choice("interpolation", interpolation, INTERPOLATIONS)
        inverse = check_choice("inverse", inverse, INVERSES)
        fill_values = _check_fill(fill, channels, frame.dtype)
        if max(width, height) > self.max_texture_size:
            raise ValueError(
                f"frame {width}×{height} exceeds this GL driver's texture limit of {self.max_texture_size} "
                f"pixels per side (GL_MAX_TEXTURE_SIZE); use backend='cpu' for it"
            )
        scale = checked_scale(lens, (width, height), direction, fit)
        if out is None:
            out = np.empty(frame.shape, frame.dtype)
        elif not (isinstance(out, np.ndarray) and out.shape == frame.shape and out.dtype == frame.dtype and out.flags.c_contiguous):
            raise ValueError(f"out must be a C-contiguous {frame.dtype} array of shape {frame.shape}")
        self._frame_objects(width, height, channels, frame.dtype)
        assert self._source is not None and self._fbo is not None
        self._source.write(np.ascontiguousarray(frame))
        unit = _TEXTURE_DTYPES[frame.dtype][1]
        rgba = tuple(v / unit for v in fill_values)
        self._draw(self._source, self._fbo, (0, 0, width, height), lens, direction, scale, interpolation, inverse, rgba, 0)
        self._fbo.read_into(out, components=channels, alignment=1, dtype=_TEXTURE_DTYPES[frame.dtype][0])
        return out


# -- CPU backend ----------------------------------------------------------------------------------
def cpu_maps(
    lens: Lens, size: tuple[int, int], direction: str, scale: float, inverse: str, nearest: bool,
    plane: Plane | None = None, *, float_maps: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Maps for ``cv2.remap`` of :meth:`Lens.maps` and the flat indices of the output pixels with
    no source (outside the input's area, or no inverse), cached (``functools.lru_cache`` of
    :data:`CPU_MAP_CACHE_SIZE` entries) by lens, size, direction, scale, inverse, nearest, ``plane`` (a
    :class:`~glradial.lens.lens.Plane` of the ``size`` frame, e.g. a chroma plane: its maps, in its
    own pixels; a sample has no source when its source lies outside the frame's area) and
    ``float_maps``. The maps are OpenCV's fixed-point ``CV_16SC2`` + ``CV_16UC1`` (positions
    rounded to 1/32 px, 6 bytes a sample), or with ``float_maps`` the float32 maps themselves
    (x, y; 8 bytes a sample): OpenCV 5 then interpolates bilinearly at the float32 position (exact
    bilinear), about twice as fast as from fixed-point maps for a single-channel plane, but slower
    for multi-channel integer images (docs/EXPERIMENTS.md). The arrays are
    shared between callers: read them, never write them."""
    return _cached_maps(lens.k1, lens.k2, lens.cx, lens.cy, lens.pixel_aspect, tuple(size), direction, scale,
                        inverse if direction == "distort" else "", bool(nearest), plane, bool(float_maps))


@functools.lru_cache(maxsize=CPU_MAP_CACHE_SIZE)
def _cached_maps(k1: float, k2: float, cx: float, cy: float, pixel_aspect: float, size: tuple[int, int], direction: str,
                 scale: float, inverse: str, nearest: bool, plane: Plane | None,
                 float_maps: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`cpu_maps` of the lens ``(k1, k2, cx, cy, pixel_aspect)``, computed once per key."""
    lens = Lens(k1, k2, cx, cy, pixel_aspect)
    map_x, map_y = lens.maps(size, direction, inverse=inverse or "exact", scale=scale, plane=plane)
    if float_maps:
        map1, map2 = map_x, map_y
    else:
        map1, map2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2, nninterpolation=nearest)
    return map1, map2, _no_source(map_x, map_y, size, plane or Plane.full(size), direction)


#: margin (plane pixels) by which the border samples' sources must lie inside the frame's area for
#: :func:`_no_source` to skip the per-sample test: well above the float32 maps' error (~1e-4 px)
_INSIDE_MARGIN = 1e-3


def _no_source(map_x: np.ndarray, map_y: np.ndarray, size: tuple[int, int], plane: Plane, direction: str) -> np.ndarray:
    """Flat indices of the samples of ``plane`` (maps in its pixels) whose source lies outside the
    ``size`` frame's area (pixel coordinates outside ``[-0.5, W-0.5] x [-0.5, H-0.5]``).

    Correction maps skip the per-sample test when the border samples' sources lie inside: the
    source is ``c + p (1 + k1 |p|^2 + k2 |p|^4)`` (``p`` the output point, scaled), and where the
    radial map ``R(r) = r (1 + k1 r^2 + k2 r^4)`` is increasing (``R' > 0``, which
    :meth:`Lens.check_frame` guarantees over the frame) the source's x grows with the output's x
    along every row: ``d/dx [x f(r)] = f + (x^2 / r) f' >= min(f, R') > 0`` (``f = R / r > 0``).
    So the extreme sources of x lie in the first and last columns, those of y in the first and last
    rows, and inside them (by :data:`_INSIDE_MARGIN`) all lie inside. Otherwise (and for ``distort``
    maps, which hold :data:`~glradial.lens.lens.NO_SOURCE`) every sample is tested."""
    width, height = size
    if direction == "undistort":
        low_x, high_x = (-0.5 - plane.x0) / plane.step_x, (width - 0.5 - plane.x0) / plane.step_x
        low_y, high_y = (-0.5 - plane.y0) / plane.step_y, (height - 0.5 - plane.y0) / plane.step_y
        if (map_x[:, 0].min() >= low_x + _INSIDE_MARGIN and map_x[:, -1].max() <= high_x - _INSIDE_MARGIN
                and map_y[0].min() >= low_y + _INSIDE_MARGIN and map_y[-1].max() <= high_y - _INSIDE_MARGIN):
            return np.empty(0, dtype=np.intp)
    frame_x, frame_y = plane.x0 + plane.step_x * map_x, plane.y0 + plane.step_y * map_y
    return np.flatnonzero((frame_x < -0.5) | (frame_x > width - 0.5) | (frame_y < -0.5) | (frame_y > height - 0.5))


def _remap_cpu(frame: np.ndarray, lens: Lens, direction: str, fit: str, interpolation: str, fill: object, inverse: str) -> np.ndarray:
    height, width, channels = _check_frame(frame)
    interpolation = check_choice("interpolation", interpolation, INTERPOLATIONS)
    inverse = check_choice("inverse", inverse, INVERSES)
    fill_values = _check_fill(fill, channels, frame.dtype)
    if max(width, height) > CPU_MAX_SIDE:
        raise ValueError(f"frame {width}×{height} exceeds cv2.remap's limit of {CPU_MAX_SIDE} pixels per side")
    scale = checked_scale(lens, (width, height), direction, fit)
    # float frames (float32 and float64: computed in float32, OpenEXR HALF/FLOAT read as float32) are
    # interpolated bilinearly at the exact float32 positions; integer frames from fixed-point maps
    exact = interpolation == "linear" and frame.dtype.kind == "f"
    map1, map2, outside = cpu_maps(lens, (width, height), direction, scale, inverse, interpolation == "nearest",
                                   float_maps=exact)
    result = cv2.remap(frame, map1, map2, CV_INTERPOLATION[interpolation], borderMode=cv2.BORDER_REPLICATE)
    result = result.reshape(frame.shape)
    if outside.size:
        fill_array = np.asarray(fill_values)
        if frame.dtype.kind == "u":
            fill_array = np.rint(fill_array)  # as the GL path's conversion to a normalized target
        result.reshape(height * width, channels)[outside] = fill_array.astype(frame.dtype)
    return result


# -- module-level functions -----------------------------------------------------------------------
_auto_lock = threading.Lock()
_auto_choice: dict[int, str] = {}


def _thread_remapper() -> Remapper:
    """The calling thread's Remapper on :func:`egl.thread_context` (one per thread and process,
    released with the thread's context when the thread ends)."""
    return egl.thread_resource("remapper", Remapper)


def auto_backend() -> str:
    """What ``backend="auto"`` picks in this process: ``"cpu"`` if no EGL context can be made or
    the renderer is a software rasteriser (llvmpipe, softpipe, swrast, lavapipe), else ``"gl"``."""
    pid = os.getpid()
    with _auto_lock:
        choice = _auto_choice.get(pid)
    if choice is None:
        try:
            ctx = egl.thread_context()
        except egl.GLUnavailableError:
            choice = "cpu"
        else:
            choice = "cpu" if egl.is_software_renderer(ctx) else "gl"
        with _auto_lock:
            _auto_choice[pid] = choice
    return choice


def _run_one(frame, lens, direction, fit, interpolation, fill, inverse, backend) -> np.ndarray:
    auto = backend == "auto"
    if auto:
        backend = auto_backend()
    if backend == "gl":
        remapper = _thread_remapper()
        # "auto" sends a frame beyond the GL texture limit to the CPU; the frame itself is validated
        # once, by whichever backend draws it (_check_frame: for float frames a pass over every pixel)
        oversized = (auto and isinstance(frame, np.ndarray) and frame.ndim in (2, 3)
                     and max(frame.shape[:2]) > remapper.max_texture_size)
        if not oversized:
            return remapper._remap(frame, lens, direction, fit, interpolation, fill, inverse, None)
    return _remap_cpu(frame, lens, direction, fit, interpolation, fill, inverse)


def _as_float32(frame: np.ndarray) -> np.ndarray:
    """A float64 frame as float32 (the precision both backends compute in); ``ValueError`` for
    values beyond float32's range rather than silent infinities."""
    try:
        with np.errstate(over="raise"):
            return frame.astype(np.float32)
    except FloatingPointError:
        limit = float(np.finfo(np.float32).max)
        raise ValueError(
            f"float64 frame holds values beyond float32's range (±{limit:.4g}), the precision glradial "
            f"computes in: largest magnitude {float(np.nanmax(np.abs(frame))):.4g}"
        ) from None


def _remap_frames(frame, lens_or_k1, k2, direction, fit, interpolation, fill, inverse, backend, alpha) -> np.ndarray:
    """What :func:`correct` and :func:`distort` share once the doubt policy is applied: the lens read,
    the alpha convention, then :func:`_run`."""
    lens = _lens(lens_or_k1, k2)
    return remap_with_alpha(frame, fill, alpha, lambda work, fill_values: _run(
        work, lens, direction, fit, interpolation, fill_values, inverse, backend))


def _run(frame, lens, direction, fit, interpolation, fill, inverse, backend) -> np.ndarray:
    backend = check_choice("backend", backend, BACKENDS)
    if not isinstance(frame, np.ndarray):
        return _run_one(frame, lens, direction, fit, interpolation, fill, inverse, backend)  # its TypeError
    if frame.ndim > 4:
        raise ValueError(
            f"frame must be H×W, H×W×C or a batch N×H×W×C with C in (1, 3, 4), got a {frame.ndim}-D array "
            f"of shape {frame.shape}"
        )
    if frame.dtype not in _TEXTURE_DTYPES and frame.dtype != np.float64:
        raise TypeError(f"frame dtype must be uint8, uint16, float32 or float64, got {frame.dtype}")
    if frame.ndim == 4:
        if frame.shape[0] == 0:
            raise ValueError(f"frame batch is empty: shape {frame.shape}")
        if frame.shape[3] not in (1, 3, 4):
            raise ValueError(f"a batch must be N×H×W×C with C in (1, 3, 4), got shape {frame.shape}")
    source = _as_float32(frame) if frame.dtype == np.float64 else frame
    if frame.ndim < 4:
        result = _run_one(source, lens, direction, fit, interpolation, fill, inverse, backend)
        return result.astype(np.float64) if frame.dtype == np.float64 else result
    result = np.empty(frame.shape, frame.dtype)
    for index in range(frame.shape[0]):
        result[index] = _run_one(source[index], lens, direction, fit, interpolation, fill, inverse, backend)
    return result


def correct(
    frame: np.ndarray,
    lens: Lens | float,
    k2: float | None = None,
    *,
    fit: Fit = "same",
    interpolation: Interpolation = "linear",
    fill: float | Sequence[float] = 0,
    backend: Backend = "auto",
    alpha: Alpha = "straight",
    apply_doubtful: bool = False,
) -> np.ndarray:
    """Remove a lens from ``frame`` (or a batch of frames); a new array of the same shape and dtype.

    ``lens``: a :class:`glradial.Lens` (any subclass, e.g. what :func:`glradial.estimate` returns),
    or the coefficient ``k1`` followed by ``k2`` (default 0). Convention: see the module docstring
    (lens units, principal point, fit scale, frames, batches, float64, fill, interpolation,
    backends). ``fit="same"`` equals ``cv2.undistort(frame, K, dist, newCameraMatrix=K)`` with
    ``K, dist = lens.to_opencv((W, H))``. Raises ``ValueError`` when the lens folds over inside the
    (fitted) frame, for bad shapes and unknown option values, ``TypeError`` for non-array frames,
    unsupported dtypes, non-real coefficients and a Lens given together with ``k2``.

    ``alpha``: the convention of a 4-channel (RGBA) frame, ``"straight"`` (default; PNG, ProRes 4444)
    or ``"premultiplied"`` (OpenEXR; also for 4 channels that are not colour and alpha). Either way
    the frame is interpolated premultiplied, so a key's edge has no fringe, and returned in the
    convention it came in (:mod:`glradial.remapping.alpha`).

    Doubt policy: a lens that says it is doubtful (a :class:`glradial.LensEstimate` with
    ``doubtful=True``, see its ``reason``) is not applied: the result is the frame unchanged (a
    checked copy, as with no lens at ``fit="same"``), unless ``apply_doubtful=True``.

    Args:
        frame: H×W, H×W×C or N×H×W×C array (uint8, uint16, float32 or float64).
        lens: a :class:`glradial.Lens`, or ``k1`` (width-normalised) with ``k2`` next.
        k2: the fourth-order coefficient when ``lens`` is a number (default 0).
        fit: ``"same"``, ``"crop"``, ``"full"`` or a scale (:func:`fit_scale`).
        interpolation: ``"nearest"``, ``"linear"`` or ``"cubic"``.
        fill: value of pixels the lens never reaches (one number, or one per channel).
        backend: ``"auto"`` (GL when available), ``"gl"`` or ``"cpu"`` (``cv2.remap``).
        alpha: ``"straight"`` or ``"premultiplied"`` (4-channel frames).
        apply_doubtful: apply a doubtful :class:`glradial.LensEstimate` all the same.

    Returns:
        The corrected frame(s): a new array of the same shape and dtype.

    Raises:
        ValueError: see above (fold-over, bad shapes, unknown options).
        TypeError: see above (non-arrays, dtypes, coefficients, a Lens with ``k2``).

    Example:
        >>> import numpy as np, glradial
        >>> frame = np.zeros((54, 96), np.float32); frame[27, :] = 1.0  # a horizontal line
        >>> bent = glradial.distort(frame, -0.3, backend="cpu")
        >>> back = glradial.correct(bent, -0.3, backend="cpu")
        >>> bool(abs(back[27, 20:76] - 1.0).max() < 0.05)  # straight again through the centre
        True
        >>> doubtful = glradial.LensEstimate(-0.3, 0.0, doubtful=True, reason="too_few_lines")
        >>> bool((glradial.correct(bent, doubtful, backend="cpu") == bent).all())  # not applied
        True
    """
    if not doubt.applies(getattr(lens, "doubtful", False) is True, getattr(lens, "reason", ""), apply_doubtful):
        lens, fit = Lens(0.0, 0.0), "same"
    return _remap_frames(frame, lens, k2, "undistort", fit, interpolation, fill, "exact", backend, alpha)


def distort(
    frame: np.ndarray,
    lens: Lens | float,
    k2: float | None = None,
    *,
    fit: Fit = "same",
    interpolation: Interpolation = "linear",
    fill: float | Sequence[float] = 0,
    inverse: InverseMethod = "exact",
    backend: Backend = "auto",
    alpha: Alpha = "straight",
) -> np.ndarray:
    """Apply a lens (a :class:`glradial.Lens`, or ``k1, k2``) to an undistorted ``frame`` (or a
    batch); a new array, same shape and dtype.

    Each output pixel samples the input at the inverse of the lens (``inverse="exact"``: bounded
    Newton, pixels the lens never reaches get ``fill``; ``"drap"``: the paper's four-term
    polynomial, up to 0.0015 image widths off inside the frame width at k1 = -0.7 and 0.022 at the 16:9
    corner: docs/CROPS.md). Same conventions and
    errors as :func:`correct`; ``correct(distort(x, lens), lens) ≈ x`` for the same scale
    (``fit="same"``, the same number, or "crop" here with "full" there). ``alpha``: as in :func:`correct`.

    Args:
        frame, lens, k2, fit, interpolation, fill, backend, alpha: as in :func:`correct`.
        inverse: ``"exact"`` or ``"drap"`` (above).

    Returns:
        The distorted frame(s): a new array of the same shape and dtype.

    Raises:
        ValueError, TypeError: as :func:`correct`, and for an unknown ``inverse``.

    Example:
        >>> import numpy as np, glradial
        >>> frame = np.zeros((54, 96), np.float32); frame[10, :] = 1.0  # a line above the centre
        >>> bent = glradial.distort(frame, -0.3, backend="cpu")
        >>> rows = bent.argmax(axis=0)  # the line's row in each column
        >>> int(rows[48]), bool(rows[12] > rows[48])  # barrel: pulled towards the centre, more far out
        (10, True)
    """
    return _remap_frames(frame, lens, k2, "distort", fit, interpolation, fill, inverse, backend, alpha)
