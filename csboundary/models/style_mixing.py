"""Feature-statistics mixing (MixStyle, Zhou et al., ICLR 2021): a training-only regulariser
against the look of the training imagery.

Why: the FPN is trained on synthetic cities only, and real photographs differ from them mostly
in "style" (colour, contrast, texture statistics), which early convolutional layers carry in the
per-channel mean and standard deviation of their feature maps. Mixing those statistics between
the samples of a batch (each from a random city, often of another style) shows the network the
same layout under looks no city of the generator has, so it learns the boundaries, not the
generator's rendering. At inference the module is the identity: the exported network, its
weights and its outputs are unchanged.
"""

from __future__ import annotations

import torch
from torch import nn


class StyleMix(nn.Module):
    """With probability ``p`` per batch, replace each sample's per-channel feature mean and
    standard deviation (over H, W) by a mix ``lam * own + (1 - lam) * other's`` with a random
    other sample of the batch and ``lam ~ Beta(alpha, alpha)`` per sample. Identity when not
    training, when ``p`` is 0 or for a batch of one. The statistics are detached, as in the
    paper: gradients flow through the normalised content only."""

    def __init__(self, p: float = 0.5, alpha: float = 0.1, eps: float = 1e-6):
        super().__init__()
        if not 0.0 <= p <= 1.0 or alpha <= 0:
            raise ValueError(f"style mixing needs 0 <= p <= 1 and alpha > 0, got p={p}, alpha={alpha}")
        self.p, self.alpha, self.eps = p, alpha, eps

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        batch = x.shape[0]
        if not self.training or self.p == 0 or batch < 2 or float(torch.rand(())) >= self.p:
            return x
        mean = x.mean(dim=(2, 3), keepdim=True).detach()
        std = (x.var(dim=(2, 3), keepdim=True) + self.eps).sqrt().detach()
        content = (x - mean) / std
        lam = torch.distributions.Beta(self.alpha, self.alpha).sample((batch, 1, 1, 1)).to(x)
        other = torch.randperm(batch, device=x.device)
        return content * (lam * std + (1 - lam) * std[other]) + (lam * mean + (1 - lam) * mean[other])


def add_style_mixing(model: nn.Module, p: float, alpha: float = 0.1) -> None:
    """Give a pretrained-encoder FPN (``model.encoder.style_mix``) style mixing after the
    encoder's early stages; no-op for ``p`` 0. Not saved: a module without state."""
    encoder = getattr(model, "encoder", None)
    if p <= 0:
        return
    if encoder is None or not hasattr(encoder, "style_mix"):
        raise ValueError("style mixing needs the efficientnet-lite0 backbone")
    encoder.style_mix = StyleMix(p, alpha)
