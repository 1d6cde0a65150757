"""Per-shot smoothing of per-frame lens estimates and shot-cut detection (glradial.video.smoothing)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from glradial.lens.metrics import manifold_k2, max_displacement
from glradial.video.smoothing import ShotDetector, detect_cuts, shot_ids, smooth_shot, smooth_track

WIDTH_PX = 1920  # errors are reported in pixels of a 1920-wide frame, as in docs/DESIGN.md


def synthetic_track(seed: int = 0, n: int = 240, cut: int = 140, every: int = 3):
    """Known lenses: shot 0 zooms slowly (k1 -0.35 -> -0.20), shot 1 zooms the other way from a
    very different lens (k1 0.10 -> 0.05). Estimates every `every` frames + the first frame of each
    shot, with CNN-like noise (sigma 0.02 on k1, 0.01 on k2) and 10 % gross outliers (sigma 0.3)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    k1 = np.where(t < cut, -0.35 + 0.15 * t / cut, 0.10 - 0.05 * (t - cut) / (n - cut))
    truth = np.stack([k1, manifold_k2(k1)], 1)
    times = np.union1d(np.arange(0, n, every), [cut])
    raw = truth[times] + rng.normal(0.0, [0.02, 0.01], (len(times), 2))
    outliers = rng.random(len(times)) < 0.10
    raw[outliers] += rng.normal(0.0, 0.3, (outliers.sum(), 2))
    return truth, times, raw, outliers, shot_ids([0, cut], n), cut


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_smoothing_beats_raw_and_rejects_outliers(seed):
    truth, times, raw, outliers, shots, _ = synthetic_track(seed)
    smoothed, weights, _ = smooth_track(times, raw, shots, half_window=20)
    raw_error = max_displacement(raw, truth[times]) * WIDTH_PX
    smooth_error = max_displacement(smoothed[times], truth[times]) * WIDTH_PX
    # the noise alone is ~2-4 px (sigma 0.02 on k1 at r = 0.57: 0.02 * 0.19 * 1920 ~ 7 px);
    # averaging ~13 samples per window must at least halve the median error, and the mean
    # (dominated by outliers in the raw data) must drop by more than 3x
    assert np.median(smooth_error) < 0.5 * np.median(raw_error)
    assert smooth_error.mean() < raw_error.mean() / 3
    # every frame (not only the estimated ones) is close to the truth
    all_error = max_displacement(smoothed, truth) * WIDTH_PX
    assert np.percentile(all_error, 95) < 6.0, np.percentile(all_error, 95)
    # gross outliers (> 40 px away, 10x the noise) get weight 0 (bisquare cut at 6 MAD ~ 20-25 px)
    gross = outliers & (raw_error > 40)
    assert gross.any() and np.all(weights[gross] == 0.0)
    assert np.mean(weights[~outliers] > 0) > 0.95


def test_cut_resets_the_smoother():
    truth, times, raw, _, shots, cut = synthetic_track(seed=3)
    smoothed, _, _ = smooth_track(times, raw, shots, half_window=20)
    jump = max_displacement(truth[cut - 1], truth[cut]) * WIDTH_PX
    assert jump > 100  # the two shots' lenses differ by > 100 px of displacement
    # frames on both sides of the cut follow their own shot: a smoother across the cut would mix
    # the two lenses and be off by a good fraction of the 100+ px jump
    near = np.arange(cut - 3, cut + 3)
    error = max_displacement(smoothed[near], truth[near]) * WIDTH_PX
    assert error.max() < 12.0, error
    # the same data smoothed as one shot (no reset) is visibly wrong near the cut: the check above can fail
    one_shot, _, _ = smooth_track(times, raw, np.zeros_like(shots), half_window=20)
    assert (max_displacement(one_shot[near], truth[near]) * WIDTH_PX).max() > 30.0


def test_smoothing_follows_a_zoom_without_lag():
    """Noise-free linear zoom: the local-linear fit reproduces it (a moving average would not at
    the ends)."""
    n = 100
    k1 = np.linspace(-0.4, -0.1, n)
    truth = np.stack([k1, manifold_k2(k1)], 1)
    times = np.arange(0, n, 4)
    smoothed, _, _ = smooth_shot(times, truth[times], np.arange(n), half_window=15)
    inside = slice(0, times[-1] + 1)
    # k2 is quadratic in k1, so a line through it is off by its curvature over the window only
    assert (max_displacement(smoothed[inside], truth[inside]) * WIDTH_PX).max() < 0.5


def test_smoothing_input_errors():
    with pytest.raises(ValueError, match="no estimate"):
        smooth_track(np.array([0, 1]), np.zeros((2, 2)), np.array([0, 0, 1, 1]))
    with pytest.raises(ValueError, match="strictly increasing"):
        smooth_track(np.array([1, 0]), np.zeros((2, 2)), np.array([0, 0]))
    with pytest.raises(ValueError, match="half_window"):
        smooth_shot(np.array([0.0]), np.zeros((1, 2)), np.array([0.0]), half_window=0)


