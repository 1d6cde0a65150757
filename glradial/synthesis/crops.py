"""Distorted perspective crops of equirectangular panoramas (the paper's training data), on the GPU.

Convention (docs/DESIGN.md, issue 3):

* Panorama: ``H × W × C`` equirectangular, ``W = 2 H``. Longitude runs left -> right with 0 at the
  centre column (+ to the right), latitude +90° at the top row. Pixel ``(x, y)`` of the panorama
  (centres at integers) is at ``lon = 2π ((x + 0.5) / W - 0.5)``, ``lat = π (0.5 - (y + 0.5) / H)``.
* A crop is :class:`CropParams` ``(pan, tilt, roll, hfov, k1, k2)``, angles in degrees. Pan + turns
  right, tilt + looks up, roll + rolls the camera clockwise as seen from behind it (its right side
  dips). Camera axes x right, y down, z forward; world ray ``= R_pan · R_tilt · R_roll · camera ray``
  (world axes: x toward lon = +90°, y down, z toward lon = 0 on the horizon).
* Focal length ``f = 1 / (2 tan(hfov / 2))`` in lens units (image width = 1). For each output pixel
  at lens point ``p_d`` of the frame geometry ``size`` (16:9 in the paper), ``p_u = inverse(p_d)``
  (``"exact"`` Newton inverse, or the paper's four-term ``"drap"`` one), camera ray
  ``(p_u.x, p_u.y, f)``. Where the exact inverse has no solution the pixel is 0.
* ``(k1, k2)`` always refer to the frame geometry ``size``; ``out_size`` only resamples it (area
  filter on the GPU: the aspect may be squashed, the paper's 1280×720 -> 224×224).
"""

from __future__ import annotations

import math
import numbers
import os
import warnings
from dataclasses import dataclass, fields
from typing import Literal, Mapping, Sequence

import moderngl
import numpy as np

from ..errors import check_count, check_flag
from ..gl.shaderlib import TEXTURE_FORMATS
from ..lens import lensfuncs
from ..lens.inverse_series import SERIES_DEGREE, fit_inverse_series
from ..lens.lens import Lens, corner_radius, focal_from_hfov, frame_size
from ..lens.metrics import PAPER_SIZE, manifold_k2
from ..lens.options import INVERSES, InverseMethod, real_number

#: The paper's sampling distribution (degrees; k1 in lens units). k2 = manifold(k1) + N(0, K2_NOISE).
PAPER_RANGES: Mapping[str, tuple[float, float]] = {
    "pan": (-35.0, 35.0),
    "tilt": (-15.0, 0.0),
    "roll": (-2.0, 2.0),
    "hfov": (15.0, 60.0),
    "k1": (-0.7, 0.3),
}
#: Standard deviation of k2 around the Lopez-Antequera manifold (the paper's).
K2_NOISE = 0.02


@dataclass(frozen=True)
class CropParams:
    """One crop: camera pose, horizontal field of view and lens.

    Convention: ``pan`` (+ right), ``tilt`` (+ up, within [-90, 90]), ``roll`` (+ clockwise seen
    from behind, the right side dips), ``hfov`` (horizontal field of view of the undistorted frame,
    in (0, 180)) in degrees; ``k1``, ``k2`` in width-normalised lens units of the 16:9 frame
    (default 0: an undistorted perspective view of the panorama).

    Args:
        pan, tilt, roll, hfov: degrees (convention above).
        k1, k2: the crop's lens (width-normalised).

    Raises:
        ValueError: a value that is not a finite number, ``tilt`` outside [-90, 90] or ``hfov``
            outside (0, 180).

    Example:
        >>> import glradial
        >>> crop = glradial.CropParams(pan=30.0, tilt=-10.0, roll=0.0, hfov=60.0, k1=-0.2)
        >>> crop.lens
        Lens(k1=-0.2, k2=0.0, cx=0.0, cy=0.0, pixel_aspect=1.0)
    """

    pan: float
    tilt: float
    roll: float
    hfov: float
    k1: float = 0.0
    k2: float = 0.0

    def __post_init__(self) -> None:
        for item in fields(self):
            object.__setattr__(self, item.name, real_number(item.name, getattr(self, item.name)))
        if not -90.0 <= self.tilt <= 90.0:
            raise ValueError(f"tilt must be within [-90, 90] degrees, got {self.tilt}")
        if not 0.0 < self.hfov < 180.0:
            raise ValueError(f"hfov must be within (0, 180) degrees, got {self.hfov}")

    @property
    def lens(self) -> Lens:
        return Lens(self.k1, self.k2)

    @property
    def focal(self) -> float:
        """Focal length in lens units (image width = 1): ``1 / (2 tan(hfov / 2))``."""
        return focal_from_hfov(self.hfov)

    def rotation(self) -> np.ndarray:
        """3×3 float64 ``R_pan · R_tilt · R_roll`` taking camera rays to world rays."""
        return camera_rotation(self.pan, self.tilt, self.roll)

    def as_dict(self) -> dict[str, float]:
        return {item.name: getattr(self, item.name) for item in fields(self)}


