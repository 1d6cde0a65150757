"""The broadcast camera as a pinhole with a two-coefficient radial lens, and the plane homography.

Conventions:
    * Pitch (world) coordinates: metres, :mod:`glradial.pitch.template` (origin at the centre spot, x
      along the touchlines, y toward the far touchline, z up).
    * Camera coordinates: x right, y down, z forward (OpenCV). ``rotation`` maps world to camera,
      ``X_cam = rotation @ (X - position)``; ``position`` is the camera centre in pitch metres.
    * Intrinsics: principal point at the image centre, square pixels, ``focal`` in image widths (the
      lens coordinates of :mod:`glradial.lens.lens`: the undistorted lens point of a camera-space point
      is ``focal * (X/Z, Y/Z)``), so ``f_px = focal * W`` and the horizontal field of view is
      ``2 atan(1 / (2 focal))``. The lens (width-normalised k1, k2, :class:`glradial.Lens`) then maps
      undistorted to distorted lens points (its forward model); pixels follow the lens convention
      (pixel centres at integers, :func:`glradial.lens.lens.lens_to_pixels`).
    * ``homography``: pitch plane ``(x, y, 1)`` -> **undistorted** pixels of the frame.
    * Pan, tilt, roll (degrees): pan is the optical axis's azimuth from +y (toward the far touchline),
      positive toward +x; tilt is its angle below the horizon; roll turns the image clockwise.

The half-turn ambiguity: the markings are symmetric under ``(x, y) -> (-x, -y)``, so a frame fits two
cameras, one on each touchline. :func:`decompose_homography` (and so every camera glradial reports)
keeps the one with ``position.y < 0``: the main camera on the near touchline. A mirror image of the
pitch (``x -> -x``) would put the camera below the plane and is rejected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..lens.lens import Lens, focal_from_hfov, frame_size, hfov_deg, lens_to_pixels
from ..lens.lensfuncs import LENS_RADIUS_UNBOUNDED, fold_radii, fold_radius, radial_factor

#: The half turn of the pitch about its centre spot.
HALF_TURN = np.diag([-1.0, -1.0, 1.0])


def _matrix(name: str, value: object, shape: tuple[int, ...]) -> np.ndarray:
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a numeric array of shape {shape}, got {value!r}") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite array of shape {shape}, got {a.tolist()}")
    a.setflags(write=False)
    return a


def points3(points: object, name: str = "points") -> np.ndarray:
    """``N x 3`` float64 pitch points from ``N x 3`` or ``N x 2`` (z = 0) input."""
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an N×3 or N×2 array of metres, got {points!r}") from None
    if p.ndim == 1 and p.shape[0] in (2, 3):
        p = p[None]
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"{name} must be an N×3 or N×2 array of metres, got shape {p.shape}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    return p


@dataclass(frozen=True)
class Camera:
    """A pinhole camera with a radial lens seeing a ``size = (W, H)`` frame (see the module docstring)."""

    rotation: np.ndarray
    position: np.ndarray
    focal: float
    size: tuple[int, int]
    lens: Lens = field(default_factory=lambda: Lens(0.0, 0.0))

    def __post_init__(self) -> None:
        r = _matrix("rotation", self.rotation, (3, 3))
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise ValueError(f"rotation must be a proper rotation matrix, got {r.tolist()}")
        object.__setattr__(self, "rotation", r)
        object.__setattr__(self, "position", _matrix("position", self.position, (3,)))
        focal = float(self.focal) if isinstance(self.focal, (int, float, np.number)) and not isinstance(self.focal, bool) else None
        if focal is None or not math.isfinite(focal) or focal <= 0:
            raise ValueError(f"focal must be a positive number of image widths, got {self.focal!r}")
        object.__setattr__(self, "focal", focal)
        object.__setattr__(self, "size", frame_size(self.size))
        if not isinstance(self.lens, Lens):
            raise TypeError(f"lens must be a glradial.Lens, got {self.lens!r}")

    # -- intrinsics ---------------------------------------------------------------------------------
    @property
    def hfov_deg(self) -> float:
        """Horizontal field of view of the undistorted frame (degrees)."""
        return hfov_deg(self.focal)

    @property
    def intrinsics(self) -> np.ndarray:
        """3 x 3 camera matrix in pixels (``f_px = focal W``, principal point at the centre)."""
        return intrinsics(self.focal, self.size)

    # -- pose -------------------------------------------------------------------------------------
    @property
    def pan_tilt_roll(self) -> tuple[float, float, float]:
        """Pan, tilt, roll in degrees (see the module docstring)."""
        forward, right = self.rotation[2], self.rotation[0]
        pan = math.degrees(math.atan2(forward[0], forward[1]))
        tilt = math.degrees(math.asin(float(np.clip(-forward[2], -1.0, 1.0))))
        level = np.cross(forward, [0.0, 0.0, 1.0])
        level /= max(np.linalg.norm(level), 1e-12)
        down = np.cross(forward, level)
        return pan, tilt, math.degrees(math.atan2(float(right @ down), float(right @ level)))

    @classmethod
    def look_at(cls, position, target, hfov: float, size: tuple[int, int], lens: Lens | None = None,
                roll: float = 0.0) -> "Camera":
        """The camera at ``position`` (metres) looking at ``target`` (metres, 2 or 3 values), with
        horizontal field of view ``hfov`` (degrees) and ``roll`` (degrees, clockwise in the image)."""
        c = np.asarray(position, float)
        t = np.asarray(list(target) + [0.0] * (3 - len(target)), float)
        forward = (t - c) / np.linalg.norm(t - c)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        a = math.radians(roll)
        rot = np.stack([math.cos(a) * right + math.sin(a) * down, -math.sin(a) * right + math.cos(a) * down, forward])
        return cls(rot, c, focal_from_hfov(hfov), size, lens or Lens(0.0, 0.0))

    # -- maps -------------------------------------------------------------------------------------
    @property
    def homography(self) -> np.ndarray:
        """3 x 3 map from the pitch plane ``(x, y, 1)`` (metres) to undistorted pixels."""
        r, t = self.rotation, -self.rotation @ self.position
        return self.intrinsics @ np.column_stack([r[:, 0], r[:, 1], t])

    def undistorted_lens_points(self, points: object) -> tuple[np.ndarray, np.ndarray]:
        """``(N x 2 undistorted lens points, N depths)`` of pitch points (N x 3 or N x 2 metres)."""
        p = points3(points)
        cam = (p - self.position) @ self.rotation.T
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = self.focal * cam[:, :2] / z[:, None]
        return uv, z

    def project(self, points: object) -> np.ndarray:
        """Pitch points (N x 3, or N x 2 with z = 0; metres) -> N x 2 pixels of the distorted frame,
        lens included (:func:`project_many`, the lens's forward map)."""
        lens = self.lens
        if not lens.is_centred:
            raise ValueError(f"camera lenses have the principal point at the centre and square pixels, got {lens!r}")
        return project_many(self.rotation[None], self.position[None], np.array([self.focal]), np.array([lens.k1]),
                            np.array([lens.k2]), self.size, points3(points))[0]

    def to_pitch(self, pixels: object) -> np.ndarray:
        """Pixels of the distorted frame (N x 2, or one pair) -> N x 2 pitch metres on the plane z = 0:
        the exact inverse of :meth:`project` for pitch-plane points (the lens's exact inverse, then
        the inverse homography). NaN where a pixel sees no point of the plane (above the horizon, or
        beyond the radius where the lens folds over)."""
        try:
            xy = np.asarray(pixels, dtype=np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"pixels must be an N×2 array of pixels, got {pixels!r}") from None
        if xy.ndim == 1 and xy.shape[0] == 2:
            xy = xy[None]
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"pixels must be an N×2 array of pixels, got shape {xy.shape}")
        return lens_points_to_pitch(self, xy)

    def with_size(self, size: tuple[int, int]) -> "Camera":
        """The same camera seeing a frame of another size (same field of view, same width-normalised
        lens): a resized frame."""
        return Camera(self.rotation, self.position, self.focal, size, self.lens)

    def turned(self) -> "Camera":
        """The same view with the pitch turned half round (the camera on the other touchline)."""
        return Camera(self.rotation @ HALF_TURN, HALF_TURN @ self.position, self.focal, self.size, self.lens)


