"""The feature distance to the ImageNet encoder: its value by hand, zero for an encoder that has
not moved, positive once it has, and only in training."""

import pytest
import torch

from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.training.feature_distance import FeatureAnchor, feature_distance


def test_feature_distance_is_the_mean_euclidean_distance_per_pixel():
    a = torch.zeros(1, 2, 2, 2)
    b = torch.zeros(1, 2, 2, 2)
    b[0, 0], b[0, 1] = 3.0, 4.0  # every pixel 5 away
    b[0, :, 1, 1] = 0.0  # but one, at 0
    assert float(feature_distance(a, b)) == pytest.approx(15 / 4, abs=1e-5)


@pytest.fixture(scope="module")
def lite_fpn():
    torch.manual_seed(0)
    return FPN(FPNConfig(backbone="efficientnet-lite0", pretrained=True))


def test_an_unmoved_encoder_is_at_distance_zero_and_a_moved_one_is_not(lite_fpn):
    anchor = FeatureAnchor(lite_fpn)
    image = torch.rand(2, 4, 128, 128)
    try:
        lite_fpn.train()
        lite_fpn(image)
        assert float(anchor.take()) < 1e-4
        with torch.no_grad():
            weight = lite_fpn.encoder.stages[-1][0].project[0].weight
            weight.add_(torch.randn_like(weight) * weight.std())  # (a scale alone the batch norm after it undoes)
        logits = lite_fpn(image)
        distance = anchor.take()
        assert float(distance) > 0.1
        (logits.mean() + distance).backward()  # the distance reaches the encoder's weights
        assert lite_fpn.encoder.stages[-1][0].project[0].weight.grad.abs().sum() > 0
        lite_fpn.eval()
        with torch.no_grad():
            lite_fpn(image)
        with pytest.raises(RuntimeError):  # validation passes add nothing
            anchor.take()
    finally:
        anchor.close()


def test_the_from_scratch_fpn_has_no_encoder_to_anchor():
    with pytest.raises(ValueError, match="pretrained encoder"):
        FeatureAnchor(FPN(FPNConfig()))