def camera_rotation(pan: float, tilt: float, roll: float) -> np.ndarray:
    """``R_pan · R_tilt · R_roll`` (degrees in, 3×3 float64 out), axes x right, y down, z forward.

    ``R_roll`` turns the camera's x axis toward +y (down): its right side dips. ``R_tilt`` turns the
    forward axis toward -y (up). ``R_pan`` turns the forward axis toward +x (right).
    """
    p, t, r = (math.radians(v) for v in (pan, tilt, roll))
    cp, sp, ct, st, cr, sr = math.cos(p), math.sin(p), math.cos(t), math.sin(t), math.cos(r), math.sin(r)
    r_pan = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    r_tilt = np.array([[1.0, 0.0, 0.0], [0.0, ct, -st], [0.0, st, ct]])
    r_roll = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    return r_pan @ r_tilt @ r_roll


def lens_covers_frame(k1: float, k2: float, size: tuple[int, int] = PAPER_SIZE) -> bool:
    """True when a distorted crop of this lens on a ``size`` frame is valid everywhere.

    Two conditions: (1) the lens does not fold over on any undistorted radius up to the frame's
    corner radius (correcting the frame is one-to-one), and (2) every distorted radius up to the corner
    radius has an undistorted solution (no empty corners in the distorted crop).
    """
    r_corner = corner_radius(size)
    r_fold = lensfuncs.fold_radius(k1, k2)
    if r_fold <= r_corner:
        return False
    if r_fold < lensfuncs.LENS_RADIUS_UNBOUNDED:
        reach = r_fold * float(lensfuncs.radial_factor(r_fold * r_fold, k1, k2))
        if reach <= r_corner:
            return False
    else:  # increasing everywhere; the reach is unbounded unless the map saturates (k2 < 0 cannot be)
        pass
    return True


def _range(name: str, value: object) -> tuple[float, float]:
    if isinstance(value, (numbers.Real, np.floating, np.integer)) and not isinstance(value, bool):
        number = real_number(name, value)
        return number, number
    try:
        lo, hi = value  # type: ignore[misc]
    except (TypeError, ValueError):
        raise TypeError(f"range {name} must be a number or (low, high), got {value!r}") from None
    lo, hi = real_number(f"{name} low", lo), real_number(f"{name} high", hi)
    if lo > hi:
        raise ValueError(f"range {name} must have low <= high, got ({lo}, {hi})")
    return lo, hi


_CHUNK = 256


def sample_crop_params(
    n: int,
    seed: int,
    *,
    size: tuple[int, int] = PAPER_SIZE,
    k2_noise: float = K2_NOISE,
    **ranges: object,
) -> list[CropParams]:
    """Draw ``n`` crops from the paper's distribution (or ``ranges`` overriding it).

    ``ranges``: any of ``pan``, ``tilt``, ``roll``, ``hfov``, ``k1`` as ``(low, high)`` (uniform) or a
    number (fixed); ``k2 = 0.019 k1 + 0.805 k1² + N(0, k2_noise)``. Lenses that fail
    :func:`lens_covers_frame` on ``size`` are redrawn (whole draws are rejected, not returned).
    Deterministic per ``seed``: draws come in fixed chunks from ``numpy.random.default_rng(seed)``,
    so ``sample_crop_params(n, s)`` is a prefix of ``sample_crop_params(m, s)`` for ``n <= m``.

    Args:
        n: how many crops (>= 0).
        seed: the generator's seed (>= 0).
        size: the frame ``(W, H)`` in pixels the lenses must cover.
        k2_noise: standard deviation of ``k2`` around the manifold (width-normalised).
        **ranges: overrides (above); degrees for angles.

    Returns:
        ``n`` :class:`glradial.CropParams`.

    Raises:
        ValueError: a bad ``n``, ``seed`` or range (unknown key, low > high).

    Example:
        >>> import glradial
        >>> crops = glradial.sample_crop_params(3, seed=7, hfov=50.0)
        >>> [c.hfov for c in crops], crops[:2] == glradial.sample_crop_params(2, seed=7, hfov=50.0)
        ([50.0, 50.0, 50.0], True)
    """
    if isinstance(n, bool) or not isinstance(n, (numbers.Integral, np.integer)) or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    if isinstance(seed, bool) or not isinstance(seed, (numbers.Integral, np.integer)):
        raise TypeError(f"seed must be an integer >= 0, got {seed!r} ({type(seed).__name__})")
    if seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    unknown = set(ranges) - set(PAPER_RANGES)
    if unknown:
        raise TypeError(f"unknown range(s) {sorted(unknown)}; known: {sorted(PAPER_RANGES)}")
    size = frame_size(size)
    k2_noise = real_number("k2_noise", k2_noise)
    if k2_noise < 0:
        raise ValueError(f"k2_noise must be >= 0, got {k2_noise}")
    bounds = {name: _range(name, ranges.get(name, default)) for name, default in PAPER_RANGES.items()}
    if not (bounds["hfov"][0] > 0.0 and bounds["hfov"][1] < 180.0):
        raise ValueError(f"hfov range must lie within (0, 180), got {bounds['hfov']}")
    if not (bounds["tilt"][0] >= -90.0 and bounds["tilt"][1] <= 90.0):
        raise ValueError(f"tilt range must lie within [-90, 90], got {bounds['tilt']}")
    rng = np.random.default_rng(seed)
    out: list[CropParams] = []
    attempts = 0
    while len(out) < n:
        draws = {name: rng.uniform(lo, hi, _CHUNK) for name, (lo, hi) in bounds.items()}
        k2 = manifold_k2(draws["k1"]) + rng.normal(0.0, 1.0, _CHUNK) * k2_noise
        for i in range(_CHUNK):
            if len(out) == n:
                break
            k1_i, k2_i = float(draws["k1"][i]), float(k2[i])
            if not lens_covers_frame(k1_i, k2_i, size):
                continue
            out.append(
                CropParams(
                    float(draws["pan"][i]), float(draws["tilt"][i]), float(draws["roll"][i]),
                    float(draws["hfov"][i]), k1_i, k2_i,
                )
            )
        attempts += 1
        if attempts > 1000 and len(out) < n:
            raise ValueError(
                f"the ranges {bounds} with k2_noise={k2_noise} give almost no lens valid on a "
                f"{size[0]}×{size[1]} frame"
            )
    return out


