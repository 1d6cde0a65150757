"""bench/pitch_views.py's reference lens for an off-centre principal point (``centred_fit``: what
OpenCV's ``calibrateCamera`` with the principal point fixed at the centre reports, as the shared
wide camera was calibrated): a centred lens, barrel or pincushion, comes back as itself, and the
reference moves continuously with the principal point (known answers; the metric is the maximum
displacement at 1920 of :func:`glradial.lens.metrics.max_displacement_px`)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from glradial.lens.lens import Lens
from glradial.lens.metrics import manifold_k2, max_displacement_px

ROOT = Path(__file__).resolve().parents[1]


def _centred_fit():
    spec = importlib.util.spec_from_file_location("pitch_views_bench", ROOT / "bench" / "pitch_views.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.centred_fit


@pytest.mark.parametrize("k1, k2_above, offset, tolerance_px", [
    (-0.5, 0.0, 0.0, 0.01), (0.2, 0.0, 0.0, 0.01), (-0.7, 0.05, 0.0, 0.01),  # centred: itself
    (-0.7, 0.0, 0.002, 0.1),  # 2.6 px off centre at 1280: within a tenth of a px of the lens itself
])
def test_the_reference_of_a_centred_lens_is_the_lens_itself(k1, k2_above, offset, tolerance_px):
    lens = Lens(k1, float(manifold_k2(k1)) + k2_above, offset, 0.0)
    reference = np.array(_centred_fit()(lens))
    assert max_displacement_px(reference, np.array([lens.k1, lens.k2])) < tolerance_px
