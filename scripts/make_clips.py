"""Build the shot-evaluation clips: shots of a virtual broadcast camera (static, panning, zooming
with the lens following the zoom) over real pictures and procedural stadiums, cut together, each
with its per-frame ground truth beside it (``CLIP.mp4.truth.csv``, :func:`glradial.video.clips.write_clip`).

Real sources (validation only, never training): the three football360 stadium views and the
stadium panorama of ``../shared/data/real_football/`` (views rendered through a lens of their own,
not published, which the line fit reads at k1 -0.025/+0.028/+0.012, docs/eval/shots.md; and an
equirectangular panorama, whose crops have no lens); with ``--set twoshot`` also the real wide
camera of ``../shared/data/real_wide_camera/`` (its own lens, measured by ``scripts/plumb_lines.py``,
removed while rendering); procedural: glradial stadium panoramas. 640x360, 25 fps, H.264 crf 18.

Run: ``python scripts/make_clips.py OUT_DIR [--data ../shared/data/real_football] [--wide
../shared/data/real_wide_camera] [--frames 50] [--set main|check|static|twoshot|stands]`` (``check``:
held-out clips, other lenses and paths, other stadiums; ``static``: static shots only, more
calibration shots for the static shots' bound, see ``bench/eval_shots.py``; ``twoshot``: issue 35's
clips, a static shot, a cut and a zoom whose lens follows it, over real frames, :func:`two_shot_clips`;
``stands``: zooms at procedural stands whose lens follows the zoom by other laws, :func:`stand_zoom_clips`); writes ``OUT_DIR/manifest.json`` (clip -> group, shots, the source picture
of each shot) and the clips.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's glradial, not an installed one
from glradial.video.clips import ShotSpec, render_clip, write_clip  # noqa: E402

SIZE = (640, 360)


def _read(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise SystemExit(f"cannot read {path}")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


#: the real pictures: the three pinhole stadium views and the stadium panorama
VIEWS = tuple(f"football360_cam_{i:07d}.png" for i in (0, 12000, 19000))
PANORAMA = "stadium_01_1k_tonemapped.jpg"


def real_clips(data: Path, n: int) -> dict[str, list[ShotSpec]]:
    """Clips over the real pinhole views (60 deg wide) and the real stadium panorama."""
    views = [_read(data / name) for name in VIEWS]
    pano = _read(data / PANORAMA)
    return {
        "real_a": [
            ShotSpec(views[0], n, k1=(-0.30, -0.30)),
            ShotSpec(views[1], n, (-6, 0, 1.1), (6, 1.5, 1.1), (-0.20, -0.20)),
            ShotSpec(views[2], n, (0, 0, 1.0), (0, 0, 1.4), (-0.30, -0.18)),
        ],
        "real_b": [
            ShotSpec(views[1], n, (0, 0, 1.0), (0, 0, 1.35), (-0.45, -0.30)),
            ShotSpec(views[2], n, k1=(-0.15, -0.15)),
            ShotSpec(views[0], n, (4, 0, 1.05), (-4, -1, 1.05), (-0.60, -0.60)),
        ],
        "real_c": [
            ShotSpec(views[2], n, (-3, 0, 1.05), (3, 0, 1.25), (-0.35, -0.25)),
            ShotSpec(views[0], n, (0, 0, 1.2), (0, 0, 1.0), (-0.10, -0.22)),
            ShotSpec(views[1], n, k1=(-0.70, -0.70), k2_offset=0.05),
        ],
        "real_pano": [
            ShotSpec(pano, n, (-20, -5, 1.0), (20, -5, 1.0), (-0.25, -0.25), hfov_deg=70, panorama=True),
            ShotSpec(pano, n, (60, -8, 1.0), (60, -8, 1.4), (-0.35, -0.22), hfov_deg=70, panorama=True),
            ShotSpec(pano, n, (150, -10, 1.0), (150, -10, 1.0), (-0.10, -0.10), hfov_deg=70, panorama=True),
        ],
    }


def check_clips(data: Path, n: int, seed: int = 1) -> dict[str, list[ShotSpec]]:
    """The held-out set: the same real pictures under other, random lenses and camera paths."""
    views = [_read(data / name) for name in VIEWS]
    rng = np.random.default_rng(seed)
    clips = {}
    for c in range(3):
        shots = []
        for kind in ("static", "pan", "zoom"):
            view = views[int(rng.integers(3))]
            k1 = float(rng.uniform(-0.65, -0.1))
            if kind == "static":
                shots.append(ShotSpec(view, n, (0, 0, 1.0), (0, 0, 1.0), (k1, k1)))
            elif kind == "pan":
                a = float(rng.uniform(3, 8))
                shots.append(ShotSpec(view, n, (-a, 0, 1.1), (a, float(rng.uniform(-1, 1)), 1.1), (k1, k1)))
            else:
                shots.append(ShotSpec(view, n, (0, 0, 1.0), (0, 0, float(rng.uniform(1.2, 1.45))), (k1, k1 + float(rng.uniform(0.05, 0.15)))))
        clips[f"check_{c}"] = [shots[i] for i in rng.permutation(3)]
    return clips


def procedural_clips(n: int, seeds: tuple[int, ...] = (3, 11)) -> dict[str, list[ShotSpec]]:
    """Clips over glradial's procedural stadiums (pitch lines, stands, boards)."""
    import glradial

    clips = {}
    rng = np.random.default_rng(0)
    for seed in seeds:
        pano = glradial.stadium_panorama(seed, (2048, 1024))
        shots = []
        for kind in ("pan", "zoom", "static"):
            k1 = float(rng.uniform(-0.55, -0.1))
            pan, tilt = float(rng.uniform(-40, 40)), float(rng.uniform(-18, -8))
            if kind == "pan":
                shots.append(ShotSpec(pano, n, (pan - 12, tilt, 1.0), (pan + 12, tilt - 2, 1.0), (k1, k1), hfov_deg=50, panorama=True))
            elif kind == "zoom":
                shots.append(ShotSpec(pano, n, (pan, tilt, 1.0), (pan + 3, tilt, 1.4), (k1, k1 + 0.12), hfov_deg=55, panorama=True))
            else:
                shots.append(ShotSpec(pano, n, (pan, tilt, 1.0), (pan, tilt, 1.0), (k1, k1), hfov_deg=45, panorama=True))
        clips[f"proc_{seed}"] = shots
    return clips