def project_many(rotation: np.ndarray, position: np.ndarray, focal: np.ndarray, k1: np.ndarray, k2: np.ndarray,
                 size: tuple[int, int], points: np.ndarray, fold: np.ndarray | None = None) -> np.ndarray:
    """The one projection of pitch points to distorted pixels, for ``B`` cameras at once: ``rotation``
    B x 3 x 3, ``position`` B x 3, ``focal``, ``k1``, ``k2`` (B,), ``points`` M x 3 -> B x M x 2.

    Camera space ``X = R p - R C`` (every camera's rotation applied to the points in one product);
    undistorted lens point ``u = focal (X/Z, Y/Z)``; distorted lens
    point ``u (1 + k1 |u|² + k2 |u|⁴)`` (:func:`glradial.lens.lensfuncs.radial_factor`, the lens's
    forward model); pixels by :func:`glradial.lens.lens.lens_to_pixels`. NaN for points behind the
    camera or beyond the radius where the lens folds over (:func:`glradial.lens.lensfuncs.fold_radii`:
    the polynomial would bring them back into the frame; ``fold``: those radii (B,) when the caller
    has them, e.g. many projections through one lens). Each step runs on whole B x M planes (x and y
    apart): the refinement's Jacobian projects through ten cameras a few hundred times a frame."""
    shift = -np.einsum("bij,bj->bi", rotation, position)
    # one matrix product for all cameras: (3B x 3) rotations' rows times the 3 x M points
    cam = (np.ascontiguousarray(rotation).reshape(-1, 3) @ points.T).reshape(len(rotation), 3, -1) + shift[:, :, None]
    z = cam[:, 2]  # B x M
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = focal[:, None] / z
        u, v = cam[:, 0] * scale, cam[:, 1] * scale
        r2 = u * u + v * v
        if fold is None:  # a few lenses: each one's scalar root costs less than the vectorised one's arrays
            fold = np.array([fold_radius(a, b) for a, b in zip(k1.tolist(), k2.tolist())]) if len(k1) <= 16 else fold_radii(k1, k2)
        limit = np.where(fold >= LENS_RADIUS_UNBOUNDED, np.inf, fold)[:, None]
        factor = radial_factor(r2, k1[:, None], k2[:, None])
        factor[~((z > 0) & (r2 < limit * limit))] = np.nan
        pd = np.empty(u.shape + (2,))
        np.multiply(u, factor, out=pd[..., 0])
        np.multiply(v, factor, out=pd[..., 1])
    return lens_to_pixels(pd, size)


