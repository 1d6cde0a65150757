"""Training and test data for the estimator: panoramas, a background crop producer, a reuse pool.

Convention: crops are uint8 RGB ``N x h x w x 3`` at the network input size ``out_size = (w, h)``,
rendered by :class:`glradial.synthesis.crops.CropRenderer` with the frame geometry ``size`` (1280 x 720, 16:9)
that the labels refer to; labels are float32 ``N x 2`` = ``(k1, k2)`` in width-normalised lens
units, drawn from the paper's distribution (:func:`glradial.synthesis.crops.sample_crop_params`).

Panoramas: procedural stadiums rendered once per seed and size and cached as ``.npy`` under a cache
folder (:func:`glradial.synthesis.stadium.stadium_panorama_cached`; ``data_cache/`` by default, git-ignored);
train / val / test seeds follow :func:`glradial.synthesis.stadium_style.split_seeds`. ``synthetic_panorama``
is a fast stand-in (random lines and blobs) for tests.

Throughput on a CPU-only machine: rendering a crop (llvmpipe) costs about as much as a training
step on it, so the trainer keeps a pool of recent crops and, each step, pulls a fixed number of
fresh crops from a producer process (glradial's crop producer, :mod:`glradial.synthesis.crop_producer`,
which renders ahead, in parallel) and samples its batch from
the pool. The number of fresh crops per step is fixed, so a run is deterministic per seed no matter
how fast the producer is. Several producers (:class:`CropProducers`) each render their own shard
of the panoramas (:func:`shard_source`), so the panorama memory does not grow with their number.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from glradial.lens.metrics import PAPER_SIZE
from glradial.synthesis.crop_producer import crop_batches
from glradial.synthesis.crops import load_panorama
from glradial.synthesis.stadium import stadium_cache_path, stadium_panorama_cached
from glradial.synthesis.stadium_style import split_seeds

# --- panoramas ------------------------------------------------------------------------------------


def synthetic_panorama(seed: int, size: tuple[int, int] = (512, 256)) -> np.ndarray:
    """A fast procedural stand-in panorama (green ground, white lines, coloured blocks), uint8 RGB."""
    import cv2

    width, height = size
    rng = np.random.default_rng(seed)
    pano = np.zeros((height, width, 3), np.uint8)
    pano[: height // 2] = rng.integers(60, 200, 3)
    pano[height // 2 :] = (40, int(rng.integers(100, 160)), 40)
    for _ in range(40):
        x0, y0 = int(rng.integers(0, width)), int(rng.integers(0, height))
        x1, y1 = int(rng.integers(0, width)), int(rng.integers(0, height))
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        if rng.random() < 0.5:
            cv2.line(pano, (x0, y0), (x1, y1), (255, 255, 255), max(1, width // 512))
        else:
            cv2.rectangle(pano, (x0, y0), (x0 + width // 40, y0 + height // 40), colour, -1)
    return pano


@dataclass
class PanoramaSource:
    """Where a producer gets panoramas: ``kind`` "stadium" (seeds) or "synthetic" (seeds) or "files"."""

    kind: str
    seeds: Sequence[int] = ()
    size: tuple[int, int] = (2048, 1024)
    cache_dir: str | None = "data_cache"
    files: Sequence[str] = ()

    def _items(self) -> list:
        """The seeds, or the files for ``kind`` "files": one per panorama."""
        return list(self.files if self.kind == "files" else self.seeds)

    def __len__(self) -> int:
        return len(self._items())

    def load(self) -> list[np.ndarray]:
        """The panoramas as uint8 RGB arrays (stadiums rendered into the cache when missing)."""
        if self.kind == "stadium":
            return [stadium_panorama_cached(int(s), tuple(self.size), self.cache_dir) for s in self.seeds]
        if self.kind == "synthetic":
            return [synthetic_panorama(int(s), tuple(self.size)) for s in self.seeds]
        if self.kind == "files":
            return [load_panorama(str(f)) for f in self.files]
        raise ValueError(f"panorama source kind must be 'stadium', 'synthetic' or 'files', got {self.kind!r}")

    def inputs(self) -> list:
        """What a crop producer reads (:func:`glradial.synthesis.crop_producer.crop_batches`), loaded in its
        worker process: paths of the cached stadiums (rendered here first when missing) or of the
        files; arrays for synthetic panoramas and uncached stadiums."""
        if self.kind == "stadium" and self.cache_dir is not None:
            paths = []
            for seed in self.seeds:
                path = stadium_cache_path(int(seed), tuple(self.size), self.cache_dir)
                if not path.exists():
                    stadium_panorama_cached(int(seed), tuple(self.size), self.cache_dir)
                paths.append(str(path))
            return paths
        if self.kind == "files":
            return [str(f) for f in self.files]
        return self.load()


# --- crop producers -------------------------------------------------------------------------------


class _ChunkReader:
    """``take(n)``: exactly the next ``n`` crops of a stream that arrives in chunks from ``_fetch``."""

    _images: np.ndarray | None = None
    _labels: np.ndarray | None = None
    _pos = 0

    def _fetch(self, timeout: float) -> tuple[np.ndarray, np.ndarray]:
        """The next chunk ``(images, labels)``, waiting at most ``timeout`` seconds."""
        raise NotImplementedError

    def take(self, n: int, timeout: float = 600.0) -> tuple[np.ndarray, np.ndarray]:
        images, labels = [], []
        while n > 0:
            if self._images is None or self._pos >= len(self._images):
                self._images, self._labels = self._fetch(timeout)
                self._pos = 0
            k = min(n, len(self._images) - self._pos)
            images.append(self._images[self._pos : self._pos + k])
            labels.append(self._labels[self._pos : self._pos + k])
            self._pos += k
            n -= k
        return np.concatenate(images), np.concatenate(labels)


class CropProducer(_ChunkReader):
    """One background process rendering ``source``'s panoramas in chunks of ``chunk`` crops: the
    glradial crop producer (:func:`glradial.synthesis.crop_producer.crop_batches`, one worker, every panorama
    kept uploaded, ``threads`` llvmpipe threads, up to ``prefetch`` chunks ahead; ``paired``: lens
    pairs).

    ``take(n)`` returns exactly the next ``n`` crops of the stream (blocking), whatever the chunking.
    If the process dies (an exception, or killed, e.g. by the kernel's out-of-memory killer: it
    holds every panorama of its shard, once as an array and once as a texture), ``take`` raises
    ``RuntimeError`` naming its exit code, even when it dies halfway through sending a chunk.
    """

    def __init__(self, source: PanoramaSource, *, seed: int, out_size: tuple[int, int], chunk: int = 64,
                 ranges: dict | None = None, threads: int = 1, prefetch: int = 8, paired: bool = False):
        self.stream = crop_batches(source.inputs(), chunk, seed=seed, size=PAPER_SIZE, out_size=tuple(out_size),
                                   workers=1, ranges=ranges, cache=max(1, len(source)), prefetch=prefetch,
                                   lp_num_threads=threads, paired=paired)

    @property
    def wait_s(self) -> float:
        """Seconds spent waiting for crops."""
        return self.stream.wait_s

    def _fetch(self, timeout: float) -> tuple[np.ndarray, np.ndarray]:
        batch = self.stream.get(timeout)
        return batch.images, batch.labels

    def close(self) -> None:
        self.stream.close()

    def __enter__(self) -> "CropProducer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def shard_source(source: PanoramaSource, index: int, count: int) -> PanoramaSource:
    """Shard ``index`` of ``count`` of ``source``'s panoramas: every ``count``-th one from ``index``.

    The shards of ``0 .. count - 1`` partition the panoramas; their sizes differ by at most one.
    ``count`` may not exceed the number of panoramas (a shard would be empty).
    """
    items = source._items()
    if not 0 <= index < count:
        raise ValueError(f"shard index {index} outside 0 .. {count - 1}")
    if count > len(items):
        raise ValueError(f"cannot split {len(items)} panoramas into {count} shards (one per crop producer); "
                         "use fewer producers or ranks, or more panoramas")
    if source.kind == "files":
        return replace(source, files=items[index::count])
    return replace(source, seeds=items[index::count])


class CropProducers(_ChunkReader):
    """Several :class:`CropProducer` processes behind one ``take``, each rendering its own shard.

    ``producers[i]`` must stream chunks of ``chunk`` crops and hold ``weights[i]`` panoramas. Whole
    chunks are taken from the producers in smooth weighted round-robin order (each producer in
    proportion to its weight, interleaved), so every panorama keeps the same share of the crops
    as with one producer holding them all, and crop pairs (which never straddle a chunk) stay
    together. ``take(n)`` returns exactly the next ``n`` crops of that interleaved stream.
    """

    def __init__(self, producers: Sequence[CropProducer], weights: Sequence[int], chunk: int):
        if len(producers) != len(weights) or not producers or min(weights) <= 0:
            raise ValueError("one positive weight per producer, at least one producer")
        self.producers = list(producers)
        self.weights = [int(w) for w in weights]
        self._credit = [0] * len(self.weights)
        self._chunk = chunk

    @property
    def wait_s(self) -> float:
        """Seconds spent waiting for crops, over all producers (they are read one at a time)."""
        return sum(p.wait_s for p in self.producers)

    def _next_producer(self) -> CropProducer:
        total = sum(self.weights)
        for i, w in enumerate(self.weights):
            self._credit[i] += w
        best = max(range(len(self._credit)), key=self._credit.__getitem__)
        self._credit[best] -= total
        return self.producers[best]

    def _fetch(self, timeout: float) -> tuple[np.ndarray, np.ndarray]:
        return self._next_producer().take(self._chunk, timeout=timeout)

    def close(self) -> None:
        for p in self.producers:
            p.close()

    def __enter__(self) -> "CropProducers":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class CropPool:
    """Ring buffer of the most recent ``capacity`` crops; batches are sampled uniformly from it."""

    def __init__(self, capacity: int, out_size: tuple[int, int]):
        w, h = out_size
        self.images = np.zeros((capacity, h, w, 3), np.uint8)
        self.labels = np.zeros((capacity, 2), np.float32)
        self.capacity = capacity
        self.count = 0
        self._next = 0

    def add(self, images: np.ndarray, labels: np.ndarray) -> None:
        for img, lab in zip(images, labels):
            self.images[self._next] = img
            self.labels[self._next] = lab
            self._next = (self._next + 1) % self.capacity
            self.count = min(self.count + 1, self.capacity)

    def sample(self, n: int, rng: np.random.Generator, paired: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``n`` crops drawn uniformly; ``paired``: ``n / 2`` pairs ``(2i, 2i + 1)`` kept adjacent."""
        if self.count == 0:
            raise RuntimeError("the crop pool is empty")
        if paired:
            first = 2 * rng.integers(0, self.count // 2, n // 2)
            idx = np.stack([first, first + 1], axis=1).reshape(-1)
        else:
            idx = rng.integers(0, self.count, n)
        return self.images[idx], self.labels[idx]


def render_test_set(
    source: PanoramaSource, n: int, seed: int, out_size: tuple[int, int], *, ranges: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, list]:
    """``n`` crops (no augmentation) spread evenly over ``source``'s panoramas, rendered in this
    process by :func:`glradial.synthesis.crops.render_crop_set`. Returns ``(images, labels float32, params)``;
    deterministic per ``seed``."""
    from glradial.synthesis.crops import crop_labels, render_crop_set

    images, params = render_crop_set(source.load(), n, seed, size=PAPER_SIZE, out_size=out_size, ranges=ranges)
    return images, crop_labels(params, np.float32), params


def main(argv: list[str] | None = None) -> int:
    """``python -m net.data --split train --n 32 --size 4096 2048``: render + cache stadium panoramas."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m net.data", description=main.__doc__)
    parser.add_argument("--split", action="append", required=True, help="train / val / test (repeatable)")
    parser.add_argument("--n", type=int, action="append", required=True, help="panoramas per --split")
    parser.add_argument("--size", type=int, nargs=2, default=(4096, 2048))
    parser.add_argument("--cache-dir", default="data_cache")
    args = parser.parse_args(argv)
    for split, n in zip(args.split, args.n):
        for seed in split_seeds(split, n):
            if stadium_cache_path(seed, tuple(args.size), args.cache_dir).exists():
                continue  # cached already: not read back
            t0 = time.monotonic()
            stadium_panorama_cached(seed, tuple(args.size), args.cache_dir)
            print(f"{split} seed {seed}: {time.monotonic() - t0:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
