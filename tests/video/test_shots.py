"""One lens per shot (glradial.video.shot_fit, shot_evidence, shot_track): clips rendered through a known
lens (glradial.video.clips, checked against glradial.correct below), read back with a stand-in per-frame
estimator that knows nothing (a fixed rough guess), so what is measured is the shot fit's own
evidence: the line chains and the frame-to-frame matches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from glradial.lens.lens import Lens
from glradial.lens.metrics import manifold_k2, max_displacement_px
from glradial.video.clips import ShotSpec, render_clip, render_shot, write_clip
from glradial.video.shot_evidence import ShotCollector
from glradial.video.shot_fit import ShotEvidence, ShotSample, fit_shot

SIZE = (480, 270)
#: the stand-in estimator's answer for every frame: a barrel lens 30-55 px (at 1920) from every
#: truth below, as far off as the CNN can be. It is also the line detector's hint (chains are linked
#: and cut at corners in the frame undistorted with it): a hint much further off (k1 -0.12 for a
#: true -0.35) cuts curved lines at false corners and the static shot below reads 15 px off.
GUESS = Lens(-0.2, float(manifold_k2(-0.2)))


def guess(_frame: np.ndarray) -> Lens:
    return GUESS


@pytest.fixture(scope="module")
def stadium(gl_ctx) -> np.ndarray:
    import glradial

    return glradial.stadium_panorama(3, (2048, 1024))


def pitch_view(stadium: np.ndarray, frames: int, k1=(-0.35, -0.35), start=(0.0, -8.0, 1.0), end=None) -> ShotSpec:
    """The camera looking at the pitch of stadium 3 (its centre line, boxes and stands)."""
    return ShotSpec(stadium, frames, start, end or start, k1, hfov_deg=45, panorama=True)


def collect(spec: ShotSpec, every: int = 1) -> tuple[ShotEvidence, np.ndarray, np.ndarray]:
    """Evidence of every ``every``-th frame of a shot, the true lens and the true log zoom of those."""
    collector = ShotCollector(guess)
    truth, zoom = [], []
    for i, (frame, lens, z) in enumerate(render_shot(spec, SIZE)):
        if i % every == 0:
            collector.add(i, frame)
            truth.append(lens)
            zoom.append(z)
    return collector.evidence, np.asarray(truth), np.log(np.asarray(zoom) / zoom[0])


def errors(shot, evidence: ShotEvidence, truth: np.ndarray) -> np.ndarray:
    return max_displacement_px(shot.lens_at(np.asarray(evidence.zoom)), truth)


def test_clip_renderer_agrees_with_glradial_correct(stadium):
    """Independent oracle for every test below: a frame rendered through a lens, corrected by
    glradial.correct, equals the frame rendered through no lens (the same camera, margin and
    source), up to resampling: far below the difference the lens makes."""
    import glradial

    frame, lens, _ = next(render_shot(pitch_view(stadium, 1, k1=(-0.3, -0.3)), SIZE))
    pinhole, _, _ = next(render_shot(pitch_view(stadium, 1, k1=(0.0, 0.0)), SIZE))  # a panorama: no margin
    corrected = glradial.correct(frame, *lens, backend="cpu")
    inner = (slice(30, 240), slice(60, 420))
    after = np.abs(corrected[inner].astype(float) - pinhole[inner]).mean()
    before = np.abs(frame[inner].astype(float) - pinhole[inner]).mean()
    assert after < 0.3 * before, (after, before)


def test_static_shot_converges_to_one_lens_within_its_bound(stadium):
    """A static camera: one lens for the shot, within its stated bound and a few px of the truth,
    and the bound does not shrink with the number of (identical) frames: 8 frames of a static
    camera are no more evidence than 2."""
    evidence, truth, _ = collect(pitch_view(stadium, 8))
    shot = fit_shot(evidence)
    error = errors(shot, evidence, truth)
    assert not shot.zooming and np.ptp(error) < 1e-9
    assert error.max() <= shot.uncertainty_px and error.max() < 4.0, (error.max(), shot)
    two = fit_shot(ShotEvidence(evidence.samples[:2], [p for p in evidence.pairs if p[1] < 2], evidence.zoom[:2]))
    assert shot.uncertainty_px >= 0.9 * two.uncertainty_px, (shot.uncertainty_px, two.uncertainty_px)


def central(evidence: ShotEvidence, radius: float) -> ShotEvidence:
    """The same shot with every chain cut to its points within ``radius`` (lens units) of the
    centre: the lines of a shot that shows little near its edges, where the lens shows most."""
    from glradial.estimation.lines import Chain, LineEvidence

    samples = []
    for s in evidence.samples:
        chains = [Chain(c.points[keep], c.kind, c.length * float(keep.mean())) for c in s.evidence.chains
                  for keep in [np.hypot(c.points[:, 0], c.points[:, 1]) <= radius] if keep.sum() >= 8]
        samples.append(ShotSample(s.frame, LineEvidence(chains, s.evidence.size, s.evidence.width), s.estimate))
    return ShotEvidence(samples, evidence.pairs, evidence.zoom, evidence.travel, evidence.pan)


def test_static_bound_stays_honest_when_the_lines_lie_near_the_centre(stadium):
    """A static shot whose chains all lie within 0.3 of the centre (the frame's corner is at 0.57):
    poorly constrained where the lens matters most. Its joint fit states the static shots' bound
    (``STATIC_BOUND_SCALE`` x its 1-sigma + the floor, exactly), and that bound covers its error; cut
    to 0.2, too few chains say anything about the lens and the shot is doubtful (no_geometry)."""
    from glradial.video.shot_fit import BOUND_FLOOR_PX, STATIC_BOUND_SCALE

    evidence, truth, _ = collect(pitch_view(stadium, 3))
    near = central(evidence, 0.3)
    assert all(np.hypot(*c.points.T).max() <= 0.3 for s in near.samples for c in s.evidence.chains)
    shot = fit_shot(near)
    assert shot.static and shot.source == "joint" and shot.chains >= 2, shot
    assert shot.uncertainty_px == pytest.approx(STATIC_BOUND_SCALE * shot.sigma_px + BOUND_FLOOR_PX)
    assert errors(shot, near, truth).max() <= shot.uncertainty_px, (errors(shot, near, truth), shot)
    blind = fit_shot(central(evidence, 0.2))
    assert blind.doubtful and blind.reason == "no_geometry", blind


def test_a_static_shot_takes_the_joint_fit_when_it_is_surer(stadium):
    """Known answer of the choice rule on a static shot: per-frame estimates (a lens 5-15 px off the
    truth) stating just more than the joint fit's bound lose to it (the shot takes the joint lens and
    bound); stating just less, they win (their lens, their bound)."""
    from glradial.estimation.lens_estimate import LensEstimate
    from glradial.video.shot_fit import joint_fit

    evidence, truth, _ = collect(pitch_view(stadium, 3))
    near = central(evidence, 0.3)
    off = (-0.32, float(manifold_k2(-0.32)))
    assert 5.0 < max_displacement_px(np.asarray(off), truth[0]) < 15.0

    def stating(px):
        samples = [ShotSample(s.frame, s.evidence, LensEstimate(*off, uncertainty_px=px, method="lines")) for s in near.samples]
        return ShotEvidence(samples, near.pairs, near.zoom, near.travel, near.pan)

    joint = joint_fit(stating(1.0))  # the estimates' k1 is the fit's loose prior; their bound plays no part

    above = fit_shot(stating(joint.uncertainty_px * 1.01))
    assert above.source == "joint" and above.uncertainty_px == pytest.approx(joint.uncertainty_px), above
    assert max_displacement_px(above.lens_at(0.0), joint.lens_at(0.0)) < 0.5
    below = fit_shot(stating(joint.uncertainty_px * 0.99))
    assert below.source == "frames" and below.uncertainty_px == pytest.approx(joint.uncertainty_px * 0.99), below
    assert max_displacement_px(below.lens_at(0.0), np.asarray(off)) < 1e-9


def test_zoom_clip_follows_the_zoom(stadium):
    """The picture zooms in 40 % while k1 goes -0.35 -> -0.20 (53 px of change at the corner at
    1920): the shot gets the zoom model, its zoom is measured from the frames, and every frame's
    lens is within a few px of its own truth, at both ends."""
    evidence, truth, zoom = collect(pitch_view(stadium, 8, k1=(-0.35, -0.20), end=(0.0, -8.0, 1.4)))
    shot = fit_shot(evidence)
    assert shot.zooming
    assert np.allclose(evidence.zoom, zoom, atol=0.03), (evidence.zoom, zoom)
    error = errors(shot, evidence, truth)
    change = max_displacement_px(truth[0], truth[-1])
    assert change > 40
    assert error.max() < 6.0, (error, shot)


def test_pan_over_texture_without_lines_is_read_from_the_motion(field_panorama):
    """A camera panning 24 deg over a real grass field with no pitch lines (the packaged panorama):
    the chains are dropped from the evidence, so only the frame-to-frame matches can tell the lens;
    they do, within the bound, far from the stand-in's guess."""
    spec = ShotSpec(field_panorama, 7, (-12.0, -12.0, 1.0), (12.0, -14.0, 1.0), (-0.35, -0.35), hfov_deg=60, panorama=True)
    evidence, truth, _ = collect(spec)
    motion_only = ShotEvidence([ShotSample(s.frame, None, s.estimate) for s in evidence.samples], evidence.pairs,
                               evidence.zoom, evidence.travel, evidence.pan)
    shot = fit_shot(motion_only)
    error = errors(shot, motion_only, truth)
    assert max_displacement_px((GUESS.k1, GUESS.k2), truth[0]) > 40
    assert shot.reason != "no_geometry" and shot.matches > 300
    assert error.max() <= shot.uncertainty_px and error.max() < 6.0, (error.max(), shot)


