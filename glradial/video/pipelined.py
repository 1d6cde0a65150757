"""Two-thread pipelining for the video passes: one thread produces items (a decoder), a second
transforms them (the frame corrector), the consumer iterates the results in order, with bounded
queues between the steps so that memory does not grow with the file's length."""

from __future__ import annotations

import queue
import threading
from typing import Callable, Iterable, Iterator

__all__ = ["Pipelined", "DEPTH"]

#: frames queued between two threads of the pipeline (bounded memory: ~3 x depth frames in flight)
DEPTH = 4


class Pipelined:
    """Run ``items`` (an iterator: e.g. a decoder) on one thread and ``work`` on a second, with
    bounded queues (``depth`` items) between them and the consumer; iterate to get ``work(item)`` in
    order. ``work=None`` passes items through (decode-ahead only). ``on_worker_exit`` runs on the
    worker thread when it ends (release what it owns, e.g. a GL context). An exception on either
    thread is raised in the consumer; leaving the ``with`` block (normally, by an exception or a
    signal) stops and joins both threads."""

    _END = object()

    def __init__(
        self,
        items: Iterable,
        work: Callable | None = None,
        *,
        depth: int = DEPTH,
        on_worker_exit: Callable[[], None] | None = None,
    ) -> None:
        self._items, self._work, self._exit = iter(items), work, on_worker_exit
        self._decoded: queue.Queue = queue.Queue(depth)
        self._done: queue.Queue = queue.Queue(depth)
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._produce, name="glradial-decode", daemon=True)]
        if work is not None:
            self._threads.append(threading.Thread(target=self._transform, name="glradial-correct", daemon=True))
        else:
            self._decoded = self._done

    def _put(self, target: queue.Queue, entry: tuple) -> bool:
        while not self._stop.is_set():
            try:
                target.put(entry, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def _produce(self) -> None:
        try:
            for item in self._items:
                if not self._put(self._decoded, (True, item)):
                    return
            self._put(self._decoded, (True, self._END))
        except BaseException as err:  # handed to the consumer
            self._put(self._decoded, (False, err))

    def _transform(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    ok, item = self._decoded.get(timeout=0.05)
                except queue.Empty:
                    continue
                if not ok or item is self._END:
                    self._put(self._done, (ok, item))
                    return
                if not self._put(self._done, (True, self._work(item))):
                    return
        except BaseException as err:
            self._put(self._done, (False, err))
        finally:
            if self._exit is not None:
                self._exit()

    def __enter__(self) -> "Pipelined":
        for thread in self._threads:
            thread.start()
        return self

    def __iter__(self) -> Iterator:
        while True:
            ok, item = self._done.get()
            if not ok:
                raise item
            if item is self._END:
                return
            yield item

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join()
