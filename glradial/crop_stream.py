"""An endless, seeded, torch-free stream of distorted training crops (optionally from worker processes).

Convention:

* ``crop_batches(panoramas, batch_size, seed=S, ...)`` yields :class:`CropBatch` values in order
  ``index = 0, 1, 2, ...``. Batch ``i`` is a pure function of ``(S, i)`` and the arguments: its random
  numbers come from ``numpy.random.default_rng([S, i])``, which picks ``panoramas_per_batch``
  panoramas, assigns each crop to one of them and draws the crop parameters
  (:func:`glradial.crops.sample_crop_params`, the paper's distribution unless ``ranges`` is given).
  With ``workers = n >= 1``, batch ``i`` is rendered by worker ``i % n`` and the stream reads the
  workers' queues in turn, so the sequence of batches is identical for any number of workers
  (and to ``workers=0``, up to the renderer being the same driver).
* ``images``: uint8 ``N × h × w × 3`` RGB (``out_size = (w, h)``); ``labels``: float32 ``N × 2`` =
  ``(k1, k2)`` of the ``size`` frame (16:9 in the paper); ``params``: the full
  :class:`~glradial.crops.CropParams` of each crop; ``panorama``: int64 ``N``, the index into
  ``panoramas`` of each crop's source.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Iterator, Mapping, NamedTuple, Sequence

import numpy as np

from .crops import CropParams, CropRenderer, sample_crop_params
from .lens import frame_size

#: Newton steps of the exact inverse when crops come from the paper's distribution: 3 steps from the
#: Drap-Lefevre seed reach 1e-9 lens units on every such lens (see tests/test_crops_stream.py); any
#: other ``ranges`` use the full default of common.glsl.
PAPER_NEWTON_STEPS = 3

#: Seconds between liveness checks of the workers while waiting for a batch.
_POLL_S = 1.0
#: Seconds close() waits for the workers to finish their current batch before terminating them.
_JOIN_S = 30.0


class CropBatch(NamedTuple):
    """One batch of crops (see the module docstring for shapes and units)."""

    images: np.ndarray
    labels: np.ndarray
    params: list[CropParams]
    panorama: np.ndarray
    index: int


def load_panorama(item: Any) -> np.ndarray:
    """A panorama as H×W×3 uint8 RGB: arrays are converted (gray repeated, alpha dropped), paths read."""
    if isinstance(item, (str, os.PathLike)):
        import cv2

        from .native_stderr import silenced

        with silenced():  # libpng/libjpeg chatter on a corrupt file: the ValueError below says it
            image = cv2.imread(str(item), cv2.IMREAD_COLOR)
        if image is None:
            raise ValueError(f"cannot read panorama {str(item)!r}")
        return np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
    array = np.asarray(item)
    if array.dtype != np.uint8:
        raise TypeError(f"panorama arrays must be uint8, got {array.dtype}")
    if array.ndim == 2:
        array = array[:, :, None]
    if array.ndim != 3 or array.shape[2] not in (1, 3, 4):
        raise ValueError(f"panorama must be H×W, H×W×1, H×W×3 or H×W×4, got shape {array.shape}")
    if array.shape[2] == 1:
        array = np.repeat(array, 3, axis=2)
    return np.ascontiguousarray(array[:, :, :3])


@dataclass
class _Config:
    panoramas: list[Any]
    batch_size: int
    seed: int
    size: tuple[int, int]
    out_size: tuple[int, int]
    ranges: dict[str, Any] | None
    inverse: str
    panoramas_per_batch: int
    cache: int
    supersample: int | tuple[int, int] | str
    newton_steps: int = field(init=False)

    def __post_init__(self) -> None:
        self.newton_steps = PAPER_NEWTON_STEPS if not self.ranges else 8


def plan_batch(config: _Config, index: int) -> tuple[list[CropParams], np.ndarray]:
    """Crop parameters and panorama index of each crop of batch ``index`` (pure function of the seed)."""
    rng = np.random.default_rng([config.seed, index])
    count = len(config.panoramas)
    k = min(config.panoramas_per_batch, count)
    chosen = rng.choice(count, size=k, replace=False)
    which = chosen[rng.integers(0, k, size=config.batch_size)].astype(np.int64)
    params_seed = int(rng.integers(0, 2**63 - 1))
    params = sample_crop_params(config.batch_size, params_seed, size=config.size, **(config.ranges or {}))
    return params, which


class _Producer:
    """Renders batches in the calling process, keeping the last ``cache`` panoramas uploaded."""

    def __init__(self, config: _Config) -> None:
        self.config = config
        self.renderers: dict[int, CropRenderer] = {}

    def renderer(self, index: int) -> CropRenderer:
        found = self.renderers.pop(index, None)
        if found is None:
            while len(self.renderers) >= self.config.cache:
                oldest = next(iter(self.renderers))
                self.renderers.pop(oldest).release()
            found = CropRenderer(
                load_panorama(self.config.panoramas[index]),
                size=self.config.size,
                out_size=self.config.out_size,
                inverse=self.config.inverse,  # type: ignore[arg-type]
                supersample=self.config.supersample,
                newton_steps=self.config.newton_steps,
            )
        self.renderers[index] = found  # most recently used last
        return found

    def batch(self, index: int) -> CropBatch:
        config = self.config
        params, which = plan_batch(config, index)
        w, h = config.out_size
        images = np.empty((config.batch_size, h, w, 3), np.uint8)
        for pano in np.unique(which):
            rows = np.flatnonzero(which == pano)
            images[rows] = self.renderer(int(pano)).render([params[r] for r in rows])
        labels = np.array([(p.k1, p.k2) for p in params], np.float32).reshape(-1, 2)
        return CropBatch(images, labels, params, which, index)

    def close(self) -> None:
        for renderer in self.renderers.values():
            renderer.release()
        self.renderers.clear()


def _worker_main(worker: int, workers: int, config: _Config, out: Any, stop: Any, lp_num_threads: int | None) -> None:
    if lp_num_threads is not None:
        os.environ["LP_NUM_THREADS"] = str(lp_num_threads)
    producer = None
    try:
        producer = _Producer(config)
        index = worker
        while not stop.is_set():
            item = producer.batch(index)
            payload = (index, item.images, item.labels, np.array([tuple(p.as_dict().values()) for p in item.params]), item.panorama)
            while not stop.is_set():
                try:
                    out.put(payload, timeout=0.2)
                    break
                except queue.Full:
                    continue
            index += workers
    except BaseException:  # report to the parent, which raises
        try:
            out.put(("error", worker, traceback.format_exc()), timeout=5)
        except Exception:
            pass
    finally:
        if producer is not None:
            producer.close()
        if stop.is_set():
            out.cancel_join_thread()  # exit without waiting for the parent to read what is still queued


class CropStream:
    """Iterator of :class:`CropBatch` (endless); ``close()`` (or ``with``) stops the workers."""

    def __init__(self, config: _Config, workers: int, prefetch: int, lp_num_threads: int | None) -> None:
        self.config = config
        self.workers = workers
        self._next = 0
        self._closed = False
        self._procs: list[Any] = []
        self._queues: list[Any] = []
        self._producer: _Producer | None = None
        if workers == 0:
            if lp_num_threads is not None:  # takes effect if this process has no GL context yet
                os.environ.setdefault("LP_NUM_THREADS", str(lp_num_threads))
            self._producer = _Producer(config)
            return
        ctx = mp.get_context("spawn")
        self._stop = ctx.Event()
        for worker in range(workers):
            out = ctx.Queue(maxsize=prefetch)
            proc = ctx.Process(
                target=_worker_main,
                args=(worker, workers, config, out, self._stop, lp_num_threads),
                name=f"glradial-crops-{worker}",
                daemon=True,
            )
            proc.start()
            self._procs.append(proc)
            self._queues.append(out)

    def __iter__(self) -> Iterator[CropBatch]:
        return self

    def __next__(self) -> CropBatch:
        if self._closed:
            raise StopIteration
        index = self._next
        self._next += 1
        if self._producer is not None:
            return self._producer.batch(index)
        worker = index % self.workers
        while True:
            try:
                payload = self._queues[worker].get(timeout=_POLL_S)
                break
            except queue.Empty:
                if not self._procs[worker].is_alive():
                    try:  # what it queued before exiting (an error report) is still readable
                        payload = self._queues[worker].get(timeout=_POLL_S)
                        break
                    except queue.Empty:
                        pass
                    self.close()
                    raise RuntimeError(f"crop worker {worker} died (exit code {self._procs[worker].exitcode})") from None
        if payload[0] == "error":
            self.close()
            raise RuntimeError(f"crop worker {payload[1]} failed:\n{payload[2]}")
        got, images, labels, table, which = payload
        if got != index:  # cannot happen: each worker produces its indices in order
            self.close()
            raise RuntimeError(f"crop stream out of order: expected batch {index}, got {got}")
        params = [CropParams(*row) for row in table.tolist()]
        return CropBatch(images, labels, params, which, index)

    def close(self) -> None:
        """Stop and join the workers (terminating stragglers); release GL objects (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self._producer is not None:
            self._producer.close()
            self._producer = None
            return
        # Workers check the stop flag between batches and while waiting on a full queue; they exit
        # without flushing what is queued (never read from a queue here: a worker that exits in the
        # middle of writing a message would leave this process blocked on the pipe).
        self._stop.set()
        deadline = time.monotonic() + _JOIN_S
        for proc in self._procs:
            proc.join(timeout=max(0.0, deadline - time.monotonic()))
        for proc in self._procs:
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5)
        for out in self._queues:
            out.close()
            out.cancel_join_thread()

    def __enter__(self) -> "CropStream":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass


def crop_batches(
    panoramas: Sequence[Any],
    batch_size: int,
    *,
    seed: int,
    size: tuple[int, int] = (1280, 720),
    out_size: tuple[int, int] = (224, 224),
    workers: int = 0,
    ranges: Mapping[str, Any] | None = None,
    inverse: str = "exact",
    panoramas_per_batch: int = 4,
    cache: int = 4,
    prefetch: int = 2,
    supersample: int | tuple[int, int] | str = 1,
    lp_num_threads: int | None = None,
) -> CropStream:
    """Endless seeded stream of :class:`CropBatch` from ``panoramas`` (arrays or image paths).

    ``panoramas``: uint8 equirectangular (2:1) arrays (H×W, H×W×3 or H×W×4; converted to RGB) or
    paths of image files (read in whichever process renders). ``batch_size`` crops per batch,
    spread over ``panoramas_per_batch`` panoramas picked per batch; the ``cache`` most recently used
    panoramas stay uploaded per process. ``size``/``out_size``/``inverse``/``supersample`` as in
    :class:`~glradial.crops.CropRenderer`; ``ranges`` overrides the paper's distribution (keys of
    :func:`~glradial.crops.sample_crop_params`). ``workers`` >= 1 renders in that many spawned
    processes (each makes its own EGL context; ``lp_num_threads`` sets their ``LP_NUM_THREADS``,
    llvmpipe's thread count), each keeping up to ``prefetch`` batches ready. Determinism: see the
    module docstring. Close the stream (``close()`` or ``with``) to stop the workers.
    """
    items = list(panoramas)
    if not items:
        raise ValueError("panoramas must not be empty")
    for name, value, low in (("batch_size", batch_size, 1), ("workers", workers, 0), ("panoramas_per_batch", panoramas_per_batch, 1), ("cache", cache, 1), ("prefetch", prefetch, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if inverse not in ("exact", "drap"):
        raise ValueError(f"inverse must be 'exact' or 'drap', got {inverse!r}")
    if lp_num_threads is not None and (not isinstance(lp_num_threads, int) or lp_num_threads < 0):
        raise ValueError(f"lp_num_threads must be a non-negative integer, got {lp_num_threads!r}")
    items = [os.path.abspath(item) if isinstance(item, (str, os.PathLike)) else load_panorama(item) for item in items]
    config = _Config(
        panoramas=items,
        batch_size=int(batch_size),
        seed=int(seed),
        size=frame_size(size),
        out_size=frame_size(out_size),
        ranges=dict(ranges) if ranges else None,
        inverse=inverse,
        panoramas_per_batch=int(panoramas_per_batch),
        cache=int(cache),
        supersample=supersample,
    )
    # Validate the ranges and sizes here, not in a worker.
    plan_batch(config, 0)
    return CropStream(config, int(workers), int(prefetch), lp_num_threads)