def test_a_wide_pan_is_read_from_the_motion_even_when_the_hint_is_far_off(field_panorama):
    """The per-frame estimate (the matcher's hint) says no distortion at all, the truth is k1 -0.3
    (some 80 px at 1920 apart): five samples of a 30 deg pan over grass without lines. Samples far
    apart in the pan are matched too (not only neighbours), and the points near the frame edge,
    which a homography under the wrong hint misfits most and which show the lens best, are kept:
    the matches alone read the lens within a few px and within the bound."""
    spec = ShotSpec(field_panorama, 5, (-15.0, -12.0, 1.0), (15.0, -13.0, 1.0), (-0.3, -0.3), hfov_deg=60, panorama=True)
    collector = ShotCollector(lambda _frame: Lens(0.0, 0.0))
    truth = []
    for i, (frame, lens, _) in enumerate(render_shot(spec, SIZE)):
        collector.add(i, frame)
        truth.append(lens)
    evidence = collector.evidence
    assert any(j - i > 1 for i, j, _ in evidence.pairs), [(i, j) for i, j, _ in evidence.pairs]
    motion_only = ShotEvidence([ShotSample(s.frame, None, s.estimate) for s in evidence.samples], evidence.pairs,
                               evidence.zoom, evidence.travel, evidence.pan)
    shot = fit_shot(motion_only)
    error = errors(shot, motion_only, np.asarray(truth))
    assert max_displacement_px((0.0, 0.0), truth[0]) > 60
    assert error.max() <= shot.uncertainty_px and error.max() < 4.0, (error.max(), shot)