def static_clips(data: Path, n: int, seed: int = 2, seeds: tuple[int, ...] = (23, 29, 31)) -> dict[str, list[ShotSpec]]:
    """Static shots only (calibration of the static shots' bound): the real views under other
    lenses, zooms and directions, and procedural stadiums not used elsewhere."""
    import glradial

    views = [_read(data / name) for name in VIEWS]
    rng = np.random.default_rng(seed)
    clips = {}
    for c in range(2):
        shots = []
        for v in rng.permutation(3):
            k1 = float(rng.uniform(-0.7, -0.1))
            camera = (float(rng.uniform(-5, 5)), float(rng.uniform(-2, 2)), float(rng.uniform(1.0, 1.3)))
            shots.append(ShotSpec(views[int(v)], n, camera, camera, (k1, k1)))
        clips[f"static_r{c}"] = shots
    for seed_ in seeds:
        pano = glradial.stadium_panorama(seed_, (2048, 1024))
        shots = []
        for _ in range(3):
            k1 = float(rng.uniform(-0.6, -0.1))
            camera = (float(rng.uniform(-60, 60)), float(rng.uniform(-18, -8)), 1.0)
            shots.append(ShotSpec(pano, n, camera, camera, (k1, k1), hfov_deg=float(rng.uniform(45, 55)), panorama=True))
        clips[f"static_p{seed_}"] = shots
    return clips


#: the real wide camera (``../shared/data/real_wide_camera``): its lens, width-normalised, and the
#: lens's centre (widths from the frame's centre, y down), measured by the plumb-line method on seven
#: lines of frame 0 (``scripts/plumb_lines.py``: straight to 0.57 px RMS at 1536 wide, 11.7 px with no
#: lens; the README's centred checkerboard lens -0.6615/+0.4098 leaves 1.9 px, 2.6 px on the near
#: touchline; known to a few px on these clips, docs/eval/shots.md), and the frames used (0 s and
#: 8 s: the players move, the camera does not)
WIDE_VIDEO = "wide_pitch_camera.mp4"
WIDE_LENS = (-0.5241, 0.2481)
WIDE_CENTRE = (0.0159, -0.0816)
WIDE_FRAMES = (0, 200)
#: the wide frames are used at a third of their 3072 px width (area filter: the lens is width-normalised)
WIDE_WIDTH = 1024


