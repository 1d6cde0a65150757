"""A script that exits without closing its :class:`glradial.LiveCorrector` (or ``OnlineShotLens``)
while a worker thread is inside OpenCV must exit cleanly, not abort.

The failure this guards against: CPython 3.11-3.13 stops a daemon thread that tries to take the
interpreter's lock once the interpreter finalizes (``pthread_exit``); a thread returning from an
OpenCV call (which released the lock) unwinds through OpenCV's C++ frames, and the C++ runtime
aborts the process (SIGABRT, "terminate called without an active exception"). Whether it happens
depends on the native call ending during finalization; the child script makes that certain: its
worker enters a ~0.7 s OpenCV call, the script ends, and an object in a reference cycle, collected
by the interpreter's last garbage collection (after ``atexit``, once finalizing), waits there until
the call has returned. A bare daemon thread in the same situation (the control case) aborts, so the
scenario is the real one; glradial's workers must have been stopped and joined before finalization."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

CHILD = '''
import sys, threading, time
import av, cv2, numpy as np
import glradial
from glradial.media.video_io import frame_planes
from glradial.video.live_lens import OnlineShotLens

SIZE = (320, 180)
busy, returned = threading.Event(), threading.Event()


def native_work():
    """About 0.7 s inside one OpenCV call (the interpreter's lock released), said before."""
    busy.set()
    cv2.GaussianBlur(np.zeros((1500, 1500), np.float32), (0, 0), 60)
    returned.set()


class SlowFrames:  # LiveCorrector's ``frames``: called on its worker thread for each planar frame
    pix_fmt = "yuv420p"

    def takes_planes_of(self, pix_fmt):
        return pix_fmt == self.pix_fmt

    def planar_frame(self):
        native_work()
        frame = av.VideoFrame(*SIZE, self.pix_fmt)
        return frame, frame_planes(frame)

    def stamp(self, frame, pts):
        frame.pts = pts
        return frame


calls = []


def estimator(frame):  # the "auto" lens worker's estimator (a thread here)
    calls.append(1)
    if len(calls) > 1:  # not the warm-up call made before the worker says it is ready
        native_work()
    return glradial.Lens(-0.1, 0.0)


case = sys.argv[1]
rgb = np.random.default_rng(0).integers(0, 255, (SIZE[1], SIZE[0], 3), np.uint8)
if case == "corrector":
    live = glradial.LiveCorrector(glradial.Lens(-0.1, 0.0), SIZE, 25, frames=SlowFrames())
    live.push(av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(format="yuv420p"), 0.0)
elif case == "auto":
    live = glradial.LiveCorrector("auto", SIZE, 25, estimator=estimator, auto={"worker": "thread", "every": 1})
    for i in range(1000):
        if busy.is_set():
            break
        live.push(rgb, i / 25)
        live.pull(0.05)
elif case == "online":
    online = OnlineShotLens(estimator, worker="thread", every=1)
    online.wait_ready()
    for i in range(1000):
        if busy.is_set():
            break
        online.observe(i, cv2.resize(rgb, (64, 36)), lambda: rgb)
        time.sleep(0.02)
elif case == "bare":
    threading.Thread(target=native_work, daemon=True).start()
if not busy.wait(60):
    sys.exit("the worker never reached the native call")
time.sleep(0.2)  # it is inside it now
print("worker in native code at exit", flush=True)


class WaitInFinalization:
    def __del__(self, wait=returned.wait):
        wait(5.0)


cycle = WaitInFinalization()
cycle.me = cycle
del cycle
'''


def _run_child(tmp_path: Path, case: str) -> subprocess.CompletedProcess:
    script = tmp_path / "exit_without_close.py"
    script.write_text(CHILD)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}  # this checkout's glradial
    return subprocess.run([sys.executable, str(script), case], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.skipif(sys.version_info >= (3, 14), reason="3.14 no longer stops daemon threads with pthread_exit")
def test_the_scenario_aborts_a_bare_daemon_thread(tmp_path):
    """Control: the child script's exit really kills a daemon thread inside OpenCV (SIGABRT)."""
    done = _run_child(tmp_path, "bare")
    assert "worker in native code at exit" in done.stdout
    assert done.returncode == -signal.SIGABRT, (done.returncode, done.stderr[-2000:])


@pytest.mark.parametrize("case", ["corrector", "auto", "online"])
def test_exit_without_close_while_a_worker_is_in_opencv(tmp_path, case):
    """The correction worker (fixed lens), the ``"auto"`` lens worker thread, and an OnlineShotLens
    used alone: each inside OpenCV when the script ends without close(); the process exits with 0."""
    done = _run_child(tmp_path, case)
    assert "worker in native code at exit" in done.stdout, done.stderr[-2000:]
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert "terminate called" not in done.stderr


def test_close_drops_the_exit_hook_and_twice_is_a_no_op():
    """The exit hook holds a corrector only while it is open: once closed (twice: a no-op), nothing
    keeps it alive (a long-running program that opens many keeps none), and its worker has ended."""
    import gc
    import weakref

    import numpy as np

    import glradial

    live = glradial.LiveCorrector(glradial.Lens(-0.1, 0.0), (64, 36), 25)
    live.push(np.zeros((36, 64, 3), np.uint8), 0.0)
    thread, gone = live._thread, weakref.ref(live)
    live.close()
    live.close()
    assert not thread.is_alive()
    del live
    gc.collect()
    assert gone() is None