def test_static_shot_without_lines_is_doubtful(field_panorama):
    """A static camera on grass (no lines, and still frames say nothing): doubtful, no_geometry,
    with at least the no-geometry bound, and the lens left at the per-frame estimate."""
    spec = ShotSpec(field_panorama, 4, (40.0, -35.0, 1.0), (40.0, -35.0, 1.0), (-0.3, -0.3), hfov_deg=50, panorama=True)
    evidence, _, _ = collect(spec)
    shot = fit_shot(evidence)
    assert shot.doubtful and shot.reason == "no_geometry", shot
    assert shot.uncertainty_px >= 16.0
    assert max_displacement_px(shot.lens_at(0.0), (GUESS.k1, GUESS.k2)) < 1.0


def test_a_shot_takes_its_per_frame_estimates_when_they_are_surer(stadium):
    """The joint fit and the per-frame estimates (which state their own calibrated bound) both read
    the shot. A static shot is never worse than its frames: it takes their median whenever that is
    sure enough (not doubtful). Estimates stating 2 px give the shot their lens and exactly their
    bound, even with one of three 15 px out; stating 200 px (doubtful), they lose to the fit.
    Estimates that scatter further than they state add their typical scatter (the median distance
    from their median) to the bound."""
    from glradial.estimation.lens_estimate import LensEstimate

    evidence, truth, _ = collect(pitch_view(stadium, 3))

    def stating(lenses, px):
        samples = [ShotSample(s.frame, s.evidence, LensEstimate(*k, uncertainty_px=px, method="lines"))
                   for s, k in zip(evidence.samples, lenses)]
        return ShotEvidence(samples, evidence.pairs, evidence.zoom, evidence.travel, evidence.pan)

    fit = fit_shot(evidence)
    assert fit.chains > 0 and fit.uncertainty_px > 2.0, fit
    sure = fit_shot(stating([truth[0]] * 3, 2.0))
    assert sure.chains == 0 and sure.uncertainty_px == pytest.approx(2.0) and not sure.doubtful, sure
    assert max_displacement_px(sure.lens_at(0.0), truth[0]) < 1e-9
    unsure = fit_shot(stating([truth[0]] * 3, 200.0))
    assert unsure.chains > 0 and unsure.uncertainty_px < 200.0, unsure  # the fit (its prior: their median)
    assert fit.static
    other = (-0.30, float(manifold_k2(-0.30)))
    apart = max_displacement_px(np.asarray(other), truth[0])
    # one estimate of three far out (15 px): the median is the other two's lens, stating their bound
    outlier = fit_shot(stating([other, truth[0], truth[0]], 2.0))
    assert apart > 10.0 and outlier.chains == 0 and outlier.uncertainty_px == pytest.approx(2.0), (outlier, apart)
    assert max_displacement_px(outlier.lens_at(0.0), truth[0]) < 1e-9
    # estimates scattered beyond what they state (0.5 px): their median bound plus their typical
    # scatter, the median distance from their median (doubtful above 10 px: then weighed against the fit)
    k1s = truth[0][0] + np.array([-0.06, -0.03, 0.0, 0.03, 0.06])[:len(evidence.samples)]
    spaced = [(float(k), float(manifold_k2(k))) for k in k1s]
    scatter = float(np.median(max_displacement_px(np.asarray(spaced), np.median(spaced, axis=0))))
    wide = fit_shot(stating(spaced, 0.5))
    assert 0.5 < scatter and 0.5 + scatter <= 10.0
    assert wide.chains == 0 and wide.uncertainty_px == pytest.approx(0.5 + scatter, rel=1e-6), (wide, scatter)
    assert max_displacement_px(wide.lens_at(0.0), np.median(spaced, axis=0)) < 1e-9


