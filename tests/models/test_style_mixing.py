"""Style mixing: statistics mixed between samples in training, content kept, identity otherwise."""

from __future__ import annotations

import pytest
import torch

from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.style_mixing import StyleMix, add_style_mixing


def _stats(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    return x.mean(dim=(2, 3)), x.std(dim=(2, 3), unbiased=False)


def test_mixed_statistics_lie_between_two_samples_and_the_content_is_kept():
    torch.manual_seed(0)
    # four samples whose channel statistics are far apart: means 0, 10, 20, 30, spreads 1..4
    x = torch.randn(4, 3, 16, 16) * torch.arange(1.0, 5.0).view(4, 1, 1, 1) + 10 * torch.arange(4.0).view(4, 1, 1, 1)
    mix = StyleMix(p=1.0, alpha=0.1).train()
    y = mix(x)
    mean_x, std_x = _stats(x)
    mean_y, std_y = _stats(y)
    assert mean_y.min() >= mean_x.min() - 1e-4 and mean_y.max() <= mean_x.max() + 1e-4
    assert std_y.min() >= std_x.min() * 0.99 and std_y.max() <= std_x.max() * 1.01
    content_x = (x - mean_x[..., None, None]) / std_x[..., None, None]
    content_y = (y - mean_y[..., None, None]) / std_y[..., None, None]
    torch.testing.assert_close(content_y, content_x, atol=1e-4, rtol=1e-4)
    assert not torch.allclose(y, x)  # with p = 1 and statistics this far apart, something moved


@pytest.mark.parametrize("setup", ["eval", "p0", "single"])
def test_style_mixing_is_the_identity_outside_training_at_p0_and_for_one_sample(setup):
    x = torch.randn(1 if setup == "single" else 3, 2, 8, 8)
    mix = StyleMix(p=0.0 if setup == "p0" else 1.0)
    mix.train(setup != "eval")
    assert torch.equal(mix(x), x)


def test_gradients_reach_the_input_through_the_content():
    x = torch.randn(2, 2, 8, 8, requires_grad=True)
    torch.manual_seed(1)
    y = StyleMix(p=1.0).train()(x)
    y.sum().backward()  # statistics detached: d y / d x = mixed std / own std, the same over H, W
    grad = x.grad
    assert torch.isfinite(grad).all() and (grad > 0).all()
    torch.testing.assert_close(grad, grad[..., :1, :1].expand_as(grad))


def test_an_fpn_with_style_mixing_has_the_same_state_and_the_same_outputs_in_eval():
    torch.manual_seed(0)
    fpn = FPN(FPNConfig(backbone="efficientnet-lite0", pretrained=False)).eval()
    keys = set(fpn.state_dict())
    image = torch.rand(1, 4, 64, 64)
    before = fpn(image)
    add_style_mixing(fpn, 1.0)
    assert set(fpn.state_dict()) == keys and isinstance(fpn.encoder.style_mix, StyleMix)
    assert torch.equal(fpn(image), before)


def test_style_mixing_needs_the_pretrained_encoder_and_a_valid_probability():
    with pytest.raises(ValueError, match="efficientnet-lite0"):
        add_style_mixing(FPN(FPNConfig(widths=(8, 8, 8, 8), blocks=(1, 1, 1, 1), pyramid=8, stem=8)), 0.5)
    with pytest.raises(ValueError, match="0 <= p <= 1"):
        StyleMix(p=1.5)
