"""Folding batch norms into convolutions: the same function in float32, no batch norm left,
the original untouched."""

from __future__ import annotations

import torch
from torch import nn

from csboundary.models.batchnorm_folding import fold_batch_norms
from csboundary.models.fpn import FPN, FPNConfig


def _with_statistics(model: nn.Module) -> nn.Module:
    """Batch norms with running statistics and affine parameters far from the identity."""
    generator = torch.Generator().manual_seed(3)
    for module in model.modules():
        if isinstance(module, nn.BatchNorm2d):
            n = module.num_features
            module.running_mean.copy_(torch.randn(n, generator=generator))
            module.running_var.copy_(torch.rand(n, generator=generator) * 3 + 0.1)
            module.weight.data.copy_(torch.randn(n, generator=generator))
            module.bias.data.copy_(torch.randn(n, generator=generator))
    return model.eval()


def test_a_folded_conv_norm_pair_computes_the_same_as_by_hand():
    conv = nn.Conv2d(2, 3, 3, padding=1, bias=False)
    model = _with_statistics(nn.Sequential(conv, nn.BatchNorm2d(3), nn.ReLU()))
    folded = fold_batch_norms(model)
    assert isinstance(folded[1], nn.Identity) and isinstance(model[1], nn.BatchNorm2d)  # the original keeps its norm
    x = torch.randn(1, 2, 8, 8)
    norm = model[1]
    by_hand = torch.relu(
        (conv(x) - norm.running_mean[:, None, None])
        / torch.sqrt(norm.running_var[:, None, None] + norm.eps)
        * norm.weight[:, None, None]
        + norm.bias[:, None, None]
    )
    with torch.no_grad():
        assert torch.allclose(folded(x), by_hand, atol=1e-5)


def test_a_folded_fpn_has_no_batch_norm_and_the_same_logits():
    torch.manual_seed(0)
    model = _with_statistics(FPN(FPNConfig(widths=(8, 16, 16, 16), pyramid=8, stem=8)))
    folded = fold_batch_norms(model)
    assert not any(isinstance(m, nn.BatchNorm2d) for m in folded.modules())
    assert sum(isinstance(m, nn.BatchNorm2d) for m in model.modules()) > 4
    x = torch.rand(2, 4, 64, 64)
    with torch.no_grad():
        expected, got = model(x), folded(x)
    assert torch.allclose(got, expected, atol=1e-4 * float(expected.abs().max()))
    assert not model.training and not folded.training
