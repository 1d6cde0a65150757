"""Estimate a frame's radial lens ``(k1, k2)`` with the bundled CNN (ONNX, onnxruntime; no torch).

Convention:
    Input frames: NumPy arrays ``H x W x 3`` RGB (``H x W`` grayscale and ``H x W x 4`` RGBA are
    accepted: gray is repeated, alpha dropped), dtype uint8 (0..255) or float32/float64 in [0, 1].
    Any size and aspect ratio: the network sees the frame's centred 16:9 view (:func:`view_box`: the
    full width of a taller frame, the full height of a wider one; never squashed), resized with area
    interpolation (``cv2.INTER_AREA``) to its input (``NetLinesEstimator.input_size``, ``(W, H)``, e.g.
    384 x 216), as in training (crops rendered as 1280 x 720 frames). Its answer refers to that view
    and is converted to the frame's own width-normalised lens (:func:`view_to_frame`): the same
    ``(k1, k2)`` for a view as wide as the frame, ``Lens.rescale(W_view / W)`` for a narrower one.
    The line fit works in the frame's own geometry. Crop letterboxes before estimating.
    Output: :class:`glradial.LensEstimate`, a :class:`glradial.Lens` ``(k1, k2)`` in width-normalised
    lens units (image width = 1, origin at the frame centre): forward model
    ``p_d = p_u (1 + k1 r^2 + k2 r^4)``, with ``method`` ("net" or "lines"), ``uncertainty_px``
    (a 90 % bound on the maximum displacement error, px at 1920), ``chains``, ``doubtful`` and
    ``reason`` (:mod:`glradial.estimation.trust`).

Methods: ``"net"`` is the CNN alone; ``"lines"`` fits the lens that straightens the frame's pitch
lines and straight edges (:mod:`glradial.estimation.lines`, :mod:`glradial.estimation.line_fit`; the CNN is its prior);
``"auto"`` (default) takes the line fit when its bound beats the CNN's. Frames without usable lines
get the CNN's answer, labelled ``method="net"`` and doubtful (docs/LINES.md).

The ONNX graph takes uint8 ``N x H x W x 3`` RGB and does the rest of the preprocessing itself
(``/ 255``, mean/std normalisation, NHWC -> NCHW; see the model's metadata and docs/MODEL.md).

Mirror averaging (default): a radial lens about the frame centre is unchanged by a left-right
mirror, so the estimate is the mean of the network's outputs for the frame and for its mirror
image (one batch of 2N; training saw mirrored crops with the same labels). What it gains on the
held-out test crops is measured in docs/MODEL.md.
"""

from __future__ import annotations

import json
import os
import threading
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import check_count, check_flag
from ..lens.lens import Lens
from ..lens.options import Method
from ..media.frames import to_rgb8
from ..threads import thread_budget
from .lens_estimate import LensEstimate, check_method, frame_evidence, judge
from .model_check import ModelLoadError, check_checksum, check_model
from .trust import FrameEvidence, view_features

#: File name of the bundled model inside the ``glradial.models`` package.
DEFAULT_MODEL_NAME = "glradial_k1k2.onnx"
#: Aspect ratio (W / H) of the frames the model was trained on.
TRAINED_ASPECT = 16.0 / 9.0
#: Relative aspect deviation within which a frame is taken whole as the 16:9 view.
ASPECT_TOLERANCE = 0.01


def view_box(size: tuple[int, int]) -> tuple[int, int, int, int]:
    """``(x0, y0, w, h)`` of the centred 16:9 view of a ``(W, H)`` frame that the network sees: the
    whole frame when within :data:`ASPECT_TOLERANCE` of 16:9, the full width of a taller frame, the
    full height of a wider one, with equal margins (so its centre is the frame's; 16:9 within a
    pixel)."""
    width, height = size
    if abs(width / height / TRAINED_ASPECT - 1.0) <= ASPECT_TOLERANCE:
        return 0, 0, width, height
    if width / height > TRAINED_ASPECT:  # equal margins: the view's centre is the frame's centre
        margin = int(round((width - height * TRAINED_ASPECT) / 2))
        return margin, 0, width - 2 * margin, height
    margin = int(round((height - width / TRAINED_ASPECT) / 2))
    return 0, margin, width, height - 2 * margin


def view_to_frame(k: tuple[float, float], size: tuple[int, int]) -> tuple[float, float]:
    """The network's ``(k1, k2)`` of the 16:9 view (:func:`view_box`) -> the width-normalised lens
    of the ``(W, H)`` frame. A radial lens about the centre is the same map in pixels; lens units
    are pixels / width, so a view of width ``w`` has ``r_frame = (w / W) r_view`` and
    ``k_frame = Lens(k).rescale(w / W)`` (``k1 (W / w)²``, ``k2 (W / w)⁴``); same width, same k."""
    w = view_box(size)[2]
    if w == size[0]:
        return float(k[0]), float(k[1])
    lens = Lens(float(k[0]), float(k[1])).rescale(w / size[0])
    return lens.k1, lens.k2


