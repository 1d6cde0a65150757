"""``glradial live``'s run: a live source to an output, frame by frame, on three threads.

* the **reader** thread decodes the source (:class:`glradial.media.stream_io.LiveSource`) and pushes
  every frame, with its timestamp, into the :class:`~glradial.video.live.LiveCorrector` (which drops
  frames rather than let the delay grow when the input outruns the rest);
* the corrector's **worker** thread corrects them (planar YUV in its own samples where the output
  takes it, :mod:`glradial.remapping.planes`);
* the caller's thread (:func:`run_live`) encodes each corrected frame (the writer: a file, stdout or
  UDP, :func:`glradial.media.stream_io.open_live_output`; None: no video out), then sends its OpenTrackIO sample (UDP,
  :class:`glradial.export.opentrackio_udp.SampleSender`) and appends it to the samples file, and
  only then counts the frame as left (its delay, :class:`~glradial.video.live.LiveStats`): the
  sample goes as soon as its frame is out, never before.

A status line (frames out, fps, delay percentiles, dropped, late) is handed to ``status`` at most
every ``status_every`` seconds.
"""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path
from typing import Callable

import av

from ..media.atomic import atomic_path
from .live import LiveCorrector

__all__ = ["run_live", "SampleFile"]


class SampleFile:
    """OpenTrackIO samples appended as they are made to a file that appears complete at
    :meth:`close` (atomic, :func:`glradial.media.atomic.atomic_path`): JSON lines, or a CBOR
    sequence with ``cbor``. :meth:`abort` leaves nothing."""

    def __init__(self, path: str | Path, cbor: bool = False) -> None:
        self.path, self.separator, self.count = Path(path), b"" if cbor else b"\n", 0
        self._context = atomic_path(self.path)
        self._file = open(self._context.__enter__(), "wb")

    def write(self, payload: bytes) -> None:
        self._file.write(payload + self.separator)
        self.count += 1

    def close(self) -> None:
        self._file.close()
        self._context.__exit__(None, None, None)

    def abort(self) -> None:
        self._file.close()
        with contextlib.suppress(KeyboardInterrupt):
            self._context.__exit__(KeyboardInterrupt, KeyboardInterrupt(), None)


def _read(source, corrector: LiveCorrector, failure: list) -> None:
    """The reader thread: every frame of ``source`` into ``corrector``; an error goes to ``failure``."""
    try:
        for frame in source.frames():
            corrector.push(frame, source.timestamp(frame))
    except BaseException as err:
        failure.append(err)
    finally:
        corrector.finish()


def run_live(source, writer, corrector: LiveCorrector, *, sender=None, samples: SampleFile | None = None,
             cbor: bool = False, status: Callable[[str], None] | None = None, status_every: float = 1.0) -> str:
    """Run the stream until the source ends (module docstring); returns why it ended (``"eof"`` or
    ``"idle"``: ``idle_timeout`` without data). An error of the source midway is raised after the
    frames before it were written; a KeyboardInterrupt (Ctrl-C, or SIGTERM through the CLI) passes
    through: the caller closes the outputs either way."""
    from ..export.opentrackio import encode_sample

    failure: list[BaseException] = []
    reader = threading.Thread(target=_read, args=(source, corrector, failure), name="glradial-live-read", daemon=True)
    reader.start()
    shown = time.monotonic()
    while True:
        item = corrector.pull(0.1, leave=False)
        if item is None:
            if corrector.done:
                break
        else:
            if writer is None:  # OUTPUT none: the samples only
                pass
            elif isinstance(item.image, av.VideoFrame):
                writer.write(item.image)
            else:
                writer.write(item.image, item.pts)
            if item.sample is not None:
                payload = encode_sample(item.sample, cbor)
                if sender is not None:
                    sender.send(payload)
                if samples is not None:
                    samples.write(payload)
            corrector.left(item)
        if status is not None and time.monotonic() - shown >= status_every:
            shown = time.monotonic()
            status(corrector.stats.line())
    reader.join(timeout=1.0)
    if failure:
        raise failure[0]
    return source.ended or "eof"
