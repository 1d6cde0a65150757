"""Issue 35's two-shot clips: a picture with a lens of its own used as a pinhole source
(``ShotSpec.source_lens``/``source_centre``), and the frames right after a cut into a zoom.

Oracles: OpenCV's own distortion model (``cv2.projectPoints`` with the camera matrix ``fx = fy =
width``, so its coefficients are glradial's width-normalised ones) draws the straight lines of a
distorted picture independently of glradial; a clip's frames carry a known lens by construction
(:mod:`glradial.video.clips`, checked against ``glradial.correct`` in tests/video/test_shots.py); ffprobe
says which frames are B-frames.
"""

from __future__ import annotations

import math
import shutil
import subprocess

import cv2
import numpy as np
import pytest
from repo_scripts import load_script

from glradial.lens.lens import Lens
from glradial.lens.metrics import manifold_k2, max_displacement_px
from glradial.video.clips import ShotSpec, render_clip, render_shot
from glradial.video.shot_fit import fit_shot

SIZE = (480, 270)
#: the picture's own lens and its centre (widths from the picture's centre), as strong and as far
#: off centre as the real wide camera's (scripts/make_clips.py: -0.52 / +0.25 about (0.016, -0.082))
OWN = (-0.5, 0.25)
CENTRE = (0.03, -0.06)


def _distorted_grid(size: tuple[int, int], lens: tuple[float, float], centre: tuple[float, float]) -> np.ndarray:
    """A picture of straight lines (9 upright ones in red, 7 level ones in green, in the pinhole view)
    seen through ``lens`` about ``centre``, drawn by OpenCV's forward model: each line's points
    projected with ``cv2.projectPoints`` (fx = fy = width, principal point the centre) and joined by
    short segments."""
    width, height = size
    camera = np.array([[width, 0, width / 2 - 0.5 + centre[0] * width],
                       [0, width, height / 2 - 0.5 + centre[1] * width], [0, 0, 1]], np.float64)
    coefficients = np.array([lens[0], lens[1], 0.0, 0.0], np.float64)
    picture = np.zeros((height, width, 3), np.uint8)
    t = np.linspace(-1.0, 1.0, 400)
    families = [(0, [np.stack([np.full_like(t, x), t * 0.6], 1) for x in np.linspace(-0.72, 0.72, 9)]),
                (1, [np.stack([t * 0.8, np.full_like(t, y)], 1) for y in np.linspace(-0.42, 0.42, 7)])]
    for channel, lines in families:  # pinhole points (x/z, y/z) in width units about the principal point
        layer = np.zeros((height, width), np.uint8)
        for line in lines:
            points = np.concatenate([line, np.ones((len(line), 1))], 1)
            pixels, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), camera, coefficients)
            cv2.polylines(layer, [np.round(pixels.reshape(-1, 2) * 16).astype(np.int32)], False, 255, 4, cv2.LINE_AA, shift=4)
        picture[..., channel] = layer
    return picture


def _straightness_px(frame: np.ndarray) -> float:
    """The largest RMS distance (px) of a line's centre points from their straight-line fit, over
    the long lines of ``frame`` (red: upright lines, centre per row; green: level ones, per column)."""
    worst = 0.0
    for channel in (0, 1):
        plane = frame[..., channel].astype(np.float64)
        count, labels = cv2.connectedComponents((plane > 64).astype(np.uint8))
        for label in range(1, count):
            weight = np.where(labels == label, plane, 0.0)
            if channel == 1:
                weight = weight.T
            rows = np.flatnonzero(weight.sum(axis=1) > 0)
            if len(rows) < 60:
                continue
            cols = (weight[rows] * np.arange(weight.shape[1])).sum(axis=1) / weight[rows].sum(axis=1)
            points = np.stack([cols, rows], 1)[5:-5]  # line ends: cut by the frame's edge
            centred = points - points.mean(axis=0)
            normal = np.linalg.svd(centred, full_matrices=False)[2][1]
            worst = max(worst, float(np.sqrt(np.mean((centred @ normal) ** 2))))
    return worst