# --- NumPy reference (the oracle for tests; float64) ------------------------------------------------


def crop_lonlat(
    params: CropParams,
    size: tuple[int, int] = PAPER_SIZE,
    out_size: tuple[int, int] | None = None,
    inverse: InverseMethod = "exact",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Longitude, latitude (radians, arrays of shape (h, w)) and validity of each output pixel centre.

    Same geometry as ``shaders/crop.frag`` (see the module docstring), computed in float64.
    """
    width, height = frame_size(size)
    w_out, h_out = frame_size(out_size) if out_size is not None else (width, height)
    u = (np.arange(w_out) + 0.5) / w_out
    v = (np.arange(h_out) + 0.5) / h_out
    uv = np.stack(np.meshgrid(u, v), axis=-1)
    p_d = lensfuncs.lens_from_uv(uv, height / width)
    if inverse == "exact":
        p_u, valid = lensfuncs.undistort_point_exact(p_d, params.k1, params.k2)
    elif inverse == "drap":
        p_u, valid = lensfuncs.undistort_point_drap(p_d, params.k1, params.k2), np.ones(p_d.shape[:2], bool)
    else:
        raise ValueError(f"inverse must be 'exact' or 'drap', got {inverse!r}")
    rays = np.concatenate([p_u, np.full(p_u.shape[:2] + (1,), params.focal)], axis=-1)
    world = rays @ params.rotation().T
    lon, lat = ray_to_lonlat(world)
    return lon, lat, valid


def ray_to_lonlat(world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rays (..., 3) (x right, y down, z forward; any length) -> (lon, lat) in radians.

    ``lon = atan2(x, z)`` (0 at the panorama's centre column, + right), ``lat = atan2(-y, |(x, z)|)``
    (+ up).
    """
    world = np.asarray(world, dtype=np.float64)
    x, y, z = world[..., 0], world[..., 1], world[..., 2]
    return np.arctan2(x, z), np.arctan2(-y, np.hypot(x, z))


# --- GPU renderer ---------------------------------------------------------------------------------

#: Cap on the bytes of one atlas framebuffer (4 channels); a batch larger than that is drawn in passes.
ATLAS_BYTES = 64 * 2**20
#: Default anisotropy of panorama reads: 1 (plain trilinear). Mesa llvmpipe's anisotropic path
#: blurs even magnified reads and is slower (figures in docs/CROPS.md); supersampling does the
#: anti-aliasing instead.
ANISOTROPY = 1.0
#: Per-crop vertex attributes of crop.vert, in buffer order (vec4 each): rotation rows | f, k1, k2;
#: inverse series coefficients c0..c10 | tile index.
_INSTANCE_ATTRIBUTES = ("in_r0", "in_r1", "in_r2", "in_s0", "in_s1", "in_s2")
_INSTANCE_FLOATS = 4 * len(_INSTANCE_ATTRIBUTES)


def _panorama_array(panorama: object) -> np.ndarray:
    array = np.asarray(panorama)
    if array.ndim == 2:
        array = array[:, :, None]
    if array.ndim != 3 or array.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"panorama must be H×W or H×W×C with C in 1..4, got shape {array.shape}")
    if array.dtype not in TEXTURE_FORMATS:
        raise TypeError(f"panorama dtype must be uint8, uint16 or float32, got {array.dtype}")
    height, width = array.shape[:2]
    if height == 0 or width == 0:
        raise ValueError(f"panorama is empty: shape {array.shape}")
    if array.dtype.kind == "f":
        low, high = float(array.min()), float(array.max())
        if not (np.isfinite(low) and np.isfinite(high)):
            raise ValueError(f"panorama contains NaN or infinite pixels (min {low}, max {high})")
    if width != 2 * height:
        raise ValueError(f"panorama must be equirectangular 2:1 (W = 2 H), got {width}×{height}")
    return array


#: Largest number of sub-samples per axis that ``supersample`` accepts.
MAX_SUPERSAMPLE = 8


