"""bench/pitch_views.py's reference lens for an off-centre principal point (``centred_fit``: what
OpenCV's ``calibrateCamera`` with the principal point fixed at the centre reports, as the shared
wide camera was calibrated): a centred lens, barrel or pincushion, comes back as itself, and the
reference moves continuously with the principal point (known answers; the metric is the maximum
displacement at 1920 of :func:`glradial.lens.metrics.max_displacement_px`); its per-frame listing
(``--list``) tells a frame left uncorrected from one corrected by the identity lens's error."""

from __future__ import annotations

import numpy as np
import pytest
from repo_scripts import load_script

from glradial.lens.lens import Lens
from glradial.lens.metrics import manifold_k2, max_displacement_px


def _bench():
    return load_script("bench/pitch_views.py")


def _centred_fit():
    return _bench().centred_fit


@pytest.mark.parametrize("k1, k2_above, offset, tolerance_px", [
    (-0.5, 0.0, 0.0, 0.01), (0.2, 0.0, 0.0, 0.01), (-0.7, 0.05, 0.0, 0.01),  # centred: itself
    (-0.7, 0.0, 0.002, 0.1),  # 2.6 px off centre at 1280: within a tenth of a px of the lens itself
])
def test_the_reference_of_a_centred_lens_is_the_lens_itself(k1, k2_above, offset, tolerance_px):
    lens = Lens(k1, float(manifold_k2(k1)) + k2_above, offset, 0.0)
    reference = np.array(_centred_fit()(lens))
    assert max_displacement_px(reference, np.array([lens.k1, lens.k2])) < tolerance_px



def test_the_per_frame_listing_tells_left_from_corrected_by_the_identity_lens():
    """``frame_rows`` (``--list``): a CNN-only answer on a pitch view (grass region, no line fit) is
    corrected when its bound (``q_no_lines_rel`` x its error head) is below its own shift and left
    otherwise; the verdict compares its error with the identity lens's (known answers: truth = the
    answer itself, or no lens)."""
    from glradial.estimation.trust import FrameEvidence, shift_px, shipped_trust

    bench, trust = _bench(), shipped_trust()
    lens = (-0.5, float(manifold_k2(-0.5)))
    shift = shift_px(lens)

    def evidence(head):
        return FrameEvidence(net=lens, grass=0.5, grass_width=1.0, net_error_px=head, edge_density=0.01)

    sure, unsure = 0.5 * shift / trust.q_no_lines_rel, 2.0 * shift / trust.q_no_lines_rel
    rows = bench.frame_rows([("sure", evidence(sure), lens), ("unsure", evidence(unsure), lens),
                             ("no lens", evidence(sure), (0.0, 0.0))], trust)
    assert [r["verdict"] for r in rows] == ["corrected", "left, would help", "corrected, worse"]
    assert [r["reason"] for r in rows] == ["ok", "too_few_lines", "ok"]
    assert rows[0]["error"] == pytest.approx(0.0, abs=1e-9) and rows[1]["identity"] == pytest.approx(shift)
    assert rows[2]["error"] == pytest.approx(shift) and rows[2]["identity"] == 0.0
    assert all(r["shift"] == pytest.approx(shift) for r in rows)


def test_an_answers_overshoot_toward_no_lens_says_when_correcting_helps():
    """bench/cnn_alone_doubt.py's overshoot ``o = (s + d - d0) / 2`` (s the answer's shift, d its
    error, d0 the identity lens's error): ``o = s`` when the truth is no lens, 0 when it is the answer,
    ``0 <= o <= min(s, d)`` (triangle inequality of the metric), and correcting helps (``d < d0``)
    exactly when ``o < s / 2``, on lens pairs drawn over the real range."""
    bench = load_script("bench/cnn_alone_doubt.py")
    rng = np.random.default_rng(5)
    for k1a, k1t in rng.uniform(-1.0, 0.4, (200, 2)):
        answer = (float(k1a), float(manifold_k2(k1a)) + float(rng.normal(0.0, 0.03)))
        truth = (float(k1t), float(manifold_k2(k1t)) + float(rng.normal(0.0, 0.03)))
        s, d, d0 = bench._distances(answer, truth)
        o = bench.overshoot(answer, truth)
        assert -1e-9 <= o <= min(s, d) + 1e-9
        assert (o < s / 2) == (d < d0)
        assert bench.overshoot(answer, (0.0, 0.0)) == pytest.approx(s)
        assert bench.overshoot(answer, answer) == pytest.approx(0.0, abs=1e-9)
