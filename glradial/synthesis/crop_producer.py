"""The crop producer: an endless, seeded, torch-free stream of distorted crops, rendered in this
process or in worker processes (the training data of ``net/``, and of anyone else's trainer).

Convention:

* ``crop_batches(panoramas, batch_size, seed=S, ...)`` returns a :class:`CropProducer` that yields
  :class:`CropBatch` values in order ``index = 0, 1, 2, ...``. Batch ``i`` is a pure function of
  ``(S, i)`` and the arguments (:func:`plan_batch`): its random numbers come from
  ``numpy.random.default_rng([S, i])``, which picks ``panoramas_per_batch`` panoramas, assigns each
  crop to one of them and draws the crop parameters (:func:`glradial.synthesis.crops.sample_crop_params`, the
  paper's distribution unless ``ranges`` is given). With ``paired=True`` batch ``i`` is instead
  ``batch_size / 2`` pairs ``(2j, 2j + 1)`` of one panorama that share pan, tilt, roll and field of
  view and differ only in the lens (:func:`plan_pairs`, random numbers from
  ``default_rng([S, i, 0xA1])``).
* With ``workers = n >= 1``, batch ``i`` is rendered by worker ``i % n`` and the stream reads the
  workers' queues in turn, so the sequence of batches is identical for any number of workers
  (and to ``workers=0``, up to the renderer being the same driver). Rendering goes through
  :class:`glradial.synthesis.crops.PanoramaRenderers`.
* ``images``: uint8 ``N × h × w × 3`` RGB (``out_size = (w, h)``); ``labels``: float32 ``N × 2`` =
  ``(k1, k2)`` of the ``size`` frame (16:9 in the paper); ``params``: the full
  :class:`~glradial.synthesis.crops.CropParams` of each crop; ``panorama``: int64 ``N``, the index into
  ``panoramas`` of each crop's source.
* A worker that fails raises ``RuntimeError`` with its traceback in the reader; one that dies (killed,
  e.g. by the out-of-memory killer, even halfway through sending a batch) raises ``RuntimeError``
  naming its exit code instead of leaving the reader waiting; one that dies before running any
  glradial code (typically: the main script, imported again by the spawned worker, starts a producer
  itself because it lacks an ``if __name__ == "__main__":`` guard) raises ``RuntimeError`` saying so.
  Workers exit when the reading process is gone.
* Workers never receive panorama arrays through their start arguments (a pickled array larger than
  the 64 KiB pipe buffer blocks the parent forever when the worker dies while starting): each array
  is saved once to a ``.npy`` file in a private temporary folder, which the workers map
  (``mmap_mode="r"``); the folder is removed when the producer is closed or garbage-collected.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import queue
import shutil
import tempfile
import time
import traceback
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Mapping, NamedTuple, Sequence

import numpy as np

from ..errors import check_flag
from ..lens.lens import frame_size
from ..lens.lensfuncs import LENS_NEWTON_STEPS
from ..lens.metrics import PAPER_SIZE
from ..lens.options import INVERSES
from ..media.atomic import atomic_path
from .crops import CropParams, PanoramaRenderers, crop_labels, load_panorama, sample_crop_params

#: Newton steps of the exact inverse when crops come from the paper's distribution: 3 steps from the
#: Drap-Lefevre seed reach 1e-9 lens units on every such lens (see tests/synthesis/test_crop_producer.py); any
#: other ``ranges``, and paired batches (whose shipped training runs used it), use the full default
#: of common.glsl.
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
    paired: bool = False

    @property
    def newton_steps(self) -> int:
        """Newton steps of the exact inverse: :data:`PAPER_NEWTON_STEPS` for unpaired crops of the paper's distribution."""
        return PAPER_NEWTON_STEPS if not self.ranges and not self.paired else LENS_NEWTON_STEPS


def plan_batch(config: _Config, index: int) -> tuple[list[CropParams], np.ndarray]:
    """Crop parameters and panorama index of each crop of batch ``index`` (pure function of the seed)."""
    if config.paired:
        return plan_pairs(config, index)
    rng = np.random.default_rng([config.seed, index])
    count = len(config.panoramas)
    k = min(config.panoramas_per_batch, count)
    chosen = rng.choice(count, size=k, replace=False)
    which = chosen[rng.integers(0, k, size=config.batch_size)].astype(np.int64)
    params_seed = int(rng.integers(0, 2**63 - 1))
    params = sample_crop_params(config.batch_size, params_seed, size=config.size, **(config.ranges or {}))
    return params, which