def supersample_grid(value: object, size: tuple[int, int], out: tuple[int, int]) -> tuple[int, int]:
    """Sub-samples per output pixel along (x, y): ``value`` as one int (both axes), a pair, or ``"auto"``.

    ``"auto"``: an output pixel covers ``fx × fy = (W/w) × (H/h)`` frame pixels; with ``m = min(fx, fy)``
    it gets ``round(fx / m) × round(fy / m)`` samples when ``m > 1.5`` (each sample's footprint is then
    near-square, which a trilinear read filters well), and ``1 × 1`` otherwise. 1280×720 -> 224×224:
    2 × 1; 1280×720 -> 640×360: 1 × 1 (plain trilinear).
    """
    if isinstance(value, str):
        if value != "auto":
            raise ValueError(f"supersample must be an integer, (x, y) integers or 'auto', got {value!r}")
        fx, fy = size[0] / out[0], size[1] / out[1]
        m = min(fx, fy)
        if m <= 1.5:
            return (1, 1)
        return (max(1, min(4, round(fx / m))), max(1, min(4, round(fy / m))))
    pair = (value, value) if isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, bool) else value
    try:
        sx, sy = pair  # type: ignore[misc]
    except (TypeError, ValueError):
        raise TypeError(f"supersample must be an integer, (x, y) integers or 'auto', got {value!r}") from None
    for s in (sx, sy):
        if isinstance(s, bool) or not isinstance(s, (numbers.Integral, np.integer)) or not 1 <= s <= MAX_SUPERSAMPLE:
            raise ValueError(f"supersample must be integers in 1..{MAX_SUPERSAMPLE}, got {value!r}")
    return int(sx), int(sy)