def _pan_frames(panorama: np.ndarray, x0: int, y0: int, n: int, step: int, window=(480, 270), out=(160, 90)):
    frames = []
    for i in range(n):
        x = x0 + i * step
        crop = panorama[y0 : y0 + window[1], x : x + window[0]]
        frames.append(cv2.resize(crop, out, interpolation=cv2.INTER_AREA))
    return frames


def test_cut_detected_in_a_synthetic_video(field_panorama, tmp_path):
    """A slow pan over the real field panorama (4 px of panorama per frame), then a cut to another
    part of it, written to and read back from an .mp4: exactly one cut, at the right frame."""
    from glradial.media.video_io import VideoInfo, VideoReader, VideoWriter

    pano = field_panorama
    shot_a = _pan_frames(pano, 200, 420, 18, 4)
    shot_b = _pan_frames(pano, 1100, 380, 12, -3)
    path = tmp_path / "cut.mp4"
    with VideoWriter(path, VideoInfo.of((160, 90), 25)) as writer:
        for frame in shot_a + shot_b:
            writer.write(frame)
    with VideoReader(path) as reader:
        cuts = detect_cuts(reader)
    assert cuts == [0, len(shot_a)]


def test_fast_pan_is_not_a_cut(field_panorama):
    """A pan 4x faster (16 px per frame) inside one shot stays one shot."""
    frames = _pan_frames(field_panorama, 100, 420, 40, 16)
    assert detect_cuts(frames) == [0]


def test_detector_scores_flag_the_cut_clearly(field_panorama):
    frames = _pan_frames(field_panorama, 200, 420, 10, 4) + _pan_frames(field_panorama, 1100, 380, 5, 4)
    detector = ShotDetector()
    for frame in frames:
        detector.update(frame)
    scores = np.array(detector.scores)
    assert scores[9] > detector.threshold and scores[9] > 5 * np.median(np.delete(scores, 9))


def test_cuts_between_cameras_of_one_stadium(ctx):
    """Broadcast cuts mostly join two views of the same green pitch: a zooming pan, a cut to a
    tighter camera, a cut to a third camera, then a fast pan (3° per frame): exactly the two cuts."""
    import glradial
    from glradial.synthesis.crops import CropParams, render_crops

    panorama = glradial.stadium_panorama(9, (1024, 512))
    params = [CropParams(pan=-20 + 0.4 * i, tilt=-12, roll=0, hfov=50 - 0.5 * i, k1=-0.2, k2=0.03) for i in range(16)]
    params += [CropParams(pan=5 + 0.3 * i, tilt=-14, roll=0, hfov=25, k1=-0.1, k2=0.01) for i in range(8)]
    params += [CropParams(pan=-30 + 3 * i, tilt=-10, roll=0, hfov=40, k1=-0.1, k2=0.01) for i in range(12)]
    frames = render_crops(panorama, params, size=(160, 90))
    assert detect_cuts(frames) == [0, 16, 24]