def square_pixels(frame: np.ndarray, pixel_aspect: float) -> np.ndarray:
    """A frame stored with pixels of aspect ``pixel_aspect = fy / fx`` resized to square pixels at
    the same width (height ``H / pixel_aspect``; bicubic). Its width-normalised lens is the stored
    frame's ``(k1, k2)`` with ``pixel_aspect = 1``: lens units are widths, and the width is kept."""
    import cv2

    height = max(2, int(round(frame.shape[0] / pixel_aspect)))
    if height == frame.shape[0]:
        return frame
    return np.ascontiguousarray(cv2.resize(frame, (frame.shape[1], height), interpolation=cv2.INTER_CUBIC))


def default_model_path() -> Path:
    """Path of the bundled model (``glradial/models/glradial_k1k2.onnx``), whether or not it exists."""
    from importlib import resources

    return Path(str(resources.files("glradial.models").joinpath(DEFAULT_MODEL_NAME)))


def _as_frame(frame: Any, index: int | None = None) -> np.ndarray:
    """A frame for the estimator (:func:`glradial.media.frames.to_rgb8`; floats outside [0, 1] refused,
    at least 2×2 pixels)."""
    where = "frame" if index is None else f"frames[{index}]"
    rgb = to_rgb8(frame, where, clip=False)
    if rgb.shape[0] < 2 or rgb.shape[1] < 2:
        raise ValueError(f"{where} must be at least 2×2 pixels, got shape {np.shape(frame)}")
    return rgb