def test_a_picture_with_its_own_lens_renders_as_a_pinhole_one():
    """A picture of a grid of straight lines seen through a strong off-centre lens (OpenCV's model):
    rendered with that lens as its ``source_lens``/``source_centre`` and no clip lens, every line
    of the frame is straight again (to a small fraction of a px); rendered as if it
    were pinhole, the same lines bend by several px. With a clip lens on top, the frame corrected by
    the clip's truth is straight too: the truth is the clip's lens, the picture's own removed."""
    import glradial

    picture = _distorted_grid((960, 540), OWN, CENTRE)
    own = ShotSpec(picture, 1, (0.0, 0.0, 1.0), (0.0, 0.0, 1.0), (0.0, 0.0), source_lens=OWN, source_centre=CENTRE)
    naive = ShotSpec(picture, 1, (0.0, 0.0, 1.0), (0.0, 0.0, 1.0), (0.0, 0.0))
    straight = _straightness_px(next(render_shot(own, SIZE))[0])
    bent = _straightness_px(next(render_shot(naive, SIZE))[0])
    assert straight < 0.25 and bent > 4.0, (straight, bent)  # centre ignored: 1.1 px; k1 0.05 off: 0.3 px
    through = ShotSpec(picture, 1, (3.0, -2.0, 1.1), (3.0, -2.0, 1.1), (-0.3, -0.3), source_lens=OWN, source_centre=CENTRE)
    frame, lens, _ = next(render_shot(through, SIZE))
    assert _straightness_px(frame) > 4 * straight
    assert _straightness_px(glradial.correct(frame, *lens, backend="cpu")) < 0.5


def test_a_source_lens_is_checked():
    """Bad input: a source lens or centre that is not two finite numbers, and a source lens that
    folds over inside the view (its forward model turns back: pixels beyond the fold would be
    sampled from the wrong place, silently), are ValueErrors naming the argument and the value."""
    picture = np.zeros((90, 160, 3), np.uint8)
    for name, value in (("source_lens", (float("nan"), 0.0)), ("source_centre", (0.1,)), ("source_lens", (-0.5, "0"))):
        with pytest.raises(ValueError, match=f"{name} must be two finite numbers, got"):
            next(render_shot(ShotSpec(picture, 1, **{name: value}), (64, 36)))
    with pytest.raises(ValueError, match=r"source_lens \(-2.0, 0.0\) folds over at radius 0.408"):  # 1 + 3 k1 r^2 = 0
        next(render_shot(ShotSpec(picture, 1, source_lens=(-2.0, 0.0)), (64, 36)))


def test_the_plumb_line_tool_recovers_a_known_lens_and_centre():
    """scripts/plumb_lines.py (the wide camera's own lens for the two-shot clips) on a picture whose
    lines OpenCV drew through a known off-centre lens: segments drawn 2 px beside the lines (as by
    eye) are refined to the lines, and the fitted lens with its centre moves no point of the frame
    by more than 1 px at 1920 from the true one (after the best homography between the two pinhole
    views: a centre and a lens trade a little against a projective change, which bends no line)."""
    from glradial.lens.lensfuncs import distort_point, undistort_point_exact

    plumb = load_script("scripts/plumb_lines.py")
    size = (960, 540)
    picture = _distorted_grid(size, OWN, CENTRE)
    camera = np.array([[size[0], 0, size[0] / 2 - 0.5 + CENTRE[0] * size[0]],
                       [0, size[0], size[1] / 2 - 0.5 + CENTRE[1] * size[0]], [0, 0, 1]], np.float64)
    drawn = []
    for x in (-0.72, -0.36, 0.0, 0.36, 0.72):  # five of the upright lines, four of the level ones
        drawn.append(np.stack([np.full(9, x), np.linspace(-0.5, 0.5, 9)], 1))
    for y in (-0.42, -0.14, 0.14, 0.42):
        drawn.append(np.stack([np.linspace(-0.7, 0.7, 9), np.full(9, y)], 1))
    segments = []
    for line in drawn:
        pixels, _ = cv2.projectPoints(np.concatenate([line, np.ones((9, 1))], 1), np.zeros(3), np.zeros(3), camera,
                                      np.array([OWN[0], OWN[1], 0.0, 0.0]))
        pixels = pixels.reshape(-1, 2) + 2.0  # drawn by eye, 2 px off
        inside = (pixels[:, 0] > 4) & (pixels[:, 0] < size[0] - 5) & (pixels[:, 1] > 4) & (pixels[:, 1] < size[1] - 5)
        pixels = pixels[inside]
        segments.append([[*pixels[i], *pixels[i + 1]] for i in range(len(pixels) - 1)])
    result = plumb.measure(picture, segments, free_centre=True)
    assert result["rms_before_px"] > 3.0 and result["rms_after_px"] < 0.3, result
    grid = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 33), np.linspace(-0.28, 0.28, 19)), -1).reshape(-1, 2)
    pinhole, _ = undistort_point_exact(grid - np.asarray(CENTRE), *OWN)  # the frame's points, true pinhole view
    fitted, _ = undistort_point_exact(grid - np.array([result["cx"], result["cy"]]), result["k1"], result["k2"])
    h, _ = cv2.findHomography(fitted, pinhole, 0)
    mapped = np.concatenate([fitted, np.ones((len(fitted), 1))], 1) @ h.T
    back = distort_point(mapped[:, :2] / mapped[:, 2:], *OWN) + np.asarray(CENTRE)  # where the fit puts them
    assert float(np.max(np.hypot(*(back - grid).T))) * 1920 < 1.0, result


