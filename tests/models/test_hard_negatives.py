"""Hard negatives in FPN training: negatives on the image's outlines, away from true boundaries,
weigh more in the loss."""

from __future__ import annotations

import pytest
import torch

from csboundary.models.training.config import TrainConfig
from csboundary.models.training.fpn import fpn_loss, hard_negative_weights, image_edges


def step_image(column: int = 32, size: int = 64) -> torch.Tensor:
    image = torch.zeros(1, 4, size, size)
    image[..., column:] = 1.0  # a roof edge: dark to bright at ``column``
    image[0, :, :, column:] += 0.01 * torch.arange(size - column)  # faint texture, so the 95th percentile is the edge
    return image


def test_image_edges_are_one_on_outlines_and_small_on_texture():
    image = torch.zeros(1, 4, 64, 64)
    for left in range(8, 64, 16):
        image[..., left : left + 8] = 1.0  # roofs 8 px wide, 8 px apart: outlines on a sixth of the pixels
    image += 0.002 * torch.arange(64)  # faint texture
    edges = image_edges(image)
    # The rising outlines (columns 7, 8, 23, 24, ...) all have a Sobel magnitude of 4.016, up to the
    # last bit of float32, and the 95th percentile falls among them: whether a given one reaches the
    # clip at exactly 1 depends on how the CPU's conv kernel rounds (here columns 7 and 8 come out one
    # ulp apart). Within 1e-3 of 1 holds on any CPU, and still tells them from the falling outlines
    # (0.992) and the texture (0.004).
    assert edges[0, 0, 10, 7].item() == pytest.approx(1.0, abs=1e-3) and edges[0, 0, 10, 8].item() == pytest.approx(
        1.0, abs=1e-3
    )
    assert edges[0, 0, 10, 3] < 0.01 and edges[0, 0, 10, 12] < 0.01


def test_an_outline_far_from_a_boundary_weighs_more_and_one_beside_a_boundary_does_not():
    config = TrainConfig(hard_negative_weight=4.0, hard_negative_margin_px=6)
    target = torch.zeros(1, 2, 64, 64)
    weights = hard_negative_weights(step_image(), target, config)
    assert weights[0, 0, 10, 32] == 5.0 and weights[0, 0, 10, 10] == 1.0
    target[:, 1, :, 26] = 1.0  # a true boundary 6 px from the outline: within the margin
    assert hard_negative_weights(step_image(), target, config)[0, 0, 10, 32] == 1.0
    target[:, 1] = 0.0
    target[:, 1, :, 25] = 1.0  # 7 px away: outside it
    assert hard_negative_weights(step_image(), target, config)[0, 0, 10, 32] == 5.0


def test_the_loss_of_firing_on_an_outline_grows_with_the_weight_and_is_unchanged_when_off():
    image, target, valid = step_image(), torch.zeros(1, 2, 64, 64), torch.ones(1, 64, 64, dtype=torch.bool)
    logits = torch.full((1, 2, 64, 64), -4.0)
    logits[..., 31:33] = 4.0  # the network fires on the roof edge
    plain = fpn_loss(logits, target, valid, TrainConfig())
    assert fpn_loss(logits, target, valid, TrainConfig(), image) == plain  # weight 0: the image is not read
    hard = fpn_loss(logits, target, valid, TrainConfig(hard_negative_weight=4.0), image)
    # the two fired columns are the loss's bulk; their weight goes from 1 to 5
    assert 4.0 < float(hard / plain) < 5.0
