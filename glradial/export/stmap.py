"""STMaps for compositing tools (Nuke's STMap node, Fusion, Natron, After Effects plug-ins).

Convention (Nuke's): an STMap is an ``H x W`` image whose red channel ``S`` and green channel ``T``
tell, for each output pixel, where to sample the source, in normalised coordinates with the origin
at the *bottom-left* corner of the source and ``(1, 1)`` at its top-right corner:

    S = (x_src + 0.5) / W            T = 1 - (y_src + 0.5) / H

where ``(x_src, y_src)`` is the source pixel position (glradial pixel convention: centres at
integers, ``y`` down, row 0 at the top) that :meth:`glradial.Lens.maps` gives for the output pixel.
The blue channel is 0. Rows are stored top row first, as in any image file, so the identity STMap
has ``T`` close to 1 in the first row and ``S`` close to 0 in the first column. Output pixels that
have no source (only when distorting with a strong barrel lens, beyond the largest distorted
radius) hold ``S = T =`` :data:`STMAP_NO_SOURCE` (outside ``[0, 1]``, so the compositor shows its
outside colour there).

``direction="undistort"``: applying the STMap to the *distorted* footage yields the corrected frame
(the same as :func:`glradial.correct`). ``direction="distort"``: applying it to an undistorted
render (CG, graphics) yields the distorted frame (the same as :func:`glradial.distort`).

Files: ``.exr`` = OpenEXR with 32-bit float R, G, B channels, ZIP-compressed (lossless; what Nuke,
Natron and Gyroflow load; written with the OpenEXR project's own Python bindings),
``.tif``/``.tiff`` = uncompressed 32-bit float RGB TIFF (OpenCV's writer), ``.npy`` = the same
``H x W x 3`` float32 array (R, G, B order).

Unreal Engine's layout (``layout="unreal"``; CameraCalibration plug-in, lens file "ST Map"
distortion source: "RG channels are expected to have the undistortion map (from distorted to
undistorted), BA channels the distortion map (from undistorted (CG) to distorted)"): one RGBA
float image, R, G = the ``"undistort"`` map's (S, T) and B, A = the ``"distort"`` map's, with the
pixel origin selectable: ``"top-left"`` (``T = (y_src + 0.5) / H``, v down) or ``"bottom-left"``
(Nuke's ``T`` above). Written as a 4-channel file (EXR R, G, B, A).

Overscan (:mod:`glradial.export.overscan`): with ``overscan = Ω > 1`` the undistorted side of a map
is the overscanned render (its field ``Ω`` times the frame's, about the screen centre): the
``"distort"`` map samples that render, the ``"undistort"`` map produces it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..lens.lens import NO_SOURCE, Lens, frame_size
from ..lens.options import ORIGINS, check_choice
from ..media.atomic import atomic_path, check_output_folder
from ..media.native_stderr import silenced
from .overscan import uv_maps

__all__ = ["STMAP_EXTENSIONS", "STMAP_NO_SOURCE", "check_stmap_path", "stmap_from_maps", "maps_from_stmap",
           "lens_stmap", "unreal_stmap", "write_stmap", "read_stmap"]

#: S and T of output pixels without a source
STMAP_NO_SOURCE = -1.0

#: file extensions :func:`write_stmap` and :func:`read_stmap` handle
STMAP_EXTENSIONS = (".exr", ".tif", ".tiff", ".npy")


def stmap_from_maps(map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    """``cv2.remap`` maps (pixels of a source of the same ``W x H``) -> STMap ``H x W x 3`` float32.

    Map entries at or beyond :data:`glradial.lens.lens.NO_SOURCE` become :data:`STMAP_NO_SOURCE`."""
    map_x = np.asarray(map_x, dtype=np.float64)
    map_y = np.asarray(map_y, dtype=np.float64)
    if map_x.shape != map_y.shape or map_x.ndim != 2:
        raise ValueError(f"map_x and map_y must be equal H×W arrays, got {map_x.shape} and {map_y.shape}")
    height, width = map_x.shape
    missing = (map_x <= NO_SOURCE / 2) | (map_y <= NO_SOURCE / 2)
    uv = np.stack([(map_x + 0.5) / width, (map_y + 0.5) / height], axis=-1)
    stmap = np.zeros((height, width, 3), dtype=np.float32)
    stmap[..., 0:2] = _st(np.where(missing[..., None], np.nan, uv), "bottom-left")
    return stmap


def _st(uv: np.ndarray, origin: str) -> np.ndarray:
    """Normalised source coordinates (..., 2) (origin top-left, v down, NaN = no source) -> (S, T)
    float32 with the pixel ``origin``'s T; no source -> :data:`STMAP_NO_SOURCE`."""
    check_choice("origin", origin, ORIGINS)
    st = np.array(uv, dtype=np.float64)
    if origin == "bottom-left":
        st[..., 1] = 1.0 - st[..., 1]
    st[~np.all(np.isfinite(st), axis=-1)] = STMAP_NO_SOURCE
    return st.astype(np.float32)