def _encode(path, frames: np.ndarray) -> None:
    """H.264 with B-frames and no key frame forced at a cut (a fixed-GOP broadcast encode)."""
    height, width = frames.shape[1:3]
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}",
                    "-r", "25", "-i", "-", "-c:v", "libx264", "-crf", "14", "-x264-params",
                    "keyint=60:bframes=3:scenecut=0", "-pix_fmt", "yuv420p", str(path)], input=frames.tobytes(), check=True)


def _decoded(path) -> list[int]:
    """The frames the sparse decode of pass 1 decodes."""
    from glradial.media.video_io import VideoReader, frame_timestamps

    order = frame_timestamps(path)
    with VideoReader(path, order="rgb", max_width=64) as reader:
        reader.skip_nonreference()
        return [int(np.searchsorted(order, item.pts)) for item in reader.items()]


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs ffmpeg (make setup installs it)")
def test_the_frames_right_after_a_cut_carry_the_new_zoom_lens(gl_ctx, tmp_path):
    """A static shot (k1 -0.35) cut to a fast zoom-in (1.0 -> 1.8x over 14 frames, k1 -0.45 ->
    -0.12, about 10 px of lens change per frame at 1920) whose first frame the sparse decode skips:
    the cut is placed on it, and the frames from the cut to the shot's first decoded frame carry the
    zoom's lens at their own zoom (within 6 px of the truth, the zoom test's tolerance in
    tests/video/test_shots.py), not the first decoded frame's (which would be off by more than that)."""
    import glradial
    from glradial.video.video_pipeline import track_video

    stadium = glradial.stadium_panorama(3, (2048, 1024))
    guess = Lens(-0.2, float(manifold_k2(-0.2)))
    for first in range(9, 14):  # the first shot's length: the cut must fall on a frame the decode skips
        shots = [ShotSpec(stadium, first, (0.0, -8.0, 1.0), (0.0, -8.0, 1.0), (-0.35, -0.35), hfov_deg=45, panorama=True),
                 ShotSpec(stadium, 14, (25.0, -10.0, 1.0), (25.0, -10.0, 1.8), (-0.45, -0.12), hfov_deg=50, panorama=True)]
        frames, truth = render_clip(shots, SIZE)
        path = tmp_path / f"cut{first}.mp4"
        _encode(path, frames)
        decoded = _decoded(path)
        if first not in decoded:
            break
    else:
        pytest.fail(f"the cut fell on a decoded frame at every length tried ({decoded})")
    sample = min(i for i in decoded if i > first)
    track = track_video(path, lambda _frame: guess, every=2, progress=False)
    assert list(np.flatnonzero(np.diff(track.shot)) + 1) == [first]
    error = max_displacement_px(track.lens, truth.lens)
    near = slice(first, sample)
    held = max_displacement_px(truth.lens[sample], truth.lens[near])  # the first decoded frame's lens, held
    assert held.max() > 6.0 and error[near].max() < 6.0, (error[first:sample + 3], held)
    assert error[first:first + 3].max() < 6.0, error[first:first + 3]


