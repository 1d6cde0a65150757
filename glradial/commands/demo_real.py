"""The real-frame half of ``glradial demo`` (``--source real``, the default).

A real 1280 x 720 broadcast frame shipped with glradial (``glradial/data/``, BSD-2-Clause, see the
README there) is made the undistorted picture: its camera's own barrel lens (measured once from its
pitch lines and recorded beside it, ``own_lens``) is removed with :func:`glradial.correct` at
``fit="crop"``; the reference lines were measured on that undistorted picture. A known lens is applied to it with
:func:`glradial.distort` at ``fit="crop"`` (every pixel of the distorted frame has a source, so it
looks like a real camera's frame), the lens is estimated from the distorted frame alone, and the
frame is corrected with the estimate (``fit="same"``).

Geometry of the reference lines (lens coordinates, docs/DESIGN.md): a point ``p`` of the original frame
appears in the distorted frame at ``P(s p)`` (``s`` the distortion's crop scale) and, after a
correction with the true lens, at ``s p`` in the corrected frame: a straight line of the original
stays straight there. So the figure draws, on the distorted frame, the chord between the ends of
each reference line (the painted line bows away from it) and, on the corrected frame, the line's
true straight position (the painted line lies on it when the estimate is right).
"""

from __future__ import annotations

import argparse
import json
from importlib import resources
from pathlib import Path

import numpy as np

from ..lens.lens import Lens

#: the bundled real frame and its reference lines (package ``glradial.data``)
FRAME_NAME = "usl_broadcast_0195.jpg"
LINES_NAME = "usl_broadcast_0195.json"


def bundled_frame() -> tuple[np.ndarray, dict[str, np.ndarray], Lens]:
    """The shipped real frame made undistorted (H x W x 3 uint8 RGB: its own lens removed with
    ``correct(fit="crop")``), its reference lines ``{name: 2 x 2 end points in pixels of that
    undistorted frame}``, and the frame's own lens (both measured; see ``glradial/data/README.md``)."""
    from ..lens.lens import Lens
    from ..media.image_io import read_image
    from ..remapping.remap import correct

    data = resources.files("glradial.data")
    shipped = read_image(Path(str(data.joinpath(FRAME_NAME))))
    spec = json.loads(data.joinpath(LINES_NAME).read_text(encoding="utf-8"))
    size = (shipped.shape[1], shipped.shape[0])
    if tuple(spec["size"]) != size:
        raise ValueError(f"{LINES_NAME} describes a {spec['size']} frame, {FRAME_NAME} is {size[0]}x{size[1]}")
    own = Lens(spec["own_lens"]["k1"], spec["own_lens"]["k2"])
    frame = correct(shipped, own, fit="crop")
    lines = {name: np.asarray(ends, dtype=np.float64) for name, ends in spec["lines_after_removing_own_lens"].items()}
    return frame, lines, own


def line_positions(ends: np.ndarray, true_lens, scale: float, size: tuple[int, int], samples: int = 400):
    """Pixel positions of the points of one reference line (``ends`` 2 x 2, original pixels):
    ``(distorted, corrected)``, each ``samples x 2``: where the distorted frame shows them
    (``P(s p)``) and where a correction with the true lens shows them (``s p``)."""
    from ..lens.lens import lens_to_pixels, pixels_to_lens

    t = np.linspace(0.0, 1.0, samples)[:, None]
    p = pixels_to_lens(ends[0] + t * (ends[1] - ends[0]), size) * scale
    return true_lens.distort_points(lens_to_pixels(p, size), size), lens_to_pixels(p, size)


def run_real(args: argparse.Namespace) -> int:
    """``glradial demo --source real``: see the module docstring."""
    from ..lens.lens import Lens
    from ..remapping.remap import correct, distort
    from .demo import _distance_to_chord, estimate_and_report, timed_log, write_outputs

    log = timed_log()
    original, lines, own = bundled_frame()
    size = (original.shape[1], original.shape[0])
    true_lens = Lens(args.k1, args.k2)
    true_lens.check_frame(size)
    scale = true_lens.fit_scale(size, "crop", "distort")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    frame = distort(original, true_lens.k1, true_lens.k2, fit=scale)
    log(f"real broadcast frame {FRAME_NAME} ({size[0]}x{size[1]}): its own lens k1={own.k1:.4f} k2={own.k2:.4f} "
        f"removed, the known lens k1={true_lens.k1:.4f} k2={true_lens.k2:.4f} applied (fit=crop, scale {scale:.4f})")

    estimate = estimate_and_report(frame, true_lens, args, log)
    source = "estimated" if estimate is not true_lens else "true"
    used = Lens(float(estimate.k1), float(estimate.k2))
    corrected = correct(frame, used.k1, used.k2, fit="same")

    chords, straight = [], []
    bow, residual = 0.0, 0.0
    for ends in lines.values():
        distorted_px, true_px = line_positions(ends, true_lens, scale, size)
        chords.append(distorted_px)
        straight.append(true_px)
        bow = max(bow, _distance_to_chord(distorted_px))
        shown = used.undistort_points(distorted_px, size)  # where the corrected frame shows each point
        residual = max(residual, float(np.nanmax(np.hypot(*(shown - true_px).T))))
    print(f"reference lines: up to {bow:.1f} px from straight in the distorted frame, "
          f"{residual:.1f} px after correction ({size[0]}x{size[1]} pixels)")
    labels = (
        f"real frame, known lens k1={true_lens.k1:.3f} k2={true_lens.k2:.3f} applied; red: chords between line ends",
        f"corrected ({source} k1={used.k1:.3f} k2={used.k2:.3f}); red: the lines' true straight positions",
        "distorted: enlarged close-ups where the reference lines run",
        "corrected: the same close-ups",
    )
    write_outputs(out, frame, corrected, chords, straight, labels, log)
    return 0