class CropRenderer:
    """Owns a panorama texture (uploaded once, mipmapped) and renders batches of crops from it.

    Convention: see the module docstring. ``size`` ``(W, H)`` is the frame geometry the lens refers
    to; ``out_size`` ``(w, h)`` (default ``size``) is what :meth:`render` returns; the output pixel
    ``(i, j)`` covers the frame rectangle ``[i W/w, (i+1) W/w] × [j H/h, (j+1) H/h]``.

    Anti-aliasing: the footprint of each output pixel on the panorama comes from the derivatives of
    the world ray (no seam at ±180°) and selects the mipmap level. The default (``supersample=1``)
    is one trilinear read per pixel at that footprint: anti-aliased like any mipmapped GPU texture
    read, and, when ``out_size`` squashes the frame (1280×720 -> 224×224 is 5.7 × 3.2 frame pixels
    per output pixel), blurred along the short axis to the long axis's scale. ``supersample``
    ``(SX, SY)`` (or one int for both) averages ``SX × SY`` sub-pixel samples placed with the local
    linear map, each a trilinear read at its sub-pixel footprint: a box filter over the output pixel,
    i.e. what area-resizing (``cv2.INTER_AREA``) an anti-aliased ``size`` frame gives, without
    rendering it; ``"auto"`` picks the grid that makes each sample's footprint near-square (see
    :func:`supersample_grid`; 2 × 1 for 1280×720 -> 224×224). How close each grid comes to that, and what it costs:
    docs/CROPS.md.
    ``anisotropy`` (default 1: trilinear) is passed to the driver. ``inverse`` picks the exact
    inverse (``newton_steps`` Newton steps from the Drap-Lefevre seed; 3 reach 1e-9 lens units for
    the paper's distribution; the default is common.glsl's ``LENS_NEWTON_STEPS`` = 8, and pixels where
    Newton does not converge count as having no solution) or the paper's four-term ``"drap"`` one.
    With ``series_inverse`` (default) the exact inverse of each crop's lens is fitted on the CPU as a
    degree-10 Chebyshev series in ``r_d²`` and used instead of the per-pixel Newton solve wherever it
    is within 1e-6 lens units of it over the whole frame (:mod:`glradial.lens.inverse_series`; most of the
    paper's lenses, docs/CROPS.md; the others, near fold-over, keep Newton): the same geometry, a faster shader.

    Crops are drawn up to ``tiles_per_pass`` at a time into a vertical atlas (one instanced draw per
    inverse path and one readback per pass). A 3-channel panorama is stored as RGBA (a quarter more
    texture memory; Mesa llvmpipe samples it faster). Use it on the thread and process that made ``ctx`` (default:
    ``thread_context()``) and :meth:`release` it (or use ``with``). Panoramas wider than
    ``GL_MAX_TEXTURE_SIZE`` are downscaled (area filter) with a ``RuntimeWarning``.

    Args:
        panorama: equirectangular (2:1) H×W, H×W×3 or H×W×4 array (uint8, uint16 or float32).
        size, out_size: frame and output ``(W, H)`` in pixels (above).
        inverse, supersample, anisotropy, newton_steps, series_inverse: above.
        ctx: a moderngl context (default: the thread's glradial context).

    Raises:
        TypeError: ``ctx`` is not a moderngl context, or the panorama is not an array.
        ValueError: bad sizes, options or panorama shape.

    Example:
        >>> import numpy as np, glradial
        >>> panorama = np.full((64, 128, 3), 90, np.uint8)
        >>> with glradial.CropRenderer(panorama, size=(64, 36)) as renderer:
        ...     crops = renderer.render([glradial.CropParams(0.0, 0.0, 0.0, 60.0, k1=-0.1)])
        >>> crops.shape, int(crops[0, 18, 32, 1])  # a flat panorama stays flat
        ((1, 36, 64, 3), 90)
    """

    def __init__(
        self,
        panorama: np.ndarray,
        *,
        size: tuple[int, int] = PAPER_SIZE,
        out_size: tuple[int, int] | None = None,
        inverse: InverseMethod = "exact",
        supersample: int | tuple[int, int] | Literal["auto"] = 1,
        anisotropy: float | None = None,
        newton_steps: int = lensfuncs.LENS_NEWTON_STEPS,
        series_inverse: bool = True,
        ctx: object | None = None,
    ) -> None:
        import moderngl

        from ..gl.egl import GLOwner, thread_context

        self.size = frame_size(size)
        self.out_size = frame_size(out_size) if out_size is not None else self.size
        self._set_options(inverse, supersample, anisotropy, newton_steps, series_inverse)
        array = _panorama_array(panorama)
        self.dtype = array.dtype
        self.channels = array.shape[2]
        self._squeeze = np.asarray(panorama).ndim == 2
        if ctx is not None and not isinstance(ctx, moderngl.Context):
            raise TypeError(f"ctx must be a moderngl.Context or None, got {type(ctx).__name__} {ctx!r}")
        self._objects: list[object] = []
        self.ctx = ctx if ctx is not None else thread_context()
        self._owner = GLOwner("CropRenderer", self.ctx)
        self._owner.enter()
        array = self._within_limits(array)
        self.panorama_size = (array.shape[1], array.shape[0])
        try:
            self._build(np.ascontiguousarray(array))
        except BaseException:
            self.release()
            raise

    def _set_options(self, inverse: object, supersample: object, anisotropy: object, newton_steps: object,
                     series_inverse: object) -> None:
        """Check and keep the rendering options (the sizes are set)."""
        if inverse not in INVERSES:
            raise ValueError(f"inverse must be 'exact' or 'drap', got {inverse!r}")
        self.inverse: InverseMethod = inverse  # type: ignore[assignment]
        self.supersample = supersample_grid(supersample, self.size, self.out_size)  # type: ignore[arg-type]
        if isinstance(newton_steps, bool) or not isinstance(newton_steps, (numbers.Integral, np.integer)) or not 1 <= newton_steps <= 16:
            raise ValueError(f"newton_steps must be an integer in 1..16, got {newton_steps!r}")
        self.newton_steps = int(newton_steps)
        self.series_inverse = check_flag("series_inverse", series_inverse) and inverse == "exact"
        self._corner = corner_radius(self.size)
        if anisotropy is None:
            anisotropy = ANISOTROPY
        self.anisotropy = float(anisotropy)
        if not 1.0 <= self.anisotropy <= 16.0:
            raise ValueError(f"anisotropy must be within [1, 16], got {anisotropy!r}")

    def _within_limits(self, array: np.ndarray) -> np.ndarray:
        """The panorama as the driver takes it: an output size over the limits is a ``ValueError``;
        a panorama wider than the texture limit is downscaled with a ``RuntimeWarning``."""
        from ..gl.egl import max_texture_size

        limit = max_texture_size(self.ctx)
        rows = min(int(self.ctx.info["GL_MAX_VIEWPORT_DIMS"][1]), limit)
        if self.out_size[0] > limit or self.out_size[1] > rows:
            raise ValueError(
                f"out_size {self.out_size[0]}×{self.out_size[1]} exceeds this GL driver's limit of {limit} pixels "
                f"wide and {rows} high per crop (GL_MAX_TEXTURE_SIZE, GL_MAX_VIEWPORT_DIMS)"
            )
        if array.shape[1] > limit:
            import cv2

            new_w, new_h = limit, limit // 2
            warnings.warn(
                f"panorama {array.shape[1]}×{array.shape[0]} exceeds GL_MAX_TEXTURE_SIZE {limit}; "
                f"downscaled to {new_w}×{new_h} (area filter)",
                RuntimeWarning,
                stacklevel=3,  # the caller of CropRenderer(...)
            )
            array = cv2.resize(array, (new_w, new_h), interpolation=cv2.INTER_AREA)
            if array.ndim == 2:
                array = array[:, :, None]
        return array

    def _build(self, array: np.ndarray) -> None:
        from ..gl.shaderlib import build_program

        ctx = self.ctx
        tex_dtype = TEXTURE_FORMATS[self.dtype][0]
        if self.channels == 3:  # stored as RGBA: Mesa llvmpipe samples 4-channel textures faster (docs/CROPS.md)
            opaque = np.iinfo(self.dtype).max if self.dtype.kind == "u" else 1.0
            array = np.concatenate([array, np.full((*array.shape[:2], 1), opaque, self.dtype)], axis=2)
        self._pano = ctx.texture(self.panorama_size, array.shape[2], array.tobytes(), dtype=tex_dtype, alignment=1)
        self._objects.append(self._pano)
        self._pano.build_mipmaps()
        self._pano.repeat_x = True
        self._pano.repeat_y = False
        self._pano.anisotropy = self.anisotropy
        w, h = self.out_size
        limit = min(int(ctx.info["GL_MAX_VIEWPORT_DIMS"][1]), int(ctx.info["GL_MAX_TEXTURE_SIZE"]))
        per_tile = 4 * w * h * np.dtype(self.dtype).itemsize
        self.tiles_per_pass = max(1, min(limit // h, ATLAS_BYTES // per_tile))
        # One program per inverse path; each draws its own crops of a pass (tile index per instance):
        # "series" for lenses whose inverse series passed its check, "newton"/"drap" for the others.
        paths = ["drap"] if self.inverse == "drap" else (["series", "newton"] if self.series_inverse else ["newton"])
        self._draws: dict[str, tuple[object, object, object]] = {}  # path -> program, vao, instance buffer
        for path in paths:
            defines = {
                "CROP_SUPERSAMPLE_X": self.supersample[0],
                "CROP_SUPERSAMPLE_Y": self.supersample[1],
                "CROP_INVERSE_DRAP": path == "drap",
                "CROP_INVERSE_SERIES": path == "series",
                "LENS_NEWTON_STEPS": self.newton_steps,
            }
            prog = build_program(ctx, "crop.vert", "crop.frag", defines)
            self._objects.append(prog)
            instances = ctx.buffer(reserve=self.tiles_per_pass * _INSTANCE_FLOATS * 4)
            self._objects.append(instances)
            # Attributes a program does not read (the series coefficients outside the series
            # program) are skipped as padding: GL has no location for them.
            names = [n for n in _INSTANCE_ATTRIBUTES if n in prog]
            layout = " ".join("4f" if n in prog else "16x" for n in _INSTANCE_ATTRIBUTES)
            vao = ctx.vertex_array(prog, [(instances, layout + "/i", *names)])
            self._objects.append(vao)
            prog["u_panorama"].value = 0
            prog["u_tile_size"].value = (w, h)
            prog["u_aspect_hw"].value = self.size[1] / self.size[0]
            if path == "series":
                prog["u_series_scale"].value = 2.0 / (self._corner * self._corner)
            self._draws[path] = (prog, vao, instances)
        self._params = np.zeros((self.tiles_per_pass, len(_INSTANCE_ATTRIBUTES), 4), np.float32)
        self._target = ctx.texture((w, h * self.tiles_per_pass), 4, dtype=tex_dtype)
        self._objects.append(self._target)
        self._fbo = ctx.framebuffer(color_attachments=[self._target])
        self._objects.append(self._fbo)
        # RGB output: the atlas is read as RGBA (a plain copy) and OpenCV drops alpha, faster than the
        # driver's own RGBA -> RGB readback (docs/CROPS.md).
        self._rgba_scratch: np.ndarray | None = None  # allocated on the first RGB readback

    # -- rendering -------------------------------------------------------------------------------
    def render(self, params: Sequence[CropParams], out: np.ndarray | None = None) -> np.ndarray:
        """Render crops -> array ``(N, h, w, C)`` of the panorama's dtype (``(N, h, w)`` for an H×W one).

        A lens that folds over inside the ``size`` frame (``lensfuncs.fold_radius`` at or below the
        corner radius) is a ``ValueError`` on both paths, as in :func:`glradial.distort`. With
        ``inverse="exact"`` pixels that no undistorted point maps to (beyond a barrel lens's reach)
        are 0; with ``"drap"`` a lens that fails :func:`lens_covers_frame` on ``size`` is a
        ``ValueError``.

        ``out`` may be a preallocated C-contiguous array of that shape and dtype. Crops are drawn
        ``tiles_per_pass`` at a time (one instanced draw call and one readback per pass).
        """
        if self._fbo is None:
            raise RuntimeError("CropRenderer was released")
        self._owner.enter()
        if isinstance(params, (CropParams, str, bytes)) or not hasattr(params, "__iter__"):
            raise TypeError(f"params must be a sequence of CropParams, got {type(params).__name__}")
        params = list(params)
        for i, item in enumerate(params):
            if not isinstance(item, CropParams):
                raise TypeError(f"params[{i}] must be a CropParams, got {type(item).__name__}")
            fold = lensfuncs.fold_radius(item.k1, item.k2)
            if fold <= self._corner:
                raise ValueError(
                    f"params[{i}]: lens k1={item.k1:g}, k2={item.k2:g} folds over at radius {fold:.4f} inside "
                    f"the {self.size[0]}×{self.size[1]} frame (corner radius {self._corner:.4f}): no crop is "
                    "rendered through it"
                )
            if self.inverse == "drap" and not lens_covers_frame(item.k1, item.k2, self.size):
                raise ValueError(
                    f"params[{i}]: lens k1={item.k1:g}, k2={item.k2:g} folds over or leaves parts of a "
                    f"{self.size[0]}×{self.size[1]} frame unreachable; the Drap-Lefevre polynomial has no "
                    f"validity test there (use inverse='exact', which fills such pixels with 0)"
                )
        w, h = self.out_size
        shape = (len(params), h, w, self.channels)
        if out is None:
            out = np.empty(shape, self.dtype)
        else:
            want = shape[:3] if self._squeeze else shape
            if out.shape not in (shape, want) or out.dtype != self.dtype or not out.flags.c_contiguous:
                raise ValueError(f"out must be a C-contiguous {self.dtype} array of shape {want}, got {out.dtype} {out.shape}")
            out = out.reshape(shape)
        ctx = self.ctx
        for start in range(0, len(params), self.tiles_per_pass):
            batch = params[start : start + self.tiles_per_pass]
            n = len(batch)
            table = self._params[:n]
            for j, item in enumerate(batch):
                table[j, :3, :3] = item.rotation()
                table[j, :3, 3] = (item.focal, item.k1, item.k2)
            table[:, 5, 3] = np.arange(n)  # tile index
            use_series = np.zeros(n, bool)
            if self.series_inverse:
                coefficients, use_series = fit_inverse_series(table[:, 1, 3], table[:, 2, 3], self._corner)
                table.reshape(n, _INSTANCE_FLOATS)[:, 12 : 13 + SERIES_DEGREE] = coefficients
            self._fbo.use()
            ctx.viewport = (0, 0, w, n * h)
            self._pano.use(0)
            for path, (prog, vao, instances) in self._draws.items():
                chosen = table[use_series] if path == "series" else table[~use_series]
                if len(chosen):
                    instances.write(np.ascontiguousarray(chosen).tobytes())
                    prog["u_tiles"].value = n
                    vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=len(chosen))
            self._read_atlas(out[start : start + n], n)
        return out[..., 0] if self._squeeze else out

    def _read_atlas(self, dest: np.ndarray, n: int) -> None:
        """Copy the first ``n`` tiles of the atlas into ``dest`` (``(n, h, w, C)``, C-contiguous)."""
        import cv2

        w, h = self.out_size
        tex_dtype = TEXTURE_FORMATS[self.dtype][0]
        if self.channels != 3:
            self._fbo.read_into(dest, viewport=(0, 0, w, n * h), components=self.channels, alignment=1, dtype=tex_dtype)
            return
        if self._rgba_scratch is None or len(self._rgba_scratch) < n * h:
            self._rgba_scratch = np.empty((n * h, w, 4), self.dtype)
        rgba = self._rgba_scratch[: n * h]
        self._fbo.read_into(rgba, viewport=(0, 0, w, n * h), components=4, alignment=1, dtype=tex_dtype)
        rgb = dest.reshape(n * h, w, 3)
        written = cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB, dst=rgb)
        if not np.shares_memory(written, rgb):  # OpenCV allocated instead of writing in place
            rgb[...] = written

    def release(self) -> None:
        """Free the GL objects (idempotent)."""
        from ..gl.egl import release_objects

        objects = getattr(self, "_objects", [])
        if objects:
            self._owner.enter()
            self._objects = []
            release_objects(self.ctx, *reversed(objects))
        self._fbo = None
        self._rgba_scratch = None

    def __enter__(self) -> "CropRenderer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def render_crops(
    panorama: np.ndarray,
    params: Sequence[CropParams],
    *,
    size: tuple[int, int] = PAPER_SIZE,
    out_size: tuple[int, int] | None = None,
    inverse: InverseMethod = "exact",
    supersample: int | tuple[int, int] | Literal["auto"] = 1,
) -> np.ndarray:
    """Render ``params`` from ``panorama`` once (a :class:`CropRenderer` made and released).

    Args:
        panorama, size, out_size, inverse, supersample: as :class:`CropRenderer`.
        params: the crops (:class:`CropParams`).

    Returns:
        ``(N, h, w, C)`` array of the panorama's dtype (``(w, h)`` = ``out_size`` or ``size``).

    Raises:
        ValueError, TypeError: as :class:`CropRenderer`.

    Example:
        >>> import numpy as np, glradial
        >>> panorama = np.full((64, 128), 1000, np.uint16)
        >>> crops = glradial.render_crops(panorama, glradial.sample_crop_params(2, seed=0), size=(32, 18))
        >>> crops.shape, crops.dtype
        ((2, 18, 32), dtype('uint16'))
    """
    with CropRenderer(panorama, size=size, out_size=out_size, inverse=inverse, supersample=supersample) as renderer:
        return renderer.render(params)