def wide_frames(folder: Path) -> list[np.ndarray]:
    """The real wide camera's frames :data:`WIDE_FRAMES`, RGB, :data:`WIDE_WIDTH` wide."""
    from glradial.media.video_io import VideoReader

    out = []
    with VideoReader(folder / WIDE_VIDEO, order="rgb") as reader:
        for index, image in enumerate(reader):
            if index in WIDE_FRAMES:
                height = round(image.shape[0] * WIDE_WIDTH / image.shape[1])
                out.append(cv2.resize(image, (WIDE_WIDTH, height), interpolation=cv2.INTER_AREA))
            if index >= max(WIDE_FRAMES):
                break
    if len(out) != len(WIDE_FRAMES):
        raise SystemExit(f"{folder / WIDE_VIDEO} has fewer than {max(WIDE_FRAMES) + 1} frames")
    return out


def two_shot_clips(data: Path, wide: Path, n: int) -> dict[str, list[ShotSpec]]:
    """Issue 35's clips from real frames: a static shot (k1 -0.5), a cut, then a 1.0 -> 1.6x zoom-in
    whose lens follows the zoom (k1 -0.35 -> -0.10). Sources whose own lens is known:

    * pinhole crops of the real stadium panorama (no lens of their own; 1024 px around, so soft,
      few pitch lines);
    * the real wide camera's frames, their own lens (:data:`WIDE_LENS` about :data:`WIDE_CENTRE`,
      measured by the plumb-line method, not by the estimator scored) removed exactly while
      rendering (``source_lens``; its field of view, 60 deg assumed, only sets how far a tilt turns:
      a homography of a pinhole picture is one, so the truth stays the clip's lens).

    ``two_shot_pp``: the panorama's other stand, cut to a zoom over its main stand (the one clip whose
    truth is exact); ``two_shot_pw``: the panorama's main stand, cut to a zoom over the wide camera; ``_wp``: the wide
    camera, cut to a zoom over the panorama's other stand; ``_ww``: the wide camera's near touchline
    at 8 s, cut to a zoom over the pitch at 0 s (one camera, two framings). And, with the
    pictures' own lens unknown (the football360 views were rendered through a lens of their own),
    ``two_shot_a``/``_b``/``_c``: each football360 view once static and once zoomed (views 0 then 2,
    1 then 0, 2 then 1)."""
    views = [_read(data / name) for name in VIEWS]
    frames = wide_frames(wide)
    pano = _read(data / PANORAMA)
    static, zoom = (-0.5, -0.5), (-0.35, -0.10)

    def camera(frame: int, start: tuple, end: tuple | None, k1: tuple) -> ShotSpec:
        return ShotSpec(frames[frame], n, start, end or start, k1, hfov_deg=60.0, source_lens=WIDE_LENS,
                        source_centre=WIDE_CENTRE)

    def stand(pan: float, end_zoom: float, k1: tuple) -> ShotSpec:
        return ShotSpec(pano, n, (pan, -8.0, 1.0), (pan, -8.0, end_zoom), k1, hfov_deg=70.0, panorama=True)

    clips = {f"two_shot_{name}": [ShotSpec(views[a], n, k1=static), ShotSpec(views[b], n, (0, 0, 1.0), (0, 0, 1.6), zoom)]
             for name, (a, b) in zip("abc", ((0, 2), (1, 0), (2, 1)))}
    clips.update({
        "two_shot_pp": [stand(95.0, 1.0, static), stand(-90.0, 1.6, zoom)],
        "two_shot_pw": [stand(-90.0, 1.0, static), camera(0, (8.0, -12.0, 1.0), (8.0, -12.0, 1.6), zoom)],
        "two_shot_wp": [camera(0, (0.0, -10.0, 1.0), None, static), stand(95.0, 1.6, zoom)],
        "two_shot_ww": [camera(1, (-10.0, -14.0, 1.1), None, static), camera(0, (0.0, -10.0, 1.0), (0.0, -10.0, 1.6), zoom)],
    })
    return clips