def test_a_zoom_read_from_its_frames_alone_stays_doubtful():
    """A shot without geometry (no chains, no pan) is read from its per-frame estimates: one lens.
    Static, a 30 px bound below its lens's 100+ px shift is applied (correcting helps even at the
    bound); zooming by 50 % (the lens follows the zoom, which one lens cannot), the same estimates
    and bound stay doubtful, ``no_geometry``, passed through: their bound covers only the zooms they
    were read at."""
    from glradial.estimation.lens_estimate import LensEstimate
    from glradial.video.shot_fit import ShotEvidence, ShotSample, fit_shot

    k1 = -0.3
    lens = (k1, float(manifold_k2(k1)))
    shift = float(max_displacement_px(np.asarray(lens), np.zeros(2)))
    samples = [ShotSample(10 * i, None, LensEstimate(*lens, uncertainty_px=30.0, method="net") if i % 3 == 0 else None)
               for i in range(5)]
    static = fit_shot(ShotEvidence(samples, [], [0.0] * 5))
    zooming = fit_shot(ShotEvidence(samples, [], list(np.linspace(0.0, np.log(1.5), 5))))
    assert shift > 3 * 30.0
    assert static.source == "frames" and static.uncertainty_px == pytest.approx(30.0) and not static.doubtful, static
    assert zooming.source == "frames" and zooming.doubtful and zooming.reason == "no_geometry", zooming


def _pure_zoom_evidence(zooms: np.ndarray, truth: np.ndarray, estimates: list, pairs: bool):
    """A pure zoom's evidence: per-frame ``estimates`` (one per sample, or None), no line chains,
    and (``pairs``) the frame pairs of consecutive samples and of samples two apart, drawn by
    OpenCV's forward model: pinhole points ``e^z P`` (the same scene points ``P`` at each sample's
    log zoom ``z``, about the centre) projected with ``cv2.projectPoints`` (fx = fy = 1: lens units)
    through each sample's true lens ``truth[i]``, 0.3 px of noise on a 640-px matching copy."""
    from glradial.video.frame_motion import Matches
    from glradial.video.shot_fit import ShotEvidence, ShotSample

    rng = np.random.default_rng(3)
    scene = rng.uniform(-1.0, 1.0, (600, 2)) * [0.5, 0.28]  # pinhole points at zoom 1, lens units

    def seen(i: int) -> tuple[np.ndarray, np.ndarray]:
        at = scene * math.exp(zooms[i])
        inside = (np.abs(at[:, 0]) < 0.48) & (np.abs(at[:, 1]) < 0.27)
        points = np.concatenate([at, np.ones((len(at), 1))], 1)
        pixels, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), np.eye(3), np.array([*truth[i], 0.0, 0.0]))
        return pixels.reshape(-1, 2) + rng.normal(0.0, 0.3 / 640, (len(at), 2)), inside

    views = [seen(i) for i in range(len(zooms))]
    found = []
    for i, j in [(i, i + 1) for i in range(len(zooms) - 1)] + [(i, i + 2) for i in range(len(zooms) - 2)]:
        both = views[i][1] & views[j][1]
        found.append((i, j, Matches(views[i][0][both], views[j][0][both], 640)))
    samples = [ShotSample(10 * i, None, e) for i, e in enumerate(estimates)]
    return ShotEvidence(samples, found if pairs else [], list(zooms), travel=float(zooms[-1]))


def test_a_zoom_read_from_its_frames_follows_it():
    """A zoom without lines (no chains, no pan), read by its per-frame estimates at every sample: the
    wide end's estimate sure (10 px) and right, the zoomed-in ones loose (50 px) and reading the lens
    ever weaker than it is (as the CNN reads soft, lineless crops). The true lens is a fixed lens
    cropped by the zoom (``k1 = -0.4 e^(-2 z)``: not the model's line in log zoom). Read with the frame
    pairs (they tie the lens at one zoom to the next; the estimates give the level), the shot follows
    the zoom at every sample to within 3 px of the best line in log zoom through the truth (itself
    a few px off this curved truth); from the estimates alone, a weighted line, it follows
    their bias (more than 10 px off at the zoomed-in end). Either way the stated bound covers the
    error at every sample, and one lens for the zoom (what a frames-read zoom was) is far worse. With
    only two estimates (the estimator's rhythm, samples 0 and 3) the pairs still carry the zoom;
    without pairs two estimates give one lens, doubtful."""
    from glradial.estimation.lens_estimate import LensEstimate

    zooms = np.linspace(0.0, math.log(1.6), 5)
    k1 = -0.4 * np.exp(-2.0 * zooms)
    truth = np.stack([k1, manifold_k2(k1)], 1)
    estimates = [LensEstimate(float(k + 0.03 * i), float(manifold_k2(k + 0.03 * i)), uncertainty_px=10.0 if i == 0 else 50.0,
                              method="lines" if i == 0 else "net") for i, k in enumerate(k1)]
    line = np.polyval(np.polyfit(zooms, k1, 1), zooms)  # the model's own limit on this curved truth
    floor = float(np.max(max_displacement_px(np.stack([line, manifold_k2(line)], 1), truth)))
    for pairs in (True, False):
        shot = fit_shot(_pure_zoom_evidence(zooms, truth, estimates, pairs))
        error = max_displacement_px(shot.lens_at(zooms), truth)
        assert shot.source == "frames" and shot.zooming, shot
        assert error.max() <= shot.uncertainty_px, (pairs, error, shot.uncertainty_px)
        if pairs:
            assert error.max() < floor + 3.0, (error, floor)
        else:
            assert error[-1] > 10.0, error
    one_lens = max_displacement_px(np.median([[e.k1, e.k2] for e in estimates], axis=0), truth)
    assert one_lens.max() > 20.0, one_lens
    rhythm = [e if i % 3 == 0 else None for i, e in enumerate(estimates)]  # every 3rd sample: two estimates
    shot = fit_shot(_pure_zoom_evidence(zooms, truth, rhythm, True))
    error = max_displacement_px(shot.lens_at(zooms), truth)
    assert shot.zooming and error.max() < floor + 3.0 and error.max() <= shot.uncertainty_px, (error, shot)
    alone = fit_shot(_pure_zoom_evidence(zooms, truth, rhythm, False))  # two points fix no line worth a bound
    assert not alone.zooming and alone.doubtful and alone.reason == "no_geometry", alone