def maps_from_stmap(stmap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`stmap_from_maps` (``cv2.remap``-ready float32 maps); pixels without a
    source map to :data:`glradial.lens.lens.NO_SOURCE`."""
    stmap = np.asarray(stmap)
    if stmap.ndim != 3 or stmap.shape[2] < 2:
        raise ValueError(f"an STMap must be H×W×C with C >= 2, got shape {stmap.shape}")
    height, width = stmap.shape[:2]
    s = stmap[..., 0].astype(np.float64)
    t = stmap[..., 1].astype(np.float64)
    missing = (s == STMAP_NO_SOURCE) & (t == STMAP_NO_SOURCE)
    map_x = np.where(missing, NO_SOURCE, s * width - 0.5)
    map_y = np.where(missing, NO_SOURCE, (1.0 - t) * height - 0.5)
    return map_x.astype(np.float32), map_y.astype(np.float32)


def lens_stmap(
    lens: Lens,
    size: tuple[int, int],
    direction: str = "undistort",
    fit: str = "same",
    inverse: str = "exact",
    overscan: float | None = None,
) -> np.ndarray:
    """The STMap of ``lens`` on a ``(W, H)`` frame (see the module docstring), ``H x W x 3`` float32.

    Computed in float64 from :meth:`Lens.maps` (or, with ``overscan``, from
    :func:`glradial.export.overscan.uv_maps`, which replaces ``fit``) and rounded once to float32."""
    if overscan is not None:
        stmap = np.zeros((*frame_size(size)[::-1], 3), dtype=np.float32)
        stmap[..., 0:2] = _st(uv_maps(lens, size, direction, overscan), "bottom-left")
        return stmap
    map_x, map_y = lens.maps(size, direction=direction, fit=fit, inverse=inverse, dtype=np.float64)
    return stmap_from_maps(map_x, map_y)


def unreal_stmap(lens: Lens, size: tuple[int, int], overscan: float = 1.0, origin: str = "top-left") -> np.ndarray:
    """Unreal Engine's ST map of ``lens`` (module docstring): ``H x W x 4`` float32, R, G = the
    undistortion map, B, A = the distortion map (exact inverse), T with the pixel ``origin``."""
    width, height = frame_size(size)
    stmap = np.empty((height, width, 4), dtype=np.float32)
    stmap[..., 0:2] = _st(uv_maps(lens, (width, height), "undistort", overscan), origin)
    stmap[..., 2:4] = _st(uv_maps(lens, (width, height), "distort", overscan), origin)
    return stmap


def check_stmap_path(path: str | os.PathLike) -> Path:
    """``path`` as a :class:`Path` if its extension is one of :data:`STMAP_EXTENSIONS`, else ``ValueError``."""
    target = Path(path)
    if target.suffix.lower() not in STMAP_EXTENSIONS:
        known = ", ".join(STMAP_EXTENSIONS)
        raise ValueError(f"unknown STMap extension {target.suffix or '(none)'!r} of {str(target)!r}; use {known}")
    return target


def write_stmap(path: str | os.PathLike, stmap: np.ndarray) -> Path:
    """Write an STMap atomically: ``.exr`` (float32 R, G, B(, A), ZIP), float32 RGB(A) TIFF or ``.npy``."""
    target = check_output_folder(check_stmap_path(path))
    ext = target.suffix.lower()
    stmap = np.asarray(stmap, dtype=np.float32)
    if stmap.ndim != 3 or stmap.shape[2] not in (3, 4):
        raise ValueError(f"an STMap must be H×W×3 (RGB) or H×W×4 (RGBA, Unreal's layout), got shape {stmap.shape}")
    if ext in (".tif", ".tiff"):
        from ..media.image_io import write_image

        return write_image(target, stmap)  # float32 RGB TIFF, written atomically
    with atomic_path(target) as tmp:
        if ext == ".npy":
            with open(tmp, "wb") as handle:
                np.save(handle, stmap)
        else:
            _write_exr(tmp, stmap)
    return target


def _write_exr(path: Path, stmap: np.ndarray) -> None:
    """Scanline OpenEXR, one float32 channel each for R, G, B (and A), ZIP compression (16-line blocks)."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {name: np.ascontiguousarray(stmap[..., i]) for i, name in enumerate("RGBA"[: stmap.shape[2]])}
    with OpenEXR.File(header, channels) as exr:
        exr.write(str(path))


def _read_exr(source: Path) -> np.ndarray:
    import OpenEXR

    try:
        with OpenEXR.File(str(source), separate_channels=True) as exr:
            channels = exr.channels()
            missing = [name for name in "RGB" if name not in channels]
            if missing:
                raise ValueError(f"EXR STMap {str(source)!r} lacks channel(s) {', '.join(missing)} (has {', '.join(sorted(channels))})")
            names = "RGBA" if "A" in channels else "RGB"
            planes = [np.asarray(channels[name].pixels, dtype=np.float32) for name in names]
    except ValueError:
        raise
    except Exception as err:  # the bindings raise RuntimeError/OSError for unreadable files
        raise ValueError(f"cannot read {str(source)!r} as an EXR STMap: {err}") from None
    return np.stack(planes, axis=-1)


def read_stmap(path: str | os.PathLike) -> np.ndarray:
    """Read an STMap written by :func:`write_stmap` (``H x W x 3`` or ``x 4`` float32, R, G, B(, A) order)."""
    source = check_stmap_path(path)
    if not source.is_file():
        raise FileNotFoundError(f"STMap file {str(source)!r} does not exist")
    ext = source.suffix.lower()
    if ext == ".npy":
        return np.load(source).astype(np.float32)
    if ext == ".exr":
        return _read_exr(source)
    import cv2

    with silenced():
        image = cv2.imread(str(source), cv2.IMREAD_UNCHANGED)
    if image is None or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ValueError(f"cannot read {str(source)!r} as a 3- or 4-channel float STMap")
    order = [2, 1, 0, 3][: image.shape[2]]  # OpenCV's BGR(A) -> RGB(A)
    return np.ascontiguousarray(image[..., order]).astype(np.float32)