def load_panorama(item: object) -> np.ndarray:
    """A panorama as H×W×3 uint8 RGB: arrays through :func:`glradial.media.frames.to_rgb8` (grey repeated,
    alpha dropped, 16-bit and float scaled); paths read (image files through OpenCV, ``.npy``
    arrays such as the stadium cache, or a crop producer's panoramas, mapped by NumPy)."""
    from ..media.frames import to_rgb8

    if isinstance(item, (str, os.PathLike)):
        if not str(item).endswith(".npy"):
            import cv2

            image = cv2.imread(str(item), cv2.IMREAD_COLOR)
            if image is None:
                raise ValueError(f"cannot read panorama {str(item)!r}")
            return np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
        item = np.load(item, mmap_mode="r")  # mapped: only what a uint8 RGB array needs is copied
    return to_rgb8(np.asarray(item), "panorama")


def panorama_file_size(path: str | os.PathLike) -> tuple[int, int]:
    """``(width, height)`` of the panorama file ``path`` (an image file or a ``.npy`` array, as
    :func:`load_panorama` reads them), checked before any work is done: ``FileNotFoundError`` if it is
    missing, ``ValueError`` naming it if it is not a readable panorama or not 2:1 (W = 2 H). Image
    sizes come from the header (Pillow) where it knows the format; other files are decoded (OpenCV).
    A file whose header is fine but whose pixels are corrupt is caught only when it is rendered."""
    name = str(path)
    if not os.path.isfile(name):
        raise FileNotFoundError(f"panorama {name!r} does not exist or is not a file")
    if name.endswith(".npy"):
        try:
            shape = np.load(name, mmap_mode="r").shape
        except Exception as err:  # noqa: BLE001 - any failure means "not a readable array"
            raise ValueError(f"cannot read panorama {name!r}: not a NumPy .npy array ({err})") from None
        if len(shape) not in (2, 3):
            raise ValueError(f"panorama {name!r} must be an H×W or H×W×C array, got shape {shape}")
        height, width = int(shape[0]), int(shape[1])
    else:
        from PIL import Image

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                with Image.open(name) as image:
                    width, height = image.size
        except Exception:  # noqa: BLE001 - a format Pillow does not know, or not an image: ask OpenCV
            import cv2

            from ..media.native_stderr import silenced

            with silenced():
                decoded = cv2.imread(name, cv2.IMREAD_UNCHANGED)
            if decoded is None:
                raise ValueError(f"cannot read panorama {name!r}: not an image file") from None
            height, width = decoded.shape[:2]
    if height < 1 or width != 2 * height:
        raise ValueError(f"panorama {name!r} must be equirectangular 2:1 (W = 2 H), got {width}×{height}")
    return width, height