def plan_pairs(config: _Config, index: int) -> tuple[list[CropParams], np.ndarray]:
    """Batch ``index`` of a paired stream: one panorama, ``batch_size / 2`` views, each drawn twice
    with two independent lenses of the distribution (crops ``2j`` and ``2j + 1``)."""
    rng = np.random.default_rng([config.seed, index, 0xA1])
    panorama = int(rng.integers(len(config.panoramas)))
    half = config.batch_size // 2
    views = sample_crop_params(half, int(rng.integers(2**62)), size=config.size, **(config.ranges or {}))
    lenses = sample_crop_params(half, int(rng.integers(2**62)), size=config.size, **(config.ranges or {}))
    params: list[CropParams] = []
    for a, b in zip(views, lenses):
        params += [a, CropParams(a.pan, a.tilt, a.roll, a.hfov, b.k1, b.k2)]
    return params, np.full(len(params), panorama, np.int64)


class _Renderer:
    """Renders batches in the calling process, keeping the last ``cache`` panoramas uploaded."""

    def __init__(self, config: _Config) -> None:
        self.config = config
        self.renderers = PanoramaRenderers(
            config.panoramas, cache=config.cache, size=config.size, out_size=config.out_size,
            inverse=config.inverse, supersample=config.supersample, newton_steps=config.newton_steps,
        )

    def batch(self, index: int) -> CropBatch:
        params, which = plan_batch(self.config, index)
        images = self.renderers.render(params, which)
        return CropBatch(images, crop_labels(params, np.float32), params, which, index)

    def close(self) -> None:
        self.renderers.close()


def _spill_panoramas(panoramas: Sequence[Any], folder: Path) -> list[Any]:
    """``panoramas`` with every array replaced by the path of a ``.npy`` copy in ``folder`` (written
    atomically); paths are kept as they are."""
    spilled: list[Any] = []
    for i, item in enumerate(panoramas):
        if isinstance(item, np.ndarray):
            path = folder / f"panorama-{i:06d}.npy"
            with atomic_path(path) as tmp:
                np.save(tmp, item)
            item = str(path)
        spilled.append(item)
    return spilled


def _worker_main(worker: int, workers: int, config: _Config, out: Any, stop: Any, lp_num_threads: int | None,
                 parent: int, started: Any) -> None:
    started[worker] = 1  # glradial code runs: the worker got past importing the main module
    if lp_num_threads is not None:
        os.environ["LP_NUM_THREADS"] = str(lp_num_threads)
    renderer = None
    try:
        renderer = _Renderer(config)
        index = worker
        while not stop.is_set() and os.getppid() == parent:
            item = renderer.batch(index)
            payload = (index, item.images, item.labels, np.array([tuple(p.as_dict().values()) for p in item.params]), item.panorama)
            while not stop.is_set():
                try:
                    out.put(payload, timeout=0.2)
                    break
                except queue.Full:
                    if os.getppid() != parent:  # the reader is gone: its queue would stay full forever
                        return
            index += workers
    except KeyboardInterrupt:
        pass
    except BaseException:  # report to the reader, which raises
        try:
            out.put(("error", worker, traceback.format_exc()), timeout=5)
        except Exception:
            pass
    finally:
        if renderer is not None:
            renderer.close()
        if stop.is_set() or os.getppid() != parent:
            out.cancel_join_thread()  # exit without flushing to a reader that stopped or is gone


