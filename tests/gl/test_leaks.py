"""GL resources stay constant over thousands of calls.

Evidence: (1) the module-level functions reuse one Remapper whose texture names do not change
while the frame size does not; (2) the process's resident memory (Mesa llvmpipe keeps textures in
process memory) does not grow over 2000 calls, nor over size changes and Remapper create/release
cycles with frames large enough that one leaked texture set per call would add hundreds of MB.
"""

from __future__ import annotations

import os

import numpy as np

from glradial import Remapper, correct, distort
from glradial.remapping import remap

PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * PAGE / 2**20


def test_thousands_of_calls_reuse_the_same_objects(ctx):
    frame = np.random.default_rng(0).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    for _ in range(50):  # warm up: programs compiled, pools filled
        correct(frame, -0.2, 0.03, backend="gl")
        distort(frame, -0.2, 0.03, backend="gl")
    remapper = remap._thread_remapper()
    ids = remapper.texture_ids
    programs = len(remapper._programs)
    start = rss_mb()
    for i in range(1000):
        k1 = -0.2 + 1e-4 * i  # new coefficients every call: nothing may be keyed on them
        correct(frame, k1, 0.03, backend="gl")
        distort(frame, k1, 0.03, backend="gl")
    assert remap._thread_remapper() is remapper
    assert remapper.texture_ids == ids
    assert len(remapper._programs) == programs
    growth = rss_mb() - start
    assert growth < 8.0, f"resident memory grew {growth:.1f} MB over 2000 calls"


def test_size_changes_and_remapper_cycles_free_their_objects(ctx):
    """512×512 RGBA float32 frames: each texture is 4 MB, a source/target pair 8 MB. 60 size
    changes plus 20 Remapper lifetimes would leak over 600 MB if anything stayed alive."""
    a = np.zeros((512, 512, 4), np.float32)
    b = np.zeros((500, 512, 4), np.float32)
    remapper = Remapper(ctx)
    for frame in (a, b, a, b):  # warm up the allocator with both sizes
        remapper.correct(frame, -0.1, 0.0)
    start = rss_mb()
    for i in range(60):
        remapper.correct(a if i % 2 else b, -0.1, 0.0)
    remapper.release()
    for _ in range(20):
        with Remapper(ctx) as cycle:
            cycle.correct(a, -0.1, 0.0, interpolation="cubic")
            cycle.distort(a, -0.1, 0.0)
    growth = rss_mb() - start
    assert growth < 64.0, f"resident memory grew {growth:.1f} MB"
    assert ctx.error == "GL_NO_ERROR"
