"""Frame coercion, defined once: any image array glradial accepts -> contiguous H×W×3 uint8.

Accepted: ``H×W`` (grey, repeated to three channels) or ``H×W×C`` with ``C`` in (1, 3, 4) (alpha
dropped); uint8 as is, uint16 scaled by 255/65535 (rounded), float32/float64 in [0, 1] (values
outside are clipped, or with ``clip=False`` an error; NaN or infinity is an error) scaled by 255
(rounded). Channel order is kept
(RGB in, RGB out). Anything else is a ``TypeError`` or ``ValueError`` naming the argument.
"""

from __future__ import annotations

import numpy as np

__all__ = ["to_rgb8"]


def to_rgb8(frame: object, name: str = "frame", *, clip: bool = True) -> np.ndarray:
    """``frame`` as a contiguous ``H × W × 3`` uint8 array (see the module docstring)."""
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"{name} must be a NumPy array, got {type(frame).__name__}")
    array = frame[:, :, None] if frame.ndim == 2 else frame
    if array.ndim != 3 or array.shape[2] not in (1, 3, 4):
        raise ValueError(f"{name} must be H×W or H×W×C with C in (1, 3, 4), got shape {frame.shape}")
    if array.dtype == np.uint8:
        pass
    elif array.dtype == np.uint16:
        array = (array / 257.0 + 0.5).astype(np.uint8)
    elif array.dtype in (np.float32, np.float64):
        if not np.isfinite(array).all():
            raise ValueError(f"{name} contains NaN or infinite values")
        if not clip:
            low, high = float(array.min()), float(array.max())
            if low < 0.0 or high > 1.0:
                raise ValueError(f"float {name} must have values in [0, 1], got [{low:g}, {high:g}]")
        array = (np.clip(array, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    else:
        raise TypeError(f"{name} dtype must be uint8, uint16 or float32/float64 in [0, 1], got {array.dtype}")
    if array.shape[2] == 1:
        array = np.repeat(array, 3, axis=2)
    return np.ascontiguousarray(array[:, :, :3])