class PanoramaRenderers:
    """:class:`CropRenderer` s for a list of panoramas, and the one loop that renders crops of several.

    ``panoramas``: arrays or paths (:func:`load_panorama`: loaded, as RGB uint8, when first used).
    A panorama's renderer is made on first use with ``renderer_options`` (keywords of
    :class:`CropRenderer`); the ``cache`` most recently used stay uploaded, older ones are released.
    :meth:`render` draws crop ``i`` of ``params`` from panorama ``which[i]``. Same thread and process
    rules as :class:`CropRenderer`; :meth:`close` (or ``with``) releases them all.
    """

    def __init__(self, panoramas: Sequence[object], *, cache: int = 1, **renderer_options: object) -> None:
        check_count("cache", cache)
        self.panoramas = list(panoramas)
        self.cache = int(cache)
        self.options = renderer_options
        self._renderers: dict[int, CropRenderer] = {}  # least recently used first

    def renderer(self, index: int) -> CropRenderer:
        """The renderer of panorama ``index`` (made, and the least recently used one released, if needed)."""
        found = self._renderers.pop(index, None)
        if found is None:
            while len(self._renderers) >= self.cache:
                self._renderers.pop(next(iter(self._renderers))).release()
            found = CropRenderer(load_panorama(self.panoramas[index]), **self.options)  # type: ignore[arg-type]
        self._renderers[index] = found
        return found

    def render(self, params: Sequence[CropParams], which: Sequence[int] | np.ndarray) -> np.ndarray:
        """Crop ``i`` of ``params`` from panorama ``which[i]`` -> uint8 RGB ``(N, h, w, 3)``, in order
        (one :meth:`CropRenderer.render` call per panorama, panoramas in index order)."""
        params = list(params)
        which = np.asarray(which, np.int64).reshape(-1)
        if len(which) != len(params):
            raise ValueError(f"which must give one panorama per crop: {len(which)} for {len(params)} crops")
        if len(which) and (which.min() < 0 or which.max() >= len(self.panoramas)):
            raise ValueError(f"which must index the {len(self.panoramas)} panoramas, got {which.min()}..{which.max()}")
        images: np.ndarray | None = None
        for pano in np.unique(which):
            rows = np.flatnonzero(which == pano)
            part = self.renderer(int(pano)).render([params[r] for r in rows])
            if images is None:
                images = np.empty((len(params), *part.shape[1:]), part.dtype)
            images[rows] = part
        if images is None:
            w, h = frame_size(self.options.get("out_size") or self.options.get("size", PAPER_SIZE))
            images = np.empty((0, h, w, 3), np.uint8)
        return images

    def close(self) -> None:
        """Release every renderer (idempotent)."""
        for renderer in self._renderers.values():
            renderer.release()
        self._renderers.clear()

    def __enter__(self) -> "PanoramaRenderers":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def render_crop_set(
    panoramas: Sequence[object],
    n: int,
    seed: int,
    *,
    size: tuple[int, int] = PAPER_SIZE,
    out_size: tuple[int, int] | None = None,
    ranges: Mapping[str, object] | None = None,
) -> tuple[np.ndarray, list[CropParams]]:
    """``n`` crops spread evenly over ``panoramas`` (the first ``n % P`` get one more), for test and
    validation sets: panorama ``j`` draws its crops with ``sample_crop_params(count, seed * 1000 + j,
    size=size, **ranges)``, rendered at ``out_size`` (no augmentation; panoramas as in
    :func:`load_panorama`). Returns uint8 RGB ``(n, h, w, 3)`` images and the :class:`CropParams`
    of each crop, in order."""
    if not panoramas:
        raise ValueError("panoramas must not be empty")
    check_count("n", n)
    counts = [n // len(panoramas) + (1 if i < n % len(panoramas) else 0) for i in range(len(panoramas))]
    params: list[CropParams] = []
    which: list[int] = []
    for j, count in enumerate(counts):
        if count:
            params += sample_crop_params(count, seed * 1000 + j, size=size, **dict(ranges or {}))
            which += [j] * count
    with PanoramaRenderers(panoramas, size=size, out_size=out_size) as renderers:
        return renderers.render(params, which), params


def crop_labels(params: Sequence[CropParams], dtype: type = np.float64) -> np.ndarray:
    """``(k1, k2)`` of each crop as an ``N x 2`` array (lens units of the crops' frame geometry)."""
    return np.array([(p.k1, p.k2) for p in params], dtype).reshape(-1, 2)
