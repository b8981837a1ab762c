"""Feature pyramid network (Lin et al. 2017) for 4-band aerial patches, in plain torch.

Bottom-up: a stride-2 stem, then a ResNet-style path (basic residual blocks) at strides 4, 8,
16, 32. Top-down: lateral 1x1 convolutions and nearest upsampling merge the levels into
P2..P5, which are summed at stride 4, joined with the stem at stride 2 and decoded into two logit
maps, bilinearly upsampled to full resolution: channel 0 = keypoint map, channel 1 = boundary
segmentation (paper IV-B). No convolution runs at full resolution: on CPU that alone cost more
than the rest of the network, and logits at stride 2 resolve 3 px boundaries after upsampling.
Fully convolutional: trains on crops, infers on 1100x1100 patches (any size; padded internally
to a multiple of the total stride).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

KEYPOINT, SEGMENTATION = 0, 1


@dataclass(frozen=True)
class FPNConfig:
    in_channels: int = 4
    widths: tuple[int, ...] = (32, 48, 64, 96)  # bottom-up stages at strides 4, 8, 16, 32
    blocks: tuple[int, ...] = (2, 2, 2, 1)  # residual blocks per stage
    pyramid: int = 48  # channels of the top-down path
    stem: int = 24  # channels of the stride-2 stem
    out_channels: int = 2

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "FPNConfig":
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items() if k in cls.__dataclass_fields__})


def conv_bn_relu(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class BasicBlock(nn.Module):
    """Two 3x3 convolutions with a residual connection (ResNet-18/34 style)."""

    def __init__(self, cin: int, cout: int, stride: int = 1):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
            nn.Conv2d(cout, cout, 3, 1, 1, bias=False), nn.BatchNorm2d(cout),
        )
        self.skip = nn.Identity() if stride == 1 and cin == cout else nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.body(x) + self.skip(x))


class FPN(nn.Module):
    def __init__(self, config: FPNConfig = FPNConfig()):
        super().__init__()
        self.config = config
        c = config
        self.stem = nn.Sequential(conv_bn_relu(c.in_channels, c.stem, 2), conv_bn_relu(c.stem, c.stem))
        stages, cin = [], c.stem
        for width, count in zip(c.widths, c.blocks):
            stages.append(nn.Sequential(BasicBlock(cin, width, 2), *[BasicBlock(width, width) for _ in range(count - 1)]))
            cin = width
        self.stages = nn.ModuleList(stages)
        self.lateral = nn.ModuleList(nn.Conv2d(w, c.pyramid, 1) for w in c.widths)
        self.smooth = nn.ModuleList(conv_bn_relu(c.pyramid, c.pyramid) for _ in c.widths)
        self.head = nn.Sequential(conv_bn_relu(c.pyramid + c.stem, c.pyramid), nn.Conv2d(c.pyramid, c.out_channels, 1))
        self.stride = 2 ** (len(c.widths) + 1)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """(B, in_channels, H, W) in [0, 1] -> (B, out_channels, H, W) logits."""
        h, w = image.shape[-2:]
        pad_h, pad_w = (-h) % self.stride, (-w) % self.stride
        x = F.pad(image, (0, pad_w, 0, pad_h)) if pad_h or pad_w else image
        x = (x - 0.5) / 0.25
        stem = self.stem(x)
        features, y = [], stem
        for stage in self.stages:
            y = stage(y)
            features.append(y)
        top = self.lateral[-1](features[-1])
        pyramid = [self.smooth[-1](top)]
        for level in range(len(features) - 2, -1, -1):
            top = self.lateral[level](features[level]) + F.interpolate(top, size=features[level].shape[-2:], mode="nearest")
            pyramid.insert(0, self.smooth[level](top))
        fused = pyramid[0]
        for p in pyramid[1:]:
            fused = fused + F.interpolate(p, size=fused.shape[-2:], mode="bilinear", align_corners=False)
        half = F.interpolate(fused, size=stem.shape[-2:], mode="bilinear", align_corners=False)
        logits = self.head(torch.cat([half, stem], dim=1))
        logits = F.interpolate(logits, scale_factor=2, mode="bilinear", align_corners=False)
        return logits[..., :h, :w]