def test_a_sample_without_lines_gets_its_own_estimate():
    """The per-frame estimator runs on every ``estimate_every``-th sample, and also on every sample
    whose line detection finds fewer than FEW_CHAINS chains (a blank frame: none); a picture of 16
    straight lines (33 chains) keeps the rhythm."""
    from glradial.video.shot_evidence import FEW_CHAINS, ShotCollector

    lines = _distorted_grid(SIZE, (-0.2, float(manifold_k2(-0.2))), (0.0, 0.0))
    blank = np.full_like(lines, 90)
    for picture, expected in ((lines, [0, 3]), (blank, [0, 1, 2, 3, 4])):
        seen = []

        def estimator(frame: np.ndarray) -> tuple[float, float]:
            seen.append(len(collector.evidence.samples))
            return (-0.2, float(manifold_k2(-0.2)))

        collector = ShotCollector(estimator, estimate_every=3)
        for i in range(5):
            collector.add(10 * i, picture)
        chains = [len(s.evidence.chains) if s.evidence is not None else 0 for s in collector.evidence.samples]
        assert seen == expected, (seen, chains)
        assert all(c >= FEW_CHAINS for c in chains) if picture is lines else all(c < FEW_CHAINS for c in chains)


def test_a_cropped_lens_is_a_digital_zoom():
    """``ShotSpec(cropped=True)``: one lens cropped by the zoom, ``(k1 / s^2, k2 / s^4)``, so the
    zoomed-in frame is the wide frame's centre, 1/s of it, scaled up (oracle: OpenCV's affine warp of
    the first frame; blurred noise as the picture). The default law (the lens held at -0.3 while
    zooming) is not, by a wide margin."""
    rng = np.random.default_rng(0)
    picture = cv2.resize(cv2.GaussianBlur(rng.uniform(0, 255, (540, 960, 3)).astype(np.uint8), (0, 0), 3), (1920, 1080))
    width, height = SIZE
    scale = 1.5
    crop = np.array([[1 / scale, 0, (width - width / scale) / 2 - 0.5 + 0.5 / scale],
                     [0, 1 / scale, (height - height / scale) / 2 - 0.5 + 0.5 / scale]])
    misfit = {}
    for cropped in (True, False):
        frames, truth = render_clip([ShotSpec(picture, 2, (0, 0, 1.0), (0, 0, scale), (-0.3, -0.3), cropped=cropped)], SIZE)
        expected = cv2.warpAffine(frames[0], crop, SIZE, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        misfit[cropped] = float(np.mean(np.abs(expected.astype(float) - frames[1])[40:-40, 60:-60]))
        if cropped:
            k2 = float(manifold_k2(-0.3))
            np.testing.assert_allclose(truth.lens, [[-0.3, k2], [-0.3 / scale**2, k2 / scale**4]], rtol=1e-12)
    assert misfit[True] < 1.0 and misfit[False] > 4 * misfit[True], misfit
