"""Feature pyramid network (Lin et al. 2017) for 4-band aerial patches, in plain torch.

Bottom-up: a stride-2 stem, then a ResNet-style path (basic residual blocks) at strides 4, 8,
16, 32. Top-down: lateral 1x1 convolutions and nearest upsampling merge the levels into
P2..P5, which are summed at stride 4, joined with the stem at stride 2 and decoded into two logit
maps, bilinearly upsampled to full resolution: channel 0 = keypoint map, channel 1 = boundary
segmentation (paper IV-B). No convolution runs at full resolution: on CPU that alone cost more
than the rest of the network, and logits at stride 2 resolve 3 px boundaries after upsampling.
Fully convolutional: trains on crops, infers on 1100x1100 patches (any size; padded internally
to a multiple of the total stride).

Two bottom-up paths (``FPNConfig.backbone``):

* ``resnet``: the from-scratch path above (the first shipped model; the baselines' trunks).
* ``efficientnet-lite0`` (or ``-lite1``, ``-lite2``): the ImageNet-pretrained encoder of
  :mod:`csboundary.models.efficientnet_lite`, run on the patch resized by ``encoder_scale``
  (default 0.5: at 0.3 m/px a street is still tens of pixels wide, the encoder sees twice the
  context and costs a quarter as much). Its levels at strides 4-32 (of its input) feed the same
  top-down path; a light full-resolution stem (two convolutions at stride 2, from scratch) gives
  the head the pixel detail that a 3 px boundary needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from csboundary.config import Config

KEYPOINT, SEGMENTATION, SURFACE = 0, 1, 2


@dataclass(frozen=True)
class FPNConfig(Config):
    in_channels: int = 4
    widths: tuple[int, ...] = (32, 48, 64, 96)  # bottom-up stages at strides 4, 8, 16, 32
    blocks: tuple[int, ...] = (2, 2, 2, 1)  # residual blocks per stage
    pyramid: int = 48  # channels of the top-down path
    stem: int = 24  # channels of the stride-2 stem
    out_channels: int = 2
    backbone: str = "resnet"  # resnet (from scratch) | efficientnet-lite0/1/2 (ImageNet-pretrained)
    encoder_scale: float = 0.5  # efficientnet-lite* only: the encoder sees the patch resized by this
    pretrained: bool = True  # efficientnet-lite* only: start from the ImageNet weights (training)
    head: str = "full"  # full | light: how the stride-2 head joins the pyramid and the stem (see add_head)
    head_channels: int = 16  # light head only: channels at stride 2
    surface: bool = False  # a third output: road-surface logits from the pyramid (see add_surface_head)


def conv_bn_relu(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class BasicBlock(nn.Module):
    """Two 3x3 convolutions with a residual connection (ResNet-18/34 style)."""

    def __init__(self, cin: int, cout: int, stride: int = 1):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(cin, cout, 3, stride, 1, bias=False),
            nn.BatchNorm2d(cout),
            nn.ReLU(inplace=True),
            nn.Conv2d(cout, cout, 3, 1, 1, bias=False),
            nn.BatchNorm2d(cout),
        )
        self.skip = (
            nn.Identity()
            if stride == 1 and cin == cout
            else nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.body(x) + self.skip(x))


BACKBONES = ("resnet", "efficientnet-lite0", "efficientnet-lite1", "efficientnet-lite2")


def fpn_for_weights(config: dict) -> nn.Module:
    """An FPN to load trained weights into: built from a checkpoint's config without reading the
    ImageNet weights (they would be overwritten at once)."""
    return FPN(FPNConfig.from_dict({**config, "pretrained": False}))


def FPN(config: FPNConfig = FPNConfig()) -> nn.Module:
    """The FPN of ``config.backbone`` (both map (B, 4, H, W) in [0, 1] to (B, out, H, W) logits)."""
    if config.backbone == "resnet":
        return ResNetFPN(config)
    if config.backbone in BACKBONES[1:]:
        return LiteFPN(config)
    raise ValueError(f"unknown FPN backbone {config.backbone!r}; expected one of {', '.join(BACKBONES)}")


HEADS = ("full", "light")


def add_head(module: nn.Module, c: FPNConfig) -> None:
    """The stride-2 head's layers on ``module`` (used by :func:`head_logits`).

    ``full`` (the shipped models up to issue 15): the pyramid upsampled to stride 2, concatenated
    with the stem, a 3x3 convolution back to ``pyramid`` channels and a 1x1 to the logits; at
    1100 px that convolution (72 -> 48 channels on 550 x 550) is most of the network's time.
    ``light``: the pyramid and the stem are each mapped to ``head_channels`` by a 1x1
    convolution at their own resolution and summed (the pyramid upsampled), then one 3x3
    convolution at that width and the 1x1 logits: about a tenth of the full head's work.
    """
    if c.head not in HEADS:
        raise ValueError(f"unknown FPN head {c.head!r}; expected one of {', '.join(HEADS)}")
    if c.head == "full":
        module.head = nn.Sequential(
            conv_bn_relu(c.pyramid + c.stem, c.pyramid), nn.Conv2d(c.pyramid, c.out_channels, 1)
        )
        return
    module.reduce = nn.Conv2d(c.pyramid, c.head_channels, 1)
    module.project = nn.Conv2d(c.stem, c.head_channels, 1)
    module.head = nn.Sequential(
        conv_bn_relu(c.head_channels, c.head_channels), nn.Conv2d(c.head_channels, c.out_channels, 1)
    )


def add_surface_head(module: nn.Module, c: FPNConfig, width: int = 32) -> None:
    """The road-surface head on ``module`` when ``c.surface``: two 3x3 convolutions and a 1x1 on
    the fused pyramid (stride 4 of the encoder's input), the logits upsampled to the patch.

    Why: the boundary map fires on every outline of the scene (roofs, yards, canopy); a road
    boundary is the one with roadway beside it. The roadway is a wide, textured region that the
    pyramid's context resolves better than a 3 px line, and it lets a patch graph keep only the
    edges that border it (:mod:`csboundary.graph.surface_check`). Cheap: it runs at 1/8 (or 1/4)
    of the patch's resolution."""
    if c.surface:
        module.surface_head = nn.Sequential(
            conv_bn_relu(c.pyramid, width), conv_bn_relu(width, width), nn.Conv2d(width, 1, 1)
        )


def with_surface(module: nn.Module, logits: torch.Tensor, fused: torch.Tensor) -> torch.Tensor:
    """``logits`` (B, out, H, W) with the surface logits appended as a last channel when the
    module has a surface head."""
    if not module.config.surface:
        return logits
    road = F.interpolate(module.surface_head(fused), size=logits.shape[-2:], mode="bilinear", align_corners=False)
    return torch.cat([logits, road], dim=1)


def head_logits(module: nn.Module, fused: torch.Tensor, stem: torch.Tensor) -> torch.Tensor:
    """Logits at the stem's resolution (stride 2) from the fused pyramid and the stem."""
    if module.config.head == "full":
        half = F.interpolate(fused, size=stem.shape[-2:], mode="bilinear", align_corners=False)
        return module.head(torch.cat([half, stem], dim=1))
    half = F.interpolate(module.reduce(fused), size=stem.shape[-2:], mode="bilinear", align_corners=False)
    return module.head(half + module.project(stem))


def top_down(features: list[torch.Tensor], lateral: nn.ModuleList, smooth: nn.ModuleList) -> torch.Tensor:
    """FPN top-down path: lateral 1x1 maps plus the upsampled coarser level, each smoothed, all
    summed at the finest level's resolution."""
    top = lateral[-1](features[-1])
    pyramid = [smooth[-1](top)]
    for level in range(len(features) - 2, -1, -1):
        top = lateral[level](features[level]) + F.interpolate(top, size=features[level].shape[-2:], mode="nearest")
        pyramid.insert(0, smooth[level](top))
    fused = pyramid[0]
    for p in pyramid[1:]:
        fused = fused + F.interpolate(p, size=fused.shape[-2:], mode="bilinear", align_corners=False)
    return fused


class ResNetFPN(nn.Module):
    def __init__(self, config: FPNConfig = FPNConfig()):
        super().__init__()
        self.config = config
        c = config
        self.stem = nn.Sequential(conv_bn_relu(c.in_channels, c.stem, 2), conv_bn_relu(c.stem, c.stem))
        stages, cin = [], c.stem
        for width, count in zip(c.widths, c.blocks):
            stages.append(
                nn.Sequential(BasicBlock(cin, width, 2), *[BasicBlock(width, width) for _ in range(count - 1)])
            )
            cin = width
        self.stages = nn.ModuleList(stages)
        self.lateral = nn.ModuleList(nn.Conv2d(w, c.pyramid, 1) for w in c.widths)
        self.smooth = nn.ModuleList(conv_bn_relu(c.pyramid, c.pyramid) for _ in c.widths)
        add_head(self, c)
        add_surface_head(self, c)
        self.stride = 2 ** (len(c.widths) + 1)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """(B, in_channels, H, W) in [0, 1] -> (B, out_channels (+1 surface), H, W) logits."""
        h, w = image.shape[-2:]
        pad_h, pad_w = (-h) % self.stride, (-w) % self.stride
        x = F.pad(image, (0, pad_w, 0, pad_h)) if pad_h or pad_w else image
        x = (x - 0.5) / 0.25
        stem = self.stem(x)
        features, y = [], stem
        for stage in self.stages:
            y = stage(y)
            features.append(y)
        fused = top_down(features, self.lateral, self.smooth)
        logits = F.interpolate(head_logits(self, fused, stem), scale_factor=2, mode="bilinear", align_corners=False)
        return with_surface(self, logits, fused)[..., :h, :w]


class LiteFPN(nn.Module):
    """EfficientNet-Lite bottom-up path (ImageNet-pretrained) under the same top-down path and head."""

    def __init__(self, config: FPNConfig):
        super().__init__()
        from csboundary.models.efficientnet_lite import EfficientNetLite, pretrained_lite, tap_channels

        if config.encoder_scale not in (1.0, 0.5, 0.25):
            raise ValueError(f"encoder_scale must be 1, 0.5 or 0.25, got {config.encoder_scale}")
        self.config = c = config
        variant = c.backbone.removeprefix("efficientnet-")
        self.encoder = (
            pretrained_lite(c.in_channels, variant) if c.pretrained else EfficientNetLite(c.in_channels, variant)
        )
        levels, channels = (4, 8, 16, 32), tap_channels(variant)
        self.lateral = nn.ModuleList(nn.Conv2d(channels[s], c.pyramid, 1) for s in levels)
        self.smooth = nn.ModuleList(conv_bn_relu(c.pyramid, c.pyramid) for _ in levels)
        self.stem = nn.Sequential(conv_bn_relu(c.in_channels, c.stem, 2), conv_bn_relu(c.stem, c.stem))
        add_head(self, c)
        add_surface_head(self, c)
        self.stride = round(32 / c.encoder_scale)
        self.freeze_encoder_bn = False  # set by training: keep the encoder's ImageNet batch statistics

    def train(self, mode: bool = True) -> "LiteFPN":
        """As ``nn.Module.train``, but with ``freeze_encoder_bn`` the encoder's batch norms stay in
        eval mode: their ImageNet statistics are not pulled towards the synthetic cities'."""
        super().train(mode)
        if mode and self.freeze_encoder_bn:
            for module in self.encoder.modules():
                if isinstance(module, nn.BatchNorm2d):
                    module.eval()
        return self

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """(B, in_channels, H, W) in [0, 1] -> (B, out_channels (+1 surface), H, W) logits."""
        h, w = image.shape[-2:]
        pad_h, pad_w = (-h) % self.stride, (-w) % self.stride
        x = F.pad(image, (0, pad_w, 0, pad_h), mode="replicate") if pad_h or pad_w else image
        factor = round(1 / self.config.encoder_scale)
        small = F.avg_pool2d(x, factor) if factor > 1 else x  # box filter: antialiased, exact, exports anywhere
        features = self.encoder(small)[1:]  # strides 4..32 of the encoder's input
        fused = top_down(features, self.lateral, self.smooth)
        stem = self.stem((x - 0.5) / 0.25)
        if self.encoder.style_mix is not None:  # training only: the full-resolution stem sees the look too
            stem = self.encoder.style_mix(stem)
        logits = F.interpolate(head_logits(self, fused, stem), scale_factor=2, mode="bilinear", align_corners=False)
        return with_surface(self, logits, fused)[..., :h, :w]
