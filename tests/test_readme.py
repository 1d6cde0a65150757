"""README.md's Python API block runs as printed (on a small real photo as ``frame``), and its
comments hold: the OpenCV line equals cv2.undistort, the batch and float64 lines keep shape/dtype."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

README = Path(__file__).resolve().parent.parent / "README.md"


def python_api_block() -> str:
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Python API\n"):]
    match = re.search(r"```python\n(.*?)```", section, re.S)
    assert match, "no python block under '## Python API'"
    return match.group(1)


def test_readme_python_api_block_runs(road):
    frame = cv2.resize(road, (192, 108), interpolation=cv2.INTER_AREA)
    namespace = {"frame": frame}
    exec(compile(python_api_block(), str(README), "exec"), namespace)
    lens, K, dist = namespace["lens"], namespace["K"], namespace["dist"]
    assert not lens.is_centred  # the block's calibration is off centre with fx != fy
    reference = cv2.undistort(frame, K, dist, newCameraMatrix=K)
    inner = (slice(6, -6), slice(6, -6))
    # the GL path interpolates at float32 positions, OpenCV at 1/32 px (docs/CORE.md): < 0.3 levels
    assert np.abs(namespace["corrected"][inner].astype(float) - reference[inner]).mean() < 0.3
    assert namespace["batch"].shape == (2,) + frame.shape
    assert namespace["as_float"].dtype == np.float64 and namespace["as_float"].shape == frame.shape
    assert namespace["map_x"].shape == frame.shape[:2]
    # the Remapper (GL) and correct (auto: the CPU path on llvmpipe) agree as the backends do
    gl_vs_auto = np.abs(namespace["buffer"].astype(float) - namespace["corrected"])[inner]
    assert gl_vs_auto.mean() < 0.3, gl_vs_auto.mean()


def test_readme_embedding_example_runs_and_bends_the_graphic(ctx):
    """The "Embed in your graphics tool" block runs as printed on its own EGL context; its
    texture-to-texture result equals the library's CPU distortion of the same premultiplied graphic
    (mean < 0.5 levels, the backends' documented agreement), and the bar is bent (its edge row moves)."""
    import glradial

    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Embed in your graphics tool\n"):]
    block = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    namespace: dict = {}
    exec(compile(block, str(README), "exec"), namespace)
    from glradial.gl import egl

    egl.make_current(ctx)  # the block's context was current on this thread: hand it back
    pixels, graphic = namespace["pixels"], namespace["graphic"]
    expected = glradial.distort(graphic, glradial.Lens(-0.25, 0.05), backend="cpu", alpha="premultiplied")
    assert np.abs(pixels.astype(float) - expected).mean() < 0.5
    top_edge = [int(np.argmax(pixels[:, x, 3] > 127)) for x in (80, 320, 560)]
    assert top_edge[0] != top_edge[1]  # a barrel lens bends the straight bar
    assert "k1" in namespace["include"]