def test_one_frame_shot(stadium):
    """A shot of a single frame: a lens from its lines alone, its bound covering its error."""
    evidence, truth, _ = collect(pitch_view(stadium, 1, k1=(-0.25, -0.25)))
    shot = fit_shot(evidence)
    error = errors(shot, evidence, truth)
    assert math.isfinite(shot.uncertainty_px) and error[0] <= shot.uncertainty_px, (error, shot)
    assert error[0] < 5.0


def test_a_cut_between_two_lenses_keeps_them_apart(stadium, tmp_path):
    """The whole first pass on a lossless clip: a static shot through k1 -0.35 cut to a pan through
    k1 -0.08. The cut is found, each shot gets its own lens (even the frames right after the
    cut), the track says which shots were applied and why not; nothing is pooled across the cut."""
    from glradial.video.video_pipeline import track_video

    shots = [pitch_view(stadium, 8, k1=(-0.35, -0.35)),
             ShotSpec(stadium, 8, (30.0, -12.0, 1.0), (38.0, -13.0, 1.0), (-0.08, -0.08), hfov_deg=50, panorama=True)]
    frames, truth = render_clip(shots, SIZE)
    path = tmp_path / "cut.mkv"
    write_clip(path, frames, truth)
    track = track_video(path, guess, every=2, progress=False)
    assert list(np.flatnonzero(np.diff(track.shot))) == [7]
    error = max_displacement_px(track.lens, truth.lens)
    apart = max_displacement_px(truth.lens[0], truth.lens[-1])
    assert apart > 75 and error.max() < 8.0, error
    rows = track.rows()
    assert {"shot", "doubtful", "reason", "applied", "frame", "k1", "k2", "uncertainty_px"} <= set(rows[0])
    for row in rows:
        assert row["applied"] == (0 if row["doubtful"] else 1)
        assert bool(row["reason"]) == bool(row["doubtful"])


def test_shot_fit_input_errors(tmp_path):
    from glradial.video.video_pipeline import track_video

    for name, value in (("every", 0), ("estimate_every", 1.5)):
        with pytest.raises(ValueError, match=f"{name} must be a positive integer, got {value}"):
            track_video(tmp_path / "never-opened.mp4", guess, **{name: value})
    with pytest.raises(ValueError, match="doubtful_px must be > 0"):
        track_video(tmp_path / "never-opened.mp4", guess, doubtful_px=0)
    with pytest.raises(ValueError, match="uint8"):
        ShotCollector(guess).add(0, np.zeros((9, 16, 3), np.float32))
    with pytest.raises(ValueError, match="at least one sampled frame"):
        fit_shot(ShotEvidence())
    with pytest.raises(ValueError, match="estimate_every"):
        ShotCollector(guess, estimate_every=0)
    with pytest.raises(ValueError, match="at least one frame"):
        next(render_shot(ShotSpec(np.zeros((8, 16, 3), np.uint8), 0), SIZE))