def intrinsics(focal: float, size: tuple[int, int]) -> np.ndarray:
    """3 x 3 pixel camera matrix: ``f_px = focal W``, principal point ``((W-1)/2, (H-1)/2)``."""
    width, height = size
    f = focal * width
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def plane_views(h: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Zhang's reading of plane homographies ``h`` (N x 3 x 3, pitch ``(x, y, 1)`` -> undistorted pixels
    of a ``size`` frame) with the principal point at the centre and square pixels known: ``(focal, m)``,
    the focal length in image widths (N; NaN where ``1 / f²`` comes out not positive) and
    ``m = diag(1/f, 1/f, 1) K₁⁻¹ h`` (N x 3 x 3; ``K₁`` the intrinsics of focal 1) scaled so that
    ``|m₁| + |m₂| = 2``: up to one common sign, the columns ``r1, r2, t`` of the camera's ``[R | t]``.

    The two constraints ``r1 . r2 = 0`` and ``|r1| = |r2|`` are solved for ``1 / f²`` by least squares
    (unscaled: scaling each to unit weight lets an ill-conditioned one decide, and loses line
    hypotheses of clear views). The one decomposition of a homography in glradial:
    :func:`decompose_homography` and the first guess's plausibility test use it."""
    width, height = frame_size(size)
    a = np.array(h, dtype=np.float64, copy=True)
    a[:, 0] = (a[:, 0] - (width - 1) / 2.0 * a[:, 2]) / width
    a[:, 1] = (a[:, 1] - (height - 1) / 2.0 * a[:, 2]) / width
    (h11, h12), (h21, h22), (h31, h32) = a[:, 0, :2].T, a[:, 1, :2].T, a[:, 2, :2].T
    rows = np.stack([np.stack([h11 * h12 + h21 * h22, h31 * h32], axis=-1),
                     np.stack([h11 ** 2 + h21 ** 2 - h12 ** 2 - h22 ** 2, h31 ** 2 - h32 ** 2], axis=-1)], axis=1)
    with np.errstate(all="ignore"):
        w = -np.sum(rows[..., 0] * rows[..., 1], axis=1) / np.maximum(np.sum(rows[..., 0] ** 2, axis=1), 1e-300)
        focal = np.where(np.isfinite(w) & (w > 0), 1.0 / np.sqrt(np.abs(w)), np.nan)
        a[:, :2] /= focal[:, None, None]
        a /= (0.5 * (np.linalg.norm(a[:, :, 0], axis=1) + np.linalg.norm(a[:, :, 1], axis=1)))[:, None, None]
    return focal, a


def decompose_homography(h: object, size: tuple[int, int], lens: Lens | None = None) -> Camera | None:
    """The camera (focal, rotation, position) of a plane homography ``h`` (pitch ``(x, y, 1)`` ->
    undistorted pixels of a ``size`` frame), principal point at the centre and square pixels known
    (:func:`plane_views`).

    The camera above the pitch is kept; of the half-turn pair, the one with ``position.y < 0``.
    ``None`` when ``h`` is no view of a plane from above (``1 / f² <= 0``, singular, or mirrored)."""
    size = frame_size(size)
    hm = _matrix("h", h, (3, 3))
    focal, m = plane_views(hm[None], size)
    f = float(focal[0])
    if not math.isfinite(f) or not np.all(np.isfinite(m)):
        return None
    for sign in (1.0, -1.0):
        r1, r2, t = sign * m[0, :, 0], sign * m[0, :, 1], sign * m[0, :, 2]
        u, _, vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
        rot = u @ vt
        if np.linalg.det(rot) < 0:
            continue
        position = -rot.T @ t
        if position[2] > 0 and t[2] > 0:  # above the plane, the pitch origin in front
            cam = Camera(rot, position, f, size, lens or Lens(0.0, 0.0))
            return cam.turned() if position[1] > 0 else cam
    return None


def lens_points_to_pitch(camera: Camera, xy: np.ndarray) -> np.ndarray:
    """Distorted pixels (N x 2) of ``camera``'s frame -> pitch points (N x 2 metres, z = 0), through
    the lens's exact inverse and the inverse homography (NaN where undefined or above the horizon)."""
    und = camera.lens.undistort_points(np.asarray(xy, float), camera.size)
    p = np.column_stack([und, np.ones(len(und))]) @ np.linalg.inv(camera.homography).T
    with np.errstate(divide="ignore", invalid="ignore"):
        out = p[:, :2] / p[:, 2:3]
    out[~(p[:, 2] > 0)] = np.nan
    return out


