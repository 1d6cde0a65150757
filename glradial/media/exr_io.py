"""OpenEXR still images (scene-linear, float) read and written with the OpenEXR project's own Python
bindings, atomically, keeping what an EXR holds.

Convention:

* An :class:`ExrImage` is a set of named channels (``"R"``, ``"G"``, ``"B"``, ``"A"``, ``"Y"``,
  ``"Z"``, ``"diffuse.R"`` ...), each an ``H x W`` array of ``float16`` (EXR HALF) or ``float32``
  (EXR FLOAT), plus the file's header (compression, line order, pixel aspect, any custom attribute).
  Values are scene-linear and may lie anywhere in the format's range: nothing is clipped to [0, 1].
* Row 0 is the top of the picture; the data window must equal the display window (a picture with
  an offset or a region of interest is refused: the lens geometry is the display window's).
* Colour channels are premultiplied by alpha (the OpenEXR convention); glradial resamples each
  channel as it is stored, which is the correct (premultiplied) interpolation for such files.
* What cannot be kept is an error (``ValueError`` naming the file and the channel): UINT channels
  (object ids cannot be resampled), subsampled channels, deep or multi-part files, a result beyond
  HALF's range (±65504) for a HALF channel.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import atomic_path, check_output_folder, check_overwrite

__all__ = ["ExrImage", "read_exr", "write_exr", "channel_groups", "HALF_MAX"]

#: the largest finite value of an EXR HALF channel
HALF_MAX = float(np.finfo(np.float16).max)
#: header entries written by the bindings themselves (channels come from the arrays)
_DERIVED = ("channels",)


@dataclass
class ExrImage:
    """Named ``H x W`` channels (float16 = HALF, float32 = FLOAT) and the header they came with."""

    channels: dict[str, np.ndarray]
    header: dict = field(default_factory=dict)

    @property
    def size(self) -> tuple[int, int]:
        """``(W, H)`` in pixels."""
        height, width = next(iter(self.channels.values())).shape
        return width, height

    def replaced(self, channels: dict[str, np.ndarray]) -> "ExrImage":
        """The same header with new channel data, each cast back to the type it had here."""
        return ExrImage({name: channels[name].astype(self.channels[name].dtype, copy=False) for name in self.channels},
                        dict(self.header))


def _window(header: dict, key: str) -> tuple[int, ...]:
    low, high = header[key]
    return tuple(int(v) for v in low) + tuple(int(v) for v in high)


def read_exr(path: str | os.PathLike) -> ExrImage:
    """Read a single-part scanline or tiled OpenEXR file (every channel, its type kept)."""
    import OpenEXR

    source = Path(path)
    if not source.is_file():
        raise FileNotFoundError(f"input file {str(source)!r} does not exist")
    try:
        exr = OpenEXR.File(str(source), separate_channels=True)
    except Exception as err:  # the bindings raise a bare RuntimeError/Exception on a bad file
        raise ValueError(f"cannot read OpenEXR image {str(source)!r}: {err}") from None
    with exr:
        if len(exr.parts) != 1:
            raise ValueError(f"OpenEXR image {str(source)!r} has {len(exr.parts)} parts; glradial reads single-part files")
        header = dict(exr.header())
        channels = {}
        for name, channel in exr.channels().items():
            pixels = np.asarray(channel.pixels)
            if channel.xSampling != 1 or channel.ySampling != 1:
                raise ValueError(f"OpenEXR image {str(source)!r}: channel {name!r} is subsampled, which glradial cannot keep")
            if pixels.dtype not in (np.float16, np.float32):
                raise ValueError(f"OpenEXR image {str(source)!r}: channel {name!r} holds {pixels.dtype} samples "
                                 "(ids or counts), which cannot be resampled")
            channels[name] = pixels
    if not channels:
        raise ValueError(f"OpenEXR image {str(source)!r} has no channels")
    if _window(header, "dataWindow") != _window(header, "displayWindow"):
        raise ValueError(f"OpenEXR image {str(source)!r}: its data window {_window(header, 'dataWindow')} differs from "
                         f"its display window {_window(header, 'displayWindow')}; crop or extend it to the display window first")
    return ExrImage(channels, {k: v for k, v in header.items() if k not in _DERIVED})


def write_exr(path: str | os.PathLike, image: ExrImage, *, overwrite: bool = True) -> Path:
    """Write ``image`` atomically (its header's compression and attributes, ZIP when it names none);
    ``ValueError`` for non-finite values or values beyond HALF's range in a HALF channel."""
    import OpenEXR

    target = check_output_folder(path)
    check_overwrite(target, overwrite)
    if not image.channels:
        raise ValueError(f"cannot write {str(target)!r}: the EXR image has no channels")
    for name, pixels in image.channels.items():
        if pixels.dtype not in (np.float16, np.float32) or pixels.ndim != 2:
            raise ValueError(f"EXR channel {name!r} must be a 2-D float16 or float32 array, got {pixels.dtype} {pixels.shape}")
        largest = float(np.max(np.abs(pixels.astype(np.float32)))) if pixels.size else 0.0
        if not np.isfinite(largest):
            raise ValueError(f"cannot write {str(target)!r}: channel {name!r} holds values beyond its type's range "
                             f"(HALF stores up to ±{HALF_MAX:g}) or NaN")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, **image.header}
    header.pop("dataWindow", None), header.pop("displayWindow", None)  # from the arrays
    channels = {name: np.ascontiguousarray(pixels) for name, pixels in image.channels.items()}
    with atomic_path(target) as tmp, OpenEXR.File(header, channels) as exr:
        exr.write(str(tmp))
    return target


def channel_groups(names: list[str] | tuple[str, ...]) -> list[tuple[str, ...]]:
    """The channels resampled together: each layer's ``R, G, B`` (with its ``A`` when present) as one
    group (so that an alpha convention applies to it), every other channel alone, in name order."""
    groups: list[tuple[str, ...]] = []
    used: set[str] = set()
    for layer in sorted({name.rpartition(".")[0] for name in names}):
        prefix = f"{layer}." if layer else ""
        colour = tuple(prefix + c for c in "RGB")
        if all(name in names for name in colour):
            group = colour + ((prefix + "A",) if prefix + "A" in names else ())
            groups.append(group)
            used.update(group)
    groups.extend((name,) for name in sorted(names) if name not in used)
    return groups