class CropProducer:
    """Iterator of :class:`CropBatch` (endless); ``close()`` (or ``with``) stops the workers.

    Made by :func:`crop_batches`. :meth:`get` is ``next()`` with a time limit; :attr:`wait_s` counts
    the seconds spent waiting for workers.
    """

    def __init__(self, config: _Config, workers: int, prefetch: int, lp_num_threads: int | None) -> None:
        self.config = config
        self.workers = workers
        self.wait_s = 0.0
        self._next = 0
        self._closed = False
        self._procs: list[Any] = []
        self._queues: list[Any] = []
        self._renderer: _Renderer | None = None
        self._cleanup: weakref.finalize | None = None
        if workers == 0:
            if lp_num_threads is not None:  # takes effect if this process has no GL context yet
                os.environ.setdefault("LP_NUM_THREADS", str(lp_num_threads))
            self._renderer = _Renderer(config)
            return
        ctx = mp.get_context("spawn")
        self._stop = ctx.Event()
        self._started = ctx.Array("b", workers, lock=False)
        try:
            folder = Path(tempfile.mkdtemp(prefix="glradial-crops-"))
            self._cleanup = weakref.finalize(self, shutil.rmtree, folder, ignore_errors=True)
            worker_config = dataclasses.replace(config, panoramas=_spill_panoramas(config.panoramas, folder))
            for worker in range(workers):
                out = ctx.Queue(maxsize=prefetch)
                proc = ctx.Process(
                    target=_worker_main,
                    args=(worker, workers, worker_config, out, self._stop, lp_num_threads, os.getpid(), self._started),
                    name=f"glradial-crops-{worker}",
                    daemon=True,
                )
                proc.start()
                # The worker has its own copy of the queue's write end now; without ours, its death
                # closes the pipe, so a batch cut off halfway ends in end-of-file, not in a read that
                # waits forever.
                out._writer.close()
                self._procs.append(proc)
                self._queues.append(out)
        except BaseException:
            self.close()
            raise

    def __iter__(self) -> Iterator[CropBatch]:
        return self

    def __next__(self) -> CropBatch:
        if self._closed:
            raise StopIteration
        return self.get()

    def get(self, timeout: float | None = None) -> CropBatch:
        """The next batch, waiting at most ``timeout`` seconds for a worker (``None``: no limit;
        ``TimeoutError`` past it)."""
        if self._closed:
            raise RuntimeError("the crop producer is closed")
        index = self._next
        if self._renderer is not None:
            self._next += 1
            return self._renderer.batch(index)
        worker = index % self.workers
        t0 = time.monotonic()
        while True:
            try:
                payload = self._queues[worker].get(timeout=_POLL_S)
                break
            except (EOFError, OSError):  # the pipe closed, maybe in the middle of a batch
                raise self._died(worker) from None
            except queue.Empty:
                if not self._procs[worker].is_alive():
                    try:  # what it queued before exiting (an error report) is still readable
                        payload = self._queues[worker].get(timeout=_POLL_S)
                        break
                    except queue.Empty:
                        pass
                    except (EOFError, OSError):
                        pass
                    raise self._died(worker) from None
                if timeout is not None and time.monotonic() - t0 > timeout:
                    raise TimeoutError(f"no crops from crop worker {worker} in {timeout:.0f} s") from None
        self.wait_s += time.monotonic() - t0
        if payload[0] == "error":
            self.close()
            raise RuntimeError(f"crop worker {payload[1]} failed:\n{payload[2]}")
        got, images, labels, table, which = payload
        if got != index:  # cannot happen: each worker produces its indices in order
            self.close()
            raise RuntimeError(f"crop producer out of order: expected batch {index}, got {got}")
        self._next += 1
        params = [CropParams(*row) for row in table.tolist()]
        return CropBatch(images, labels, params, which, index)

    def _died(self, worker: int) -> RuntimeError:
        proc = self._procs[worker]
        proc.join(timeout=10)
        code = proc.exitcode
        self.close()
        if not self._started[worker]:
            return RuntimeError(
                f"crop worker {worker} died while starting (exit code {code}), before running any glradial code: "
                f"the worker imports the main module again, so a script that makes a crop producer with workers >= 1 "
                f"must do it under 'if __name__ == \"__main__\":' (see 'Safe importing of main module' in the "
                f"multiprocessing documentation); the worker's own error is on standard error"
            )
        hint = " (killed: look for the out-of-memory killer; every worker holds its panoramas)" if code == -9 else ""
        return RuntimeError(f"crop worker {worker} died (exit code {code}){hint}")

    def close(self) -> None:
        """Stop and join the workers (terminating stragglers); release GL objects (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
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
        if self._cleanup is not None:  # the workers are gone: nothing maps the panorama files now
            self._cleanup()

    def __enter__(self) -> "CropProducer":
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
    size: tuple[int, int] = PAPER_SIZE,
    out_size: tuple[int, int] = (224, 224),
    workers: int = 0,
    ranges: Mapping[str, Any] | None = None,
    inverse: str = "exact",
    panoramas_per_batch: int = 4,
    cache: int = 4,
    prefetch: int = 2,
    supersample: int | tuple[int, int] | str = 1,
    lp_num_threads: int | None = None,
    paired: bool = False,
) -> CropProducer:
    """Endless seeded stream of :class:`CropBatch` from ``panoramas`` (arrays or image paths).

    ``panoramas``: uint8 equirectangular (2:1) arrays (H×W, H×W×3 or H×W×4; converted to RGB) or
    paths of image files or ``.npy`` arrays (read in whichever process renders). ``batch_size``
    crops per batch, spread over ``panoramas_per_batch`` panoramas picked per batch; the ``cache``
    most recently used panoramas stay uploaded per process. ``paired``: batches of lens pairs (see
    the module docstring; ``batch_size`` even). ``size``/``out_size``/``inverse``/``supersample``
    as in :class:`~glradial.synthesis.crops.CropRenderer`; ``ranges`` overrides the paper's distribution
    (keys of :func:`~glradial.synthesis.crops.sample_crop_params`). ``workers`` >= 1 renders in that many
    spawned processes (each makes its own EGL context; ``lp_num_threads`` sets their
    ``LP_NUM_THREADS``, llvmpipe's thread count), each keeping up to ``prefetch`` batches ready.
    Determinism: see the module docstring. Close the stream (``close()`` or ``with``) to stop the
    workers.

    Args:
        panoramas: the panoramas (arrays or paths), at least one.
        batch_size: crops per batch (>= 1; even with ``paired``).
        seed: the stream's seed (>= 0); the same seed gives the same batches.
        size, out_size, inverse, supersample: as :class:`glradial.CropRenderer` (pixels).
        workers: rendering processes (0: in this process).
        ranges: overrides of the crop distribution (:func:`glradial.sample_crop_params` keys).
        panoramas_per_batch, cache, prefetch: as above (counts, >= 1).
        lp_num_threads: llvmpipe threads per worker (``None``: Mesa's default).
        paired: batches of lens pairs.

    Returns:
        A :class:`glradial.synthesis.crop_producer.CropProducer`: an endless iterator of
        ``CropBatch(images N×h×w×3 uint8, labels N×2 float32 (k1, k2), params, panorama, index)``.

    Raises:
        ValueError: an empty ``panoramas`` or a count, seed, inverse or range out of bounds.
        TypeError: ``paired`` is not a bool.

    Example:
        >>> import numpy as np, glradial
        >>> panorama = np.random.default_rng(0).integers(0, 255, (64, 128, 3), np.uint8)
        >>> with glradial.crop_batches([panorama], 2, seed=1, size=(64, 36), out_size=(32, 32)) as stream:
        ...     batch = next(stream)
        >>> batch.images.shape, batch.labels.shape
        ((2, 32, 32, 3), (2, 2))
    """
    items = list(panoramas)
    if not items:
        raise ValueError("panoramas must not be empty")
    for name, value, low in (("batch_size", batch_size, 1), ("workers", workers, 0), ("panoramas_per_batch", panoramas_per_batch, 1), ("cache", cache, 1), ("prefetch", prefetch, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if inverse not in INVERSES:
        raise ValueError(f"inverse must be 'exact' or 'drap', got {inverse!r}")
    if lp_num_threads is not None and (not isinstance(lp_num_threads, int) or lp_num_threads < 0):
        raise ValueError(f"lp_num_threads must be a non-negative integer, got {lp_num_threads!r}")
    check_flag("paired", paired)
    if paired and batch_size % 2:
        raise ValueError(f"batch_size must be even for pairs, got {batch_size}")
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
        paired=bool(paired),
    )
    # Validate the ranges and sizes here, not in a worker.
    plan_batch(config, 0)
    return CropProducer(config, int(workers), int(prefetch), lp_num_threads)
