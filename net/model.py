"""The distortion estimator: a light ResNet-like CNN with inverted residual blocks, two regressors.

Convention:
    input   float32 tensor ``N x C x H x W`` (NCHW), C = 3 (RGB, in that order) or 1 (grayscale,
            ITU-R BT.601 luma of the RGB frame); pixel values are ``(x / 255 - mean) / std`` with
            ``mean``/``std`` from :class:`ModelConfig`. The frame is the whole 16:9 frame the lens
            refers to, resized (area interpolation) to ``input_size = (W, H)``; the aspect ratio is
            not kept when ``W / H != 16 / 9`` (the paper squashes 16:9 into 224 x 224).
    output  float32 ``N x 2``: ``(k1, k2)`` in width-normalised lens units (docs/DESIGN.md); with
            ``error_head``, ``N x 3``: a third column, the log of the expected error in px at 1920.

Architecture (timm-style: ``forward_features`` -> pooled features, ``forward_head`` -> (k1, k2)):
a 3x3 stride-2 stem, stages of MobileNetV2 inverted residual blocks (expand 1x1, depthwise 3x3,
project 1x1, identity shortcut when stride is 1 and channels match; early stages may use the
fused variant, a full 3x3 expand conv then project 1x1), optionally three coordinate
channels (x, y, r in lens units) concatenated to the stem input (CoordConv: the distortion is radial,
so where a curved line sits matters), a 1x1 conv to ``feature_channels``, global average pooling,
and two heads ``Linear(F, 32) -> BatchNorm1d -> LeakyReLU -> Linear(32, 1)`` for k1 and k2.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from glradial.lens.metrics import PAPER_SIZE, manifold_k2
from glradial.media.atomic import atomic_write_text

#: Initial log error scale of the error head (px at 1920): about the shipped model's median error.
ERROR_INIT_LOG_PX = 1.5

#: ITU-R BT.601 luma weights (R, G, B) used by the grayscale variant.
LUMA_WEIGHTS = (0.299, 0.587, 0.114)


@dataclass
class ModelConfig:
    """Everything needed to rebuild the network and feed it (saved beside the model and in ONNX).

    ``input_size`` is ``(W, H)`` like every size in glradial. ``pool_grid`` 1 is global average
    pooling; g > 1 concatenates global pooling with a g x g grid of average pools (the heads then
    know in which part of the frame a feature was seen). ``k2_residual``: the k2 head predicts the
    deviation from the Lopez-Antequera manifold of the predicted k1, ``k2 = 0.019 k1 + 0.805 k1^2 +
    head_k2`` (the manifold term does not pass gradients back to k1). ``stages`` lists
    ``(expansion, out_channels, blocks, stride[, fused])`` (fused = 1: Fused-MBConv, a full 3x3
    expand conv instead of 1x1 + depthwise; faster to train in early stages). ``mean``/``std`` apply to ``x / 255`` per
    channel in ``channel_order`` ("RGB" or "L"). ``error_head``: a third head predicts
    ``log`` of the network's own error scale, in px of a 1920-wide frame (the maximum displacement
    between its (k1, k2) and the true lens over the 16:9 frame, :func:`net.loss.error_scale_loss`);
    it reads detached features, so it never changes what the k1/k2 heads learn.
    ``comparator_head``: a training-only second task (after Janos & Benesova's multi-task sequel):
    :class:`ComparatorHead` says from the pooled features of two crops which has the larger k1 and
    which the larger k2 (:func:`net.loss.comparator_loss`). It is never part of the exported graph
    (:func:`inference_model` drops it).
    """

    input_size: tuple[int, int] = (224, 224)
    channels: int = 3
    stem_channels: int = 16
    stages: list[tuple[int, int, int, int]] = field(
        default_factory=lambda: [(1, 16, 1, 1), (4, 24, 2, 2), (4, 32, 2, 2), (4, 48, 2, 2), (4, 64, 2, 2)]
    )
    feature_channels: int = 256
    head_hidden: int = 32
    coord_channels: bool = True
    pool_grid: int = 1
    k2_residual: bool = False
    error_head: bool = False
    comparator_head: bool = False
    k_init: tuple[float, float] = (-0.2, 0.1)
    mean: tuple[float, ...] = (0.5, 0.5, 0.5)
    std: tuple[float, ...] = (0.25, 0.25, 0.25)

    def __post_init__(self) -> None:
        self.input_size = tuple(int(v) for v in self.input_size)  # type: ignore[assignment]
        self.stages = [tuple(int(v) for v in s) for s in self.stages]  # type: ignore[misc]
        self.mean = tuple(float(v) for v in self.mean)
        self.std = tuple(float(v) for v in self.std)
        self.k_init = tuple(float(v) for v in self.k_init)  # type: ignore[assignment]
        if self.channels not in (1, 3):
            raise ValueError(f"channels must be 1 (grayscale) or 3 (RGB), got {self.channels}")
        if self.pool_grid < 1:
            raise ValueError(f"pool_grid must be >= 1, got {self.pool_grid}")
        if len(self.input_size) != 2 or min(self.input_size) < 16:
            raise ValueError(f"input_size must be (W, H) with both >= 16, got {self.input_size}")
        if len(self.mean) != self.channels or len(self.std) != self.channels:
            raise ValueError(
                f"mean/std need {self.channels} values, got mean={self.mean} std={self.std}"
            )
        if any(s <= 0 for s in self.std):
            raise ValueError(f"std must be positive, got {self.std}")
        for stage in self.stages:
            if len(stage) not in (4, 5) or min(stage[:4]) < 1:
                raise ValueError(f"a stage is (expansion, out_channels, blocks, stride[, fused]) >= 1, got {stage}")

    @property
    def channel_order(self) -> str:
        return "RGB" if self.channels == 3 else "L"

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out["channel_order"] = self.channel_order
        out["layout"] = "NCHW"
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "ModelConfig":
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})

    def save(self, path: str | Path) -> None:
        atomic_write_text(path, json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "ModelConfig":
        return cls.from_dict(json.loads(Path(path).read_text()))


class ConvBNAct(nn.Sequential):
    def __init__(self, cin: int, cout: int, kernel: int, stride: int = 1, groups: int = 1, act: bool = True):
        layers: list[nn.Module] = [
            nn.Conv2d(cin, cout, kernel, stride, kernel // 2, groups=groups, bias=False),
            nn.BatchNorm2d(cout),
        ]
        if act:
            layers.append(nn.ReLU6(inplace=True))
        super().__init__(*layers)


class InvertedResidual(nn.Module):
    """MobileNetV2 block: expand 1x1 -> depthwise 3x3 (stride) -> project 1x1 (linear)."""

    def __init__(self, cin: int, cout: int, stride: int, expansion: int):
        super().__init__()
        hidden = cin * expansion
        layers: list[nn.Module] = []
        if expansion != 1:
            layers.append(ConvBNAct(cin, hidden, 1))
        layers += [ConvBNAct(hidden, hidden, 3, stride, groups=hidden), ConvBNAct(hidden, cout, 1, act=False)]
        self.block = nn.Sequential(*layers)
        self.residual = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.block(x)
        return x + y if self.residual else y


class FusedInvertedResidual(nn.Module):
    """Fused-MBConv block (EfficientNetV2): full 3x3 expand conv (stride) -> project 1x1 (linear)."""

    def __init__(self, cin: int, cout: int, stride: int, expansion: int):
        super().__init__()
        hidden = cin * expansion
        self.block = nn.Sequential(ConvBNAct(cin, hidden, 3, stride), ConvBNAct(hidden, cout, 1, act=False))
        self.residual = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.block(x)
        return x + y if self.residual else y


class RegressionHead(nn.Module):
    """``Linear(F, hidden) -> BatchNorm1d -> LeakyReLU -> Linear(hidden, 1)``."""

    def __init__(self, features: int, hidden: int, init: float):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(features, hidden), nn.BatchNorm1d(hidden), nn.LeakyReLU(0.1), nn.Linear(hidden, 1)
        )
        nn.init.zeros_(self.net[-1].weight)
        nn.init.constant_(self.net[-1].bias, init)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class ComparatorHead(nn.Module):
    """Which of two crops has the larger k1 and which the larger k2, from their pooled features.

    ``forward(a, b)`` -> ``N x 2`` logits (k1, k2); positive means the first crop's coefficient is
    the larger. Antisymmetric by construction, ``logit(a, b) = g([a, b]) - g([b, a])`` with ``g``
    ``Linear(2F, hidden) -> LeakyReLU -> Linear(hidden, 2)``: swapping the crops flips the sign, so
    ``p(a > b) + p(b > a) = 1`` and a crop compared with itself gets exactly 0.5."""

    def __init__(self, features: int, hidden: int):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(2 * features, hidden), nn.LeakyReLU(0.1), nn.Linear(hidden, 2))

    def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([a, b], dim=1)) - self.net(torch.cat([b, a], dim=1))


def coordinate_grid(width: int, height: int) -> torch.Tensor:
    """``1 x 3 x H x W`` channels (x, y, r) in lens units of the 16:9 frame (x in [-0.5, 0.5])."""
    aspect = PAPER_SIZE[1] / PAPER_SIZE[0]
    xs = (torch.arange(width, dtype=torch.float32) + 0.5) / width - 0.5
    ys = ((torch.arange(height, dtype=torch.float32) + 0.5) / height - 0.5) * aspect
    gy, gx = torch.meshgrid(ys, xs, indexing="ij")
    r = torch.sqrt(gx * gx + gy * gy)
    # scaled to unit-ish range like the normalised pixels
    return torch.stack([gx * 4.0, gy * 4.0, r * 4.0])[None]


class DistortionNet(nn.Module):
    """Estimates ``(k1, k2)`` from a normalised frame tensor; see the module docstring."""

    def __init__(self, config: ModelConfig | None = None):
        super().__init__()
        self.config = config = config or ModelConfig()
        width, height = config.input_size
        cin = config.channels
        if config.coord_channels:
            self.register_buffer("coords", coordinate_grid(width, height), persistent=False)
            cin += 3
        else:
            self.coords = None
        self.stem = ConvBNAct(cin, config.stem_channels, 3, 2)
        blocks: list[nn.Module] = []
        channels = config.stem_channels
        for stage in config.stages:
            expansion, cout, count, stride = stage[:4]
            block = FusedInvertedResidual if len(stage) > 4 and stage[4] else InvertedResidual
            for i in range(count):
                blocks.append(block(channels, cout, stride if i == 0 else 1, expansion))
                channels = cout
        self.blocks = nn.Sequential(*blocks)
        self.conv_head = ConvBNAct(channels, config.feature_channels, 1)
        self.pool = nn.AdaptiveAvgPool2d(1)
        self.grid_pool = nn.AdaptiveAvgPool2d(config.pool_grid) if config.pool_grid > 1 else None
        features = config.feature_channels * (1 + (config.pool_grid**2 if config.pool_grid > 1 else 0))
        self.num_features = features
        self.head_k1 = RegressionHead(features, config.head_hidden, config.k_init[0])
        self.head_k2 = RegressionHead(features, config.head_hidden, config.k_init[1])
        self.head_error = RegressionHead(features, config.head_hidden, ERROR_INIT_LOG_PX) if config.error_head else None
        self.head_compare = ComparatorHead(features, config.head_hidden) if config.comparator_head else None
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out")

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        """``N x C x H x W`` normalised input -> ``N x num_features`` pooled features."""
        if self.coords is not None:
            x = torch.cat([x, self.coords.expand(x.shape[0], -1, -1, -1)], dim=1)
        x = self.conv_head(self.blocks(self.stem(x)))
        pooled = torch.flatten(self.pool(x), 1)
        if self.grid_pool is not None:
            pooled = torch.cat([pooled, torch.flatten(self.grid_pool(x), 1)], dim=1)
        return pooled

    def forward_head(self, features: torch.Tensor) -> torch.Tensor:
        """Pooled features -> ``N x 2`` (k1, k2), or ``N x 3`` (k1, k2, log error scale in px at
        1920) with ``error_head``."""
        k1 = self.head_k1(features)
        k2 = self.head_k2(features)
        if self.config.k2_residual:
            prior = k1.detach()
            k2 = k2 + manifold_k2(prior)
        if self.head_error is None:
            return torch.cat([k1, k2], dim=1)
        return torch.cat([k1, k2, self.head_error(features.detach())], dim=1)

    def forward(self, x: torch.Tensor, partner: torch.Tensor | None = None) -> torch.Tensor:
        """:meth:`forward_head` of the input; with ``partner`` (int64 ``N``: the index in the batch of
        the crop each crop is compared with; needs ``comparator_head``) two more columns, the
        comparator's logits ``(k1, k2)`` of crop i against crop ``partner[i]`` (one call, so that
        DistributedDataParallel sees the comparator's parameters used)."""
        features = self.forward_features(x)
        out = self.forward_head(features)
        if partner is None:
            return out
        if self.head_compare is None:
            raise ValueError("partner given to a model without comparator_head")
        return torch.cat([out, self.head_compare(features, features[partner])], dim=1)


def inference_model(model: DistortionNet) -> DistortionNet:
    """``model`` without its training-only parts (the comparator head): a new network, same config
    but ``comparator_head`` off, with every other weight copied; ``model`` itself when it has none.
    The exported graph and its ``model_config`` metadata are this network's."""
    if model.head_compare is None:
        return model
    config = dataclasses.replace(model.config, comparator_head=False)
    kept = {k: v for k, v in model.state_dict().items() if not k.startswith("head_compare.")}
    slim = DistortionNet(config).to(next(model.parameters()).device)
    slim.load_state_dict(kept)
    return slim.train(model.training)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def normalise_batch(images: torch.Tensor, config: ModelConfig) -> torch.Tensor:
    """uint8 ``N x H x W x 3`` RGB (already at ``input_size``) -> normalised float ``N x C x H x W``.

    The one definition of the preprocessing: training feeds the network through it and the exported
    ONNX graph contains it (:class:`net.export.ExportWrapper`)."""
    x = images.permute(0, 3, 1, 2).float().div_(255.0)
    if config.channels == 1:
        w = torch.tensor(LUMA_WEIGHTS, dtype=x.dtype).view(1, 3, 1, 1).to(x.device, non_blocking=True)
        x = (x * w).sum(dim=1, keepdim=True)
    # made on the host and sent without waiting (a CUDA training step does not stop here for the device)
    mean = torch.tensor(config.mean, dtype=x.dtype).view(1, -1, 1, 1).to(x.device, non_blocking=True)
    std = torch.tensor(config.std, dtype=x.dtype).view(1, -1, 1, 1).to(x.device, non_blocking=True)
    return (x - mean) / std


def load_grown(model: DistortionNet, weights: dict[str, torch.Tensor]) -> dict[str, list[str]]:
    """Load a smaller network's ``weights`` into ``model``, a wider and/or deeper one, so that the
    grown model computes exactly the same function (Net2Net-style growth, then fine-tune).

    Widths may grow (block expansions, stage channels, ``feature_channels``, ``head_hidden``) and
    stages may gain blocks after their last one (only where that keeps every later block's index,
    i.e. in the last stage). Rules, each of which keeps the output unchanged:

    * a tensor of the same shape is copied;
    * a grown tensor gets the old values in its leading slice; the weights a layer gives to its new
      *inputs* (dim 1 of a conv or linear weight) are zero, so the new units it receives are ignored;
      new *outputs* keep their fresh initialisation (they can learn once a consumer's zero weights
      move); batch-norm entries of new channels keep their defaults;
    * a new residual block gets a zero scale in its last batch norm, so it starts as the identity.

    Returns the names that were ``copied``, ``grown`` and ``new``. Raises ``ValueError`` for a
    tensor that shrank or changed rank (also what a block's expansion changing from or to 1 looks
    like: the layers differ) and for a new block that has no identity shortcut.
    """
    target = model.state_dict()
    report: dict[str, list[str]] = {"copied": [], "grown": [], "new": []}
    for name, value in target.items():
        if name not in weights:
            report["new"].append(name)
            continue
        old = weights[name]
        if old.shape == value.shape:
            value.copy_(old)
            report["copied"].append(name)
            continue
        if old.ndim != value.ndim or any(o > n for o, n in zip(old.shape, value.shape)):
            raise ValueError(f"{name}: cannot grow {tuple(old.shape)} into {tuple(value.shape)} (a tensor may only "
                             "widen; an expansion of 1 has no expand conv, so it cannot change)")
        if value.ndim >= 2:
            value[:, old.shape[1]:].zero_()
        value[tuple(slice(0, n) for n in old.shape)] = old
        report["grown"].append(name)
    new_names = set(report["new"])
    for prefix, module in model.named_modules():
        if isinstance(module, (InvertedResidual, FusedInvertedResidual)):
            names = [f"{prefix}.{n}" for n, _ in module.named_parameters()]
            if names and all(n in new_names for n in names):
                if not module.residual:
                    raise ValueError(f"{prefix}: a new block must have an identity shortcut (stride 1, same channels)")
                target[f"{prefix}.block.{len(module.block) - 1}.1.weight"].zero_()
    model.load_state_dict(target)
    return report
