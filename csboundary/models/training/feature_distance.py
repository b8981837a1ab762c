"""The feature distance to the ImageNet encoder (Hoyer et al. 2022, DAFormer): a training term
that keeps a pretrained FPN encoder's bottleneck features close to those of the frozen ImageNet
encoder on the same input.

Why: the ImageNet features are what carry a model trained on synthetic cities to photographs,
and training on synthetic textures pulls them away. Freezing the encoder's batch norm kept them
but cost the synthetic cities; this term lets the encoder move where the task needs it and pays
for every drift elsewhere."""

from __future__ import annotations

import torch
from torch import nn

from csboundary.models.efficientnet_lite import pretrained_lite


def feature_distance(features: torch.Tensor, reference: torch.Tensor) -> torch.Tensor:
    """Mean over pixels of the Euclidean distance between two (B, C, H, W) feature maps."""
    return (features - reference).pow(2).sum(dim=1).add(1e-12).sqrt().mean()


class FeatureAnchor:
    """Watches ``model.encoder`` (a :class:`~csboundary.models.fpn.LiteFPN`'s): on every forward
    pass in training mode it runs the frozen ImageNet encoder on the same input and keeps the
    distance of the bottleneck (stride 32) features, for :meth:`take` to add to the loss."""

    def __init__(self, model: nn.Module):
        encoder = getattr(model, "encoder", None)
        if encoder is None:
            raise ValueError("the feature distance needs a pretrained encoder: an efficientnet-lite backbone")
        device = next(encoder.parameters()).device
        # in training mode, as the watched encoder: both normalise by the batch's statistics, so an
        # encoder that has not moved is at distance 0 (its running statistics are never used here)
        self.reference = pretrained_lite(encoder.in_channels, encoder.variant).to(device).train()
        for parameter in self.reference.parameters():
            parameter.requires_grad_(False)
        self.distance: torch.Tensor | None = None
        self._handle = encoder.register_forward_hook(self._watch)

    def _watch(self, module: nn.Module, args: tuple, output: list[torch.Tensor]) -> None:
        if not module.training:
            return
        with torch.no_grad():
            reference = self.reference(args[0].float())[-1]
        self.distance = feature_distance(output[-1].float(), reference)

    def take(self) -> torch.Tensor:
        """The distance of the last training forward pass (then forgotten)."""
        if self.distance is None:
            raise RuntimeError("no training forward pass of the encoder since the last take()")
        distance, self.distance = self.distance, None
        return distance

    def close(self) -> None:
        self._handle.remove()