class NetLinesEstimator:
    """An onnxruntime session of the distortion model, created once and reused.

    ``model_path``: an ``.onnx`` file (default: the bundled :func:`default_model_path`).
    ``threads``: onnxruntime intra-op threads (default: the process's thread budget, :mod:`glradial.threads`,
    else onnxruntime's choice, all cores).
    ``mirror_average``: average the outputs for each frame and its left-right mirror (default; see
    the module docstring); ``False`` runs the network once per frame.
    Raises ``FileNotFoundError`` for a missing file and :class:`ModelLoadError` for a file that is
    not a usable glradial model (see :mod:`glradial.estimation.model_check`: structure, checksum, probe). Thread-safe: onnxruntime sessions may be run concurrently.
    """

    def __init__(
        self, model_path: str | os.PathLike | None = None, threads: int | None = None, mirror_average: bool = True
    ) -> None:
        import onnxruntime as ort

        path = Path(model_path) if model_path is not None else default_model_path()
        check_count("threads", threads, optional=True)
        self.mirror_average = check_flag("mirror_average", mirror_average)
        if not path.is_file():
            hint = " (the bundled model is missing: reinstall glradial or pass model_path)" if model_path is None else ""
            raise FileNotFoundError(f"model file not found: {path}{hint}")
        options = ort.SessionOptions()
        threads = thread_budget() if threads is None else threads  # a job's worker: its share of the cores
        if threads is not None:
            options.intra_op_num_threads = threads
            options.inter_op_num_threads = 1
        options.log_severity_level = 3
        # worker threads sleep between runs instead of busy-waiting: a spinning pool takes a core
        # from the decoder, the line fit and other processes (video pass 1 calls the network between
        # frames), and on a busy 2-core machine it doubled a call's time (docs/BENCH.md)
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        check_checksum(path)
        try:
            self._session = ort.InferenceSession(str(path), sess_options=options, providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises its own exception types
            raise ModelLoadError(f"cannot load ONNX model {path}: {' '.join(str(err).split())[:300]}") from None
        self.model_path = path
        self.threads = threads
        meta = self._session.get_modelmeta().custom_metadata_map
        self.metadata: dict[str, str] = dict(meta)
        info = check_model(self._session, path)  # names, ranks, dtypes, N×2 output, input size, probe
        self.input_size: tuple[int, int] = info.input_size
        self._input_name = info.input_name
        self._output_names = [o.name for o in self._session.get_outputs()]

    @property
    def metrics(self) -> dict:
        """Evaluation metrics stored in the model's metadata (empty if none)."""
        text = self.metadata.get("metrics")
        return json.loads(text) if text else {}

    def preprocess(self, frame: np.ndarray) -> np.ndarray:
        """A frame -> its centred 16:9 view (:func:`view_box`) as uint8 ``H x W x 3`` RGB at
        :attr:`input_size` (area interpolation)."""
        import cv2

        frame = _as_frame(frame)
        x0, y0, w, h = view_box((frame.shape[1], frame.shape[0]))
        view = frame[y0:y0 + h, x0:x0 + w]
        if (w, h) == self.input_size:
            return np.ascontiguousarray(view)
        return cv2.resize(view, self.input_size, interpolation=cv2.INTER_AREA)

    @property
    def has_error_head(self) -> bool:
        """Whether the model also outputs its own expected error (``error_px``, net/export.py)."""
        return len(self._output_names) > 1

    def run(self, images: np.ndarray) -> np.ndarray:
        """Preprocessed uint8 ``N x H x W x 3`` batch -> float64 ``N x 2`` (k1, k2).

        With :attr:`mirror_average` the result is the mean of the outputs for the images and for
        their left-right mirrors.
        """
        return self.run_with_error(images)[0]

    def run_with_error(self, images: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`run`, and the network's own expected error per frame (float64 ``N``, px of a
        1920-wide frame: the scale of a Laplace model of its maximum displacement error over the
        16:9 frame, uncalibrated) when the model has an error head, else ``None``. Mirror averaging
        averages both."""
        images = np.asarray(images)
        width, height = self.input_size
        if images.dtype != np.uint8 or images.shape[1:] != (height, width, 3):
            raise ValueError(f"images must be uint8 N×{height}×{width}×3, got {images.dtype} {images.shape}")
        n = len(images)
        batch = np.concatenate([images, images[:, :, ::-1]]) if self.mirror_average else images
        outputs = self._session.run(self._output_names, {self._input_name: np.ascontiguousarray(batch)})
        out = np.asarray(outputs[0], dtype=np.float64)
        if out.shape != (len(batch), 2):
            raise ModelLoadError(f"{self.model_path}: output of shape {out.shape} for a batch of {len(batch)}, not {len(batch)}×2")
        error = np.asarray(outputs[1], dtype=np.float64).reshape(-1) if len(outputs) > 1 else None
        if self.mirror_average:
            out = 0.5 * (out[:n] + out[n:])
            error = None if error is None else 0.5 * (error[:n] + error[n:])
        return out, error

    def estimate_batch(self, frames: Sequence[np.ndarray], method: Method = "auto",
                       pixel_aspect: float = 1.0) -> list[LensEstimate]:
        """Estimate each frame of a sequence (or an ``N x H x W x C`` array); the CNN runs in one
        session call. ``method``: ``"net"`` (the CNN), ``"lines"`` (the line fit, the CNN as its
        prior; the CNN's answer when a frame has no usable lines) or ``"auto"`` (the line fit when
        its calibrated bound beats the CNN's); each :class:`~glradial.estimation.lens_estimate.LensEstimate`
        says which method produced it, how sure it is (``uncertainty_px``, px at 1920) and whether
        it is doubtful (``doubtful``, ``reason``). ``pixel_aspect`` (``fy / fx``, default 1): for
        frames stored with non-square pixels (e.g. a 16:9 picture squashed into 640×640: 16/9); each
        is restored to square pixels (:func:`square_pixels`) before estimating, and the estimate
        carries ``pixel_aspect``, so :func:`glradial.correct` applies it to the stored frame."""
        method = check_method(method)
        if isinstance(frames, np.ndarray) and frames.ndim == 4:
            frames = list(frames)
        if isinstance(frames, (str, bytes, np.ndarray)) or not hasattr(frames, "__iter__"):
            raise TypeError(f"frames must be a sequence of NumPy arrays (or an N×H×W×C array), got {type(frames).__name__}")
        frames = [_as_frame(f, i) for i, f in enumerate(frames)]
        if pixel_aspect != 1.0:
            aspect = Lens(pixel_aspect=pixel_aspect).pixel_aspect  # checked: positive, finite
            frames = [square_pixels(f, aspect) for f in frames]
            return [replace(judge(e, method), pixel_aspect=aspect) for e in self.evidence_batch(frames, lines=method != "net")]
        return [judge(e, method) for e in self.evidence_batch(frames, lines=method != "net")]

    def evidence_batch(self, frames: Sequence[np.ndarray], lines: bool = True) -> list[FrameEvidence]:
        """The :class:`glradial.estimation.trust.FrameEvidence` of each uint8 RGB frame: the CNN (one session
        call, answers in each frame's geometry), its view's features and, with ``lines``, the line fit."""
        if not frames:
            return []
        views = [self.preprocess(f) for f in frames]
        net, error = self.run_with_error(np.stack(views))
        errors = [None] * len(frames) if error is None else [float(e) for e in error]
        return [frame_evidence(f, view_to_frame(k, (f.shape[1], f.shape[0])), view_features(v), lines, e)
                for f, v, k, e in zip(frames, views, net, errors)]

    def estimate(self, frame: np.ndarray, method: Method = "auto", pixel_aspect: float = 1.0) -> LensEstimate:
        """Estimate one frame's lens (``method``, ``pixel_aspect`` as in :meth:`estimate_batch`)."""
        return self.estimate_batch([_as_frame(frame)], method, pixel_aspect)[0]

    __call__ = estimate


_default: NetLinesEstimator | None = None
_default_lock = threading.Lock()


def default_net_lines_estimator() -> NetLinesEstimator:
    """The shared :class:`NetLinesEstimator` of the bundled model, created on first use."""
    global _default
    with _default_lock:
        if _default is None:
            _default = NetLinesEstimator()
        return _default


def estimate_net_lines(frame: np.ndarray, method: Method = "auto", pixel_aspect: float = 1.0) -> LensEstimate:
    """Estimate the radial lens of one RGB frame with the bundled model and the frame's lines
    (``method``: ``"auto"``, ``"net"`` or ``"lines"``; ``pixel_aspect`` for frames stored with
    non-square pixels; see :meth:`NetLinesEstimator.estimate_batch`)."""
    check_method(method)
    return default_net_lines_estimator().estimate(frame, method, pixel_aspect)