def test_batched_evaluation_equals_the_per_pair_definition():
    """The shot fit's residuals undistort every sample's points in one call and reuse what does not
    depend on the lens (a speed-up): they must equal, bit for bit, the definition evaluated pair by
    pair through the public lens functions (undistort_point_exact with the sample's lens, the
    pair's least-squares homography, the weighted transfer error), and undistorting must invert
    the forward model. Lenses include one that folds inside the points (``valid`` False there)."""
    from glradial.lens.lensfuncs import distort_point, undistort_point_exact
    from glradial.video.frame_motion import Matches, homography_of
    from glradial.video.shot_fit import MATCH_CAP, MATCH_SIGMA, _Pairs, _Undistort

    rng = np.random.default_rng(7)
    lenses = np.array([[-0.30, 0.05], [-0.22, 0.03], [0.05, -0.01], [-0.12, 0.0], [-1.6, 0.0]])
    sample = rng.integers(0, 5, 400)
    points = rng.uniform(-0.55, 0.55, (400, 2)) * [1.0, 0.6]
    p_u, valid = _Undistort(points, sample)(lenses)
    for s, (k1, k2) in enumerate(lenses):
        ref, ref_valid = undistort_point_exact(points[sample == s], k1, k2)
        assert np.array_equal(p_u[sample == s], ref) and np.array_equal(valid[sample == s], ref_valid)
    assert not valid[sample == 4].all() and valid[sample < 4].all()
    for s, (k1, k2) in enumerate(lenses[:4]):
        assert np.allclose(distort_point(p_u[sample == s], k1, k2), points[sample == s], rtol=0, atol=1e-12)

    truth = np.array([[1.02, 0.01, 0.03], [-0.01, 1.02, -0.01], [0.02, -0.01, 1.0]])
    pairs = []
    for i, j, n in ((0, 1, 40), (1, 2, 90), (0, 3, 12)):
        a = rng.uniform(-0.45, 0.45, (n, 2)) * [1.0, 0.5]
        q = np.c_[a, np.ones(n)] @ truth.T
        pairs.append((i, j, Matches(a, q[:, :2] / q[:, 2:3] + rng.normal(0, 1e-3, (n, 2)), 640)))
    expected = []
    for i, j, m in pairs:
        ua, _ = undistort_point_exact(m.a, *lenses[i])
        ub, _ = undistort_point_exact(m.b, *lenses[j])
        q = np.c_[ua, np.ones(len(ua))] @ homography_of(ua, ub).T
        weight = math.sqrt(min(1.0, MATCH_CAP / len(m))) * m.width / MATCH_SIGMA
        expected.append(((q[:, :2] / q[:, 2:3] - ub) * weight).ravel())
    got, expected = _Pairs(pairs).residuals(lenses), np.concatenate(expected)
    # OpenCV's Levenberg-Marquardt stops a little short of the least-squares homography the batched
    # solve reaches: the residuals (units of MATCH_SIGMA, noise here ~2) agree to 1e-3, and the
    # batched ones are never the worse fit
    assert np.allclose(got, expected, rtol=0, atol=1e-3) and got @ got <= expected @ expected * (1 + 1e-9)
    stacked = _Pairs(pairs).residuals(np.stack([lenses, lenses[::-1]]))  # K lens sets in one evaluation
    assert np.allclose(stacked[0], got, rtol=0, atol=1e-9) and np.allclose(stacked[1], _Pairs(pairs).residuals(lenses[::-1]), rtol=0, atol=1e-9)
    assert len(_Pairs([]).residuals(lenses)) == 0


def test_the_lens_track_follows_a_zoom_past_its_last_sample():
    """Frames after a shot's last sample (up to a stride) continue the zoom at the last two samples'
    rate instead of keeping the last sample's zoom, and frames before its first sample (a cut placed
    on frames the sparse decode skipped) at the first two samples' rate (known answer: a zoom linear
    in frames)."""
    from glradial.video.shot_track import _log_zoom_at

    here = np.arange(0, 50)
    z = _log_zoom_at(here, [0, 10, 20, 30, 40], [0.0, 0.1, 0.2, 0.3, 0.4])
    assert np.allclose(z, here / 100.0)
    late = _log_zoom_at(here, [3, 13, 23, 33, 43], [0.03, 0.13, 0.23, 0.33, 0.43])  # first decoded 3 frames after the cut
    assert np.allclose(late, here / 100.0)
    still = _log_zoom_at(here, [0, 10, 20, 30, 40], [0.0] * 5)
    assert np.all(still == 0.0)
    assert np.allclose(_log_zoom_at(here[:5], [0], [0.2]), 0.2)  # one sample: its zoom throughout


