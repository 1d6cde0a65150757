"""Shot-cut detection (glradial.video.cuts.ShotDetector)."""

from __future__ import annotations

import cv2
import numpy as np

from glradial.video.cuts import ShotDetector, detect_cuts


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