def _confident_track(seed: int, k1_of_t, n: int = 150, every: int = 3, sure: float = 0.3):
    """Known lens trajectory ``k1_of_t`` (k2 on the manifold) sampled every ``every`` frames by an
    estimator that states its uncertainty honestly (error ~ N(0, (u / 1.645)^2) in px at 1920, so u
    is its p90): a fraction ``sure`` of sure samples (u = 2 px), the others unsure (u = 40 px), a
    third of which are gross outliers far beyond even that (e.g. a fit locked on a wrong structure).
    With the unsure samples in the majority the robust (MAD) step alone cannot tell them apart."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    truth = np.stack([k1_of_t(t), manifold_k2(k1_of_t(t))], 1)
    times = np.arange(0, n, every)
    u_px = np.where(rng.random(len(times)) < sure, 2.0, 40.0)
    per_px = 1.0 / (WIDTH_PX * 0.5737**3)  # k1 change that moves the 16:9 corner by 1 px at 1920
    raw = truth[times].copy()
    raw[:, 0] += rng.normal(0.0, u_px / 1.645) * per_px
    gross = (u_px > 10) & (rng.random(len(times)) < 0.33)
    raw[gross, 0] += rng.choice([-1, 1], gross.sum()) * 150 * per_px
    return truth, times, raw, u_px


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_confidence_weighting_converges_on_a_static_camera(seed):
    truth, times, raw, u_px = _confident_track(seed, lambda t: np.full(t.shape, -0.3))
    shots = np.zeros(len(truth), dtype=int)
    plain, _, none = smooth_track(times, raw, shots, half_window=40)
    weighted, _, stated = smooth_track(times, raw, shots, half_window=40, uncertainty=u_px / WIDTH_PX)
    plain_err = max_displacement(plain, truth) * WIDTH_PX
    weighted_err = max_displacement(weighted, truth) * WIDTH_PX
    assert np.all(np.isnan(none))
    # the sure samples (2 px p90 each, ~15 in a window) pin the lens to ~1 px or better (the first
    # and last frames fit a line to one side only, hence 1.25 rather than 2 / sqrt(15));
    # weighting all samples equally lets the 40-px ones pull it several px away
    assert np.percentile(weighted_err, 90) < 1.25, np.percentile(weighted_err, 90)
    assert np.mean(weighted_err) < 0.5 * np.mean(plain_err)
    # the smoothed uncertainty is stated below the single sure sample's 2 px (evidence combined,
    # at most 2x: INDEPENDENT_SAMPLES) and still covers the actual error on >= 90 % of frames
    stated_px = stated * WIDTH_PX
    assert np.all(stated_px <= 2.0 + 1e-9) and np.all(stated_px >= 0.5)
    assert np.mean(weighted_err <= stated_px) >= 0.9


@pytest.mark.parametrize("seed", [0, 1])
def test_confidence_weighting_still_follows_a_zoom(seed):
    """A zoom from k1 -0.45 to -0.15 over 150 frames (a 92 px change along the manifold) with the same
    mixed-confidence estimates: the weighted local line tracks it within ~1 px."""
    truth, times, raw, u_px = _confident_track(seed, lambda t: -0.45 + 0.3 * t / 149.0)
    shots = np.zeros(len(truth), dtype=int)
    assert max_displacement(truth[0], truth[-1]) * WIDTH_PX > 80
    # the same window as the static camera: the local line, not a short window, follows the zoom
    weighted, _, stated = smooth_track(times, raw, shots, half_window=40, uncertainty=u_px / WIDTH_PX)
    inside = slice(0, times[-1] + 1)
    error = max_displacement(weighted[inside], truth[inside]) * WIDTH_PX
    assert np.percentile(error, 90) < 1.5, np.percentile(error, 90)


def test_unsure_shot_keeps_a_large_uncertainty():
    """Only unsure samples (40 px) that scatter as stated: the smoothed lens is never claimed better
    than 40 / 2 px, so 'correct --auto' can flag the shot as doubtful."""
    rng = np.random.default_rng(5)
    n = 60
    times = np.arange(0, n, 3)
    per_px = 1.0 / (WIDTH_PX * 0.5737**3)
    raw = np.stack([-0.3 + rng.normal(0, 40 / 1.645, len(times)) * per_px, np.full(len(times), manifold_k2(-0.3))], 1)
    _, _, stated = smooth_track(times, raw, np.zeros(n, int), half_window=30, uncertainty=np.full(len(times), 40 / WIDTH_PX))
    assert np.all(stated * WIDTH_PX >= 20.0 - 1e-6)
    with pytest.raises(ValueError, match="uncertainty must be >= 0"):
        smooth_track(times, raw, np.zeros(n, int), uncertainty=np.full(len(times), np.nan))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_static_camera_gets_one_lens_for_the_whole_shot(seed):
    """With stated uncertainties, a static camera's track is held at one lens (no wobble, one set of
    maps), within the stated uncertainty of the truth on >= 90 % of frames; a zoom of the same
    length is not held (92 px of change is far above any stated uncertainty)."""
    truth, times, raw, u_px = _confident_track(seed, lambda t: np.full(t.shape, -0.3))
    shots = np.zeros(len(truth), dtype=int)
    held, _, stated = smooth_track(times, raw, shots, half_window=40, uncertainty=u_px / WIDTH_PX)
    assert len(np.unique(held, axis=0)) == 1
    assert np.mean(max_displacement(held, truth) * WIDTH_PX <= stated * WIDTH_PX) >= 0.9
    zoom_truth, times, raw, u_px = _confident_track(seed, lambda t: -0.45 + 0.3 * t / 149.0)
    followed, _, _ = smooth_track(times, raw, shots, half_window=40, uncertainty=u_px / WIDTH_PX)
    assert len(np.unique(followed, axis=0)) > 100


def test_hold_static_known_answers():
    """The rule on hand-made samples: two estimates 2 sigma apart in displacement (chi-square 1 each
    around their mean) are held at the inverse-variance mean; 4 sigma apart (chi-square 4) are not;
    rejected samples (weight 0) do not count; one accepted sample is not enough."""
    from glradial.video.smoothing import P90_SIGMA, STATIC_CHI2, hold_static

    r = 0.5737
    u = np.array([2.0, 2.0]) / WIDTH_PX  # stated 90 % bounds, lens units
    sigma = u[0] / P90_SIGMA
    dk1 = 2 * sigma / r**3  # a k1 difference that moves the 16:9 corner by 2 sigma
    track = np.array([[-0.3, 0.07], [-0.29, 0.07], [-0.28, 0.07]])
    near = np.array([[-0.3, 0.07], [-0.3 + dk1, 0.07]])
    held = hold_static(track, near, u, np.ones(2))
    assert STATIC_CHI2 >= 1.0 and np.allclose(held, near.mean(axis=0)) and len(np.unique(held, axis=0)) == 1
    far = np.array([[-0.3, 0.07], [-0.3 + 2 * dk1, 0.07]])
    assert np.array_equal(hold_static(track, far, u, np.ones(2)), track)
    assert np.array_equal(hold_static(track, near, u, np.array([1.0, 0.0])), track)
    three = np.vstack([near, [[0.2, 0.0]]])  # a gross outlier the robust step rejected
    assert np.allclose(hold_static(track, three, np.append(u, u[0]), np.array([1.0, 1.0, 0.0])), near.mean(axis=0))