def test_a_shot_is_judged_by_benefit_like_a_frame():
    """Known answers of the shot-level benefit verdict: a joint fit doubtful only for stating more than
    doubtful_px is applied when its bound stays below its lens's own shift from the identity (a strong
    barrel: correcting helps even at the bound), stays doubtful when the bound reaches the uncorrected
    frame (a near-pinhole lens), and other reasons (fold_over) stand."""
    from types import SimpleNamespace

    from glradial.video.shot_fit import FittedShotLens, judged_by_benefit

    no_samples = SimpleNamespace(samples=[])

    def shot(k1: float, bound: float, reason: str = "uncertain") -> FittedShotLens:
        return FittedShotLens((k1, 0.0), 0.0, bound, True, reason, 3, 0, 1.0, False, "joint")

    strong, weak = -0.3, -0.01
    shift_strong = float(max_displacement_px(np.array([strong, manifold_k2(strong)]), np.zeros(2)))
    shift_weak = float(max_displacement_px(np.array([weak, manifold_k2(weak)]), np.zeros(2)))
    assert shift_weak < 15.0 < shift_strong  # the two cases are what they claim to be
    applied = judged_by_benefit(shot(strong, 15.0), no_samples)
    assert not applied.doubtful and applied.reason == "" and applied.uncertainty_px == 15.0
    assert judged_by_benefit(shot(strong, shift_strong + 1.0), no_samples).doubtful
    assert judged_by_benefit(shot(weak, 15.0), no_samples).doubtful
    assert judged_by_benefit(shot(strong, 15.0, "fold_over"), no_samples).reason == "fold_over"


def test_a_long_shot_is_sampled_ever_more_sparsely_up_to_the_longest_stride():
    """Pass 1's schedule (shot_track.stride), frame by frame as _scan applies it: a 2-s shot (50
    frames at 25 fps) is sampled every 10 frames as before the schedule changed, a longer one 20,
    then 40 frames later and so on, doubling, up to every 320 frames however long it lasts
    (docs/EXPERIMENTS.md, figures sweep_stride_cap and sweep_estimate_every)."""
    from glradial.video.shot_track import stride

    at = [0]
    for frame in range(1, 2000):
        if frame - at[-1] >= stride(10, len(at)):
            at.append(frame)
    assert [f for f in at if f < 50] == [0, 10, 20, 30, 40]
    assert [f for f in at if f < 150] == [0, 10, 20, 30, 40, 60, 100]
    assert at == [0, 10, 20, 30, 40, 60, 100, 180, 340, 660, 980, 1300, 1620, 1940]


def test_the_solver_reaches_the_minimum_an_independent_optimiser_finds(stadium):
    """The shot fit's damped Newton solve ends where SciPy's trust-region least squares, run from the
    same start to convergence (no evaluation cap), ends: the cost no higher than its (1e-6
    relative: both stop on a relative gain of ~1e-8) and the lens within 0.05 px at 1920."""
    from scipy.optimize import least_squares

    from glradial.video.shot_fit import PARAMETER_SCALE, _geometry, _Problem, _seed

    evidence, _, _ = collect(pitch_view(stadium, 4))
    chains, pairs = _geometry(evidence)
    problem = _Problem(chains, pairs, evidence.log_zooms(), GUESS.k1, 2.0)
    start = _seed(problem)
    ours = problem.solve(start)
    theirs = least_squares(problem.residuals, start, x_scale=np.array(PARAMETER_SCALE[:1] + PARAMETER_SCALE[-1:]),
                           diff_step=1e-4, max_nfev=5000, ftol=1e-12, xtol=1e-12, gtol=1e-12)
    assert ours.cost <= theirs.cost * (1 + 1e-6), (ours, theirs.cost, theirs.nfev)
    lenses = [problem.lenses(x)[:1] for x in (ours.x, theirs.x)]
    assert max_displacement_px(lenses[0], lenses[1]).max() < 0.05, (ours.x, theirs.x)
