"""The network that steps (:class:`Agent`) and what it sees: the ROI of the window tensor around
the current vertex plus a channel drawing the trace's recent history."""

from __future__ import annotations

import torch
from torch import nn

from csboundary.models.afanet import crop_rois
from csboundary.models.baselines.icurb.config import ICurbConfig


class Agent(nn.Module):
    """(B, 6, roi, roi) ROI -> next vertex offset (B, 2) in px, within +-roi/2, and stop logit (B,)."""

    def __init__(self, config: ICurbConfig):
        super().__init__()
        layers, cin, side = [], 6, config.roi
        for w in config.widths:
            layers += [nn.Conv2d(cin, w, 3, 2, 1, bias=False), nn.BatchNorm2d(w), nn.ReLU(inplace=True)]
            cin, side = w, (side + 1) // 2
        self.body = nn.Sequential(*layers)
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Linear(cin * side * side, config.hidden),
            nn.ReLU(inplace=True),
            nn.Linear(config.hidden, 3),
        )
        self.half = config.roi / 2

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.head(self.body(x))
        return torch.tanh(out[:, :2]) * self.half, out[:, 2]


def history_channel(history: torch.Tensor, roi: int) -> torch.Tensor:
    """(B, K, 2) vertices (last = the ROI centre) -> (B, 1, roi, roi): 1 within 1 px of their
    polyline, fading to 0 at 2 px. Pixels are placed as in ``crop_rois``."""
    rel = history - history[:, -1:]
    offsets = torch.arange(roi, device=history.device, dtype=history.dtype) - (roi - 1) / 2
    gy, gx = torch.meshgrid(offsets, offsets, indexing="ij")
    p = torch.stack([gx, gy], -1).reshape(1, -1, 1, 2)
    a, ab = rel[:, None, :-1], (rel[:, 1:] - rel[:, :-1])[:, None]
    t = (((p - a) * ab).sum(-1) / (ab * ab).sum(-1).clamp(min=1e-9)).clamp(0, 1)
    d = (p - a - t[..., None] * ab).norm(dim=-1).amin(-1)
    return (2 - d).clamp(0, 1).reshape(-1, 1, roi, roi)


def agent_input(tensor: torch.Tensor, history: torch.Tensor, roi: int) -> torch.Tensor:
    """The window tensor (5, H, W: bands, segmentation) and histories (B, K, 2) -> (B, 6, roi, roi)."""
    return torch.cat([crop_rois(tensor, history[:, -1], roi), history_channel(history, roi)], dim=1)
