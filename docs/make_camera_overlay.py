"""Make docs/camera_overlay.png: ``glradial.calibrate`` on a real Bundesliga frame (validation data,
not shipped), the projected template drawn on the frame (960 x 540 PNG).

Usage: ``python docs/make_camera_overlay.py [FRAME_NAME]`` (default 2e57b9_3_1), from the checkout root.
The 640 x 640 file is resized to 1280 x 720 first (it is a squashed 16:9 frame).
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from glradial.camera.calibrate import calibrate  # noqa: E402
from glradial.camera.views import overlay  # noqa: E402
from glradial.media.image_io import write_image  # noqa: E402


def main() -> int:
    name = sys.argv[1] if len(sys.argv) > 1 else "2e57b9_3_1"
    path = ROOT.parent / "shared" / "data" / "broadcast_bundesliga" / f"{name}.jpg"
    frame = cv2.resize(cv2.imread(str(path))[:, :, ::-1], (1280, 720), interpolation=cv2.INTER_CUBIC)
    est = calibrate(np.ascontiguousarray(frame))
    if est.camera is None:
        raise SystemExit(f"{name}: no camera ({est.reason})")
    picture = overlay(frame, est.camera)
    text = (f"{name}: {est.reason}, hfov {est.hfov_deg:.1f} deg, k1 {est.lens.k1:+.3f}, "
            f"camera at ({est.position[0]:.0f}, {est.position[1]:.0f}, {est.position[2]:.0f}) m")
    cv2.rectangle(picture, (0, 0), (1280, 34), (0, 0, 0), -1)
    cv2.putText(picture, text, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.65, (255, 255, 255), 2, cv2.LINE_AA)
    write_image(ROOT / "docs" / "camera_overlay.png", cv2.resize(picture, (960, 540), interpolation=cv2.INTER_AREA))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