def stand_zoom_clips(n: int, seeds: tuple[int, ...] = (41, 43, 47, 53)) -> dict[str, list[ShotSpec]]:
    """Zooms aimed at the stands of procedural stadiums (few pitch lines), each after a static shot,
    with lenses that follow the zoom by laws other than the other sets' (k1 linear in log zoom):
    a fixed lens cropped by the zoom (``cropped``: k1 / s^2, seeds 41 and 53), a lens held while
    zooming (43), and a zoom-out (47, k1 -0.15 -> a stronger lens, linear in log zoom). For checking
    how a zoom read by its frames follows its zoom and whether its bound covers, on procedural
    pictures only."""
    import glradial

    rng = np.random.default_rng(5)
    clips = {}
    for seed in seeds:
        pano = glradial.stadium_panorama(seed, (2048, 1024))
        pan, tilt, k1 = float(rng.uniform(-60, 60)), float(rng.uniform(2, 8)), float(rng.uniform(-0.5, -0.25))
        static = ShotSpec(pano, n, (pan + 40, -12, 1.0), (pan + 40, -12, 1.0), (-0.3, -0.3), hfov_deg=50, panorama=True)
        zoom = {41: ShotSpec(pano, n, (pan, tilt, 1.0), (pan, tilt, 1.6), (k1, k1), hfov_deg=60, panorama=True, cropped=True),
                43: ShotSpec(pano, n, (pan, tilt, 1.0), (pan, tilt, 1.5), (k1, k1), hfov_deg=60, panorama=True),
                47: ShotSpec(pano, n, (pan, tilt, 1.6), (pan, tilt, 1.0), (-0.15, k1), hfov_deg=60, panorama=True),
                53: ShotSpec(pano, n, (pan, tilt - 4, 1.0), (pan, tilt - 4, 1.5), (k1, k1), hfov_deg=55, panorama=True,
                             cropped=True)}[seed]
        clips[f"stands_{seed}"] = [static, zoom]
    return clips


def _digest(picture: np.ndarray) -> str:
    return hashlib.sha1(np.ascontiguousarray(picture).tobytes()).hexdigest()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/real_football")
    parser.add_argument("--wide", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/real_wide_camera",
                        help="the real wide camera's folder (--set twoshot)")
    parser.add_argument("--frames", type=int, default=50, help="frames per shot (default 50: 2 s)")
    parser.add_argument("--set", choices=("main", "check", "static", "twoshot", "stands"), default="main",
                        help="main: the calibration and report clips; check: held-out real clips and other stadiums; "
                             "static: static shots only, more calibration shots for the static shots' bound; "
                             "twoshot: a static shot, a cut and a zoom over real frames (issue 35); "
                             "stands: zooms at procedural stands, lenses following the zoom by other laws")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    manifest = {}
    if args.set == "main":
        sets = (("real", real_clips(args.data, args.frames)), ("procedural", procedural_clips(args.frames)))
    elif args.set == "twoshot":
        sets = (("real", two_shot_clips(args.data, args.wide, args.frames)),)
    elif args.set == "stands":
        sets = (("procedural", stand_zoom_clips(args.frames)),)
    elif args.set == "check":
        sets = (("real", check_clips(args.data, args.frames)), ("procedural", procedural_clips(args.frames, (5, 17))))
    else:
        clips = static_clips(args.data, args.frames)
        sets = (("real", {k: v for k, v in clips.items() if k.startswith("static_r")}),
                ("procedural", {k: v for k, v in clips.items() if k.startswith("static_p")}))
    names = {_digest(_read(args.data / name)): name for name in VIEWS + (PANORAMA,)}
    for group, clips in sets:
        for name, shots in clips.items():
            frames, truth = render_clip(shots, SIZE)
            write_clip(args.out / f"{name}.mp4", frames, truth)
            sources = [names.get(_digest(shot.source), WIDE_VIDEO if any(shot.source_lens) else "procedural") for shot in shots]
            manifest[name] = {"group": group, "shots": len(shots), "frames": len(frames), "sources": sources}
            print(f"{name}: {len(shots)} shots, {len(frames)} frames", flush=True)
    (args.out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")


if __name__ == "__main__":
    main()
