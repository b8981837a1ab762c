"""Training runs end to end on tiny cities, logs and checkpoints, and resumes exactly."""

from __future__ import annotations

import json

import pytest
import torch

from csboundary.models.checkpoint import load_checkpoint
from csboundary.models.training.afanet import train_afanet
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.fpn import train_fpn

TINY_FPN = {"widths": [8, 8, 8, 8], "blocks": [1, 1, 1, 1], "pyramid": 8, "stem": 8}
TINY_AFANET = {"global_size": 32, "roi": 16, "encoder_widths": [8, 8], "dim": 32, "layers": 1}


def config(tmp_path, **overrides) -> TrainConfig:
    base = {
        "cache": str(tmp_path / "cities"),
        "train_city": {"split": "train", "seed": 2, "tiles": [1, 1], "tile_size": 400},
        "valid_city": {"split": "valid", "seed": 2, "tiles": [1, 1], "tile_size": 400},
        "steps": 4,
        "validate_every": 2,
        "validation_samples": 1,
        "crop": 64,
        "batch": 2,
        "fpn": TINY_FPN,
    }
    base.update(overrides)
    return TrainConfig.from_dict(base)


@pytest.fixture(scope="module")
def fpn_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fpn")
    return tmp, train_fpn(config(tmp), tmp / "run", torch.device("cpu"), progress=False)


def test_fpn_run_writes_weights_log_and_validation(fpn_run):
    tmp, weights = fpn_run
    payload = load_checkpoint(weights, ("fpn",))
    assert payload["step"] == 4 and [v["step"] for v in payload["validation"]] == [2, 4]
    assert "optimizer" not in payload and payload["train_config"]["seed"] == 0
    events = [json.loads(line)["event"] for line in (tmp / "run" / "train.log").read_text().splitlines()]
    assert events == ["start", "validate", "validate", "done"]


def test_resumed_run_equals_uninterrupted_run(fpn_run, tmp_path):
    tmp, weights = fpn_run
    cfg = config(tmp, steps=2)
    train_fpn(cfg, tmp_path / "half", torch.device("cpu"), progress=False)
    resumed = train_fpn(
        config(tmp),
        tmp_path / "half",
        torch.device("cpu"),
        resume=str(tmp_path / "half" / "fpn-last.pt"),
        progress=False,
    )
    a, b = load_checkpoint(weights, ("fpn",))["fpn"], load_checkpoint(resumed, ("fpn",))["fpn"]
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_afanet_trains_on_fpn_maps(fpn_run, tmp_path):
    tmp, fpn_weights = fpn_run
    cfg = config(
        tmp,
        model="afanet",
        fpn_weights=str(fpn_weights),
        afanet=TINY_AFANET,
        window=200,
        gt_steps=2,
        steps=3,
        validate_every=3,
    )
    weights = train_afanet(cfg, tmp_path / "afa", torch.device("cpu"), progress=False)
    payload = load_checkpoint(weights, ("afanet",))
    assert payload["step"] == 3 and payload["train_config"]["fpn_weights"] == str(fpn_weights)
    validation = payload["validation"][-1]
    # scored on ground-truth vertices and on the FPN's (none found by this 4-step FPN: NaN loss there)
    assert validation["step"] == 3 and {"val_loss_gt", "val_edge_f1_gt", "val_loss_pred", "val_edge_f1_pred"} <= set(
        validation
    )
    assert 0 < validation["val_loss_gt"] < 10
    events = [json.loads(line)["event"] for line in (tmp_path / "afa" / "train.log").read_text().splitlines()]
    assert events == ["start", "validate", "done"]


def test_misspelt_model_option_is_an_error(tmp_path):
    with pytest.raises(ValueError, match="unknown FPNConfig option"):
        train_fpn(config(tmp_path, fpn={"width": [8, 8, 8, 8]}), tmp_path / "run", torch.device("cpu"), progress=False)


def test_pretrained_fpn_trains_with_augmentation_on_an_extra_city(tmp_path):
    """The shipped recipe in miniature: EfficientNet-Lite0 FPN, every augmentation, a synthetic
    city plus a city directory of the user's (here: the valid city standing in for one)."""
    from csboundary.models.training.data import CitySpec

    extra = CitySpec(split="valid", seed=3, tiles=(1, 1), tile_size=300).ensure(tmp_path / "cities")
    cfg = config(
        tmp_path,
        fpn={"backbone": "efficientnet-lite0"},
        augment={},
        extra_train_cities=[str(extra)],
        steps=2,
        crop=64,
        encoder_lr_scale=0.1,
        freeze_encoder_bn=True,
        style_mix=1.0,
    )
    weights = train_fpn(cfg, tmp_path / "run", torch.device("cpu"), progress=False)
    payload = load_checkpoint(weights, ("fpn",))
    assert payload["train_config"]["style_mix"] == 1.0 and not any(
        "style" in k for k in payload["fpn"]
    )  # stateless: nothing saved
    assert payload["fpn_config"]["backbone"] == "efficientnet-lite0"
    assert payload["train_config"]["extra_train_cities"] == [str(extra)]
    assert payload["code_version_at_start"]
    encoder_group, rest = load_checkpoint(tmp_path / "run" / "fpn-last.pt", ("fpn",))["optimizer"]["param_groups"]
    assert encoder_group["lr"] == pytest.approx(0.1 * rest["lr"])
    start = json.loads((tmp_path / "run" / "train.log").read_text().splitlines()[0])
    assert start["code_version"] == payload["code_version_at_start"]


def test_extra_city_that_is_not_a_city_is_an_error(tmp_path):
    from csboundary.errors import InputError

    cfg = config(tmp_path, extra_train_cities=[str(tmp_path)])
    with pytest.raises(InputError, match="not a city directory"):
        train_fpn(cfg, tmp_path / "run", torch.device("cpu"), progress=False)


def test_afanet_resumed_run_equals_uninterrupted_run(fpn_run, tmp_path):
    """AfANet trains on the shared loop, so it resumes exactly too (weights, optimizer, every
    random stream)."""
    tmp, fpn_weights = fpn_run
    # the whole 400 px city as the window and ground-truth vertices throughout: every step has edges to learn
    common = dict(
        model="afanet", fpn_weights=str(fpn_weights), afanet=TINY_AFANET, window=400, gt_steps=4, validate_every=2
    )
    whole = train_afanet(config(tmp, steps=4, **common), tmp_path / "whole", torch.device("cpu"), progress=False)
    logged = [json.loads(line) for line in (tmp_path / "whole" / "train.log").read_text().splitlines()]
    assert all(isinstance(e["train_loss"], float) and e["m"] >= 2 for e in logged if e["event"] == "validate")
    train_afanet(config(tmp, steps=2, **common), tmp_path / "half", torch.device("cpu"), progress=False)
    resumed = train_afanet(
        config(tmp, steps=4, **common),
        tmp_path / "half",
        torch.device("cpu"),
        resume=str(tmp_path / "half" / "afanet-last.pt"),
        progress=False,
    )
    a, b = load_checkpoint(whole, ("afanet",))["afanet"], load_checkpoint(resumed, ("afanet",))["afanet"]
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_fine_tuning_starts_from_the_trained_fpn_and_its_architecture(fpn_run, tmp_path):
    tmp, weights = fpn_run
    start = load_checkpoint(weights, ("fpn",))
    cfg = config(
        tmp, init_fpn=str(weights), steps=1, validate_every=1, lr=0.0, weight_decay=0.0, fpn={}
    )  # fpn {} would be the default FPN
    tuned = load_checkpoint(train_fpn(cfg, tmp_path / "tune", torch.device("cpu"), progress=False), ("fpn",))
    architecture = lambda c: {k: v for k, v in c.items() if k != "pretrained"}  # noqa: E731 (rebuilt from weights, not ImageNet)
    assert architecture(tuned["fpn_config"]) == architecture(start["fpn_config"])
    # lr 0: the weights are the trained ones (batch-norm running statistics move with the batch)
    assert all(
        torch.equal(start["fpn"][k], tuned["fpn"][k])
        for k in start["fpn"]
        if "running" not in k and "num_batches" not in k
    )
    first = json.loads((tmp_path / "tune" / "train.log").read_text().splitlines()[0])
    assert len(first["init_fpn_sha256"]) == 64


def test_a_surface_head_trained_alone_leaves_every_other_weight_and_statistic_as_it_was(fpn_run, tmp_path):
    tmp, weights = fpn_run
    start = load_checkpoint(weights, ("fpn",))
    cfg = config(tmp, init_fpn=str(weights), surface=True, surface_only=True, steps=3, validate_every=3, lr=0.01)
    tuned = load_checkpoint(train_fpn(cfg, tmp_path / "surface", torch.device("cpu"), progress=False), ("fpn",))
    assert tuned["fpn_config"]["surface"] is True
    assert all(torch.equal(start["fpn"][k], tuned["fpn"][k]) for k in start["fpn"])  # running statistics included
    head = [k for k in tuned["fpn"] if k.startswith("surface_head.")]
    assert head and set(tuned["fpn"]) == set(start["fpn"]) | set(head)
    validation = json.loads((tmp_path / "surface" / "train.log").read_text().splitlines()[-2])
    assert 0.0 <= validation["val_surface_iou"] <= 1.0

    from csboundary.models.checkpoint import load_fpn

    model = load_fpn(tmp_path / "surface" / "fpn.pt")
    assert model(torch.rand(1, 4, 64, 64)).shape == (1, 3, 64, 64)


def test_surface_only_without_a_surface_head_is_an_error(fpn_run, tmp_path):
    tmp, weights = fpn_run
    with pytest.raises(ValueError, match="surface head"):
        train_fpn(
            config(tmp, init_fpn=str(weights), surface_only=True), tmp_path / "x", torch.device("cpu"), progress=False
        )


def test_the_surface_loss_ignores_pixels_whose_surface_is_unknown():
    from csboundary.models.training.fpn import fpn_loss

    torch.manual_seed(0)
    logits, target = torch.randn(2, 3, 16, 16), torch.rand(2, 3, 16, 16)
    valid = torch.ones(2, 16, 16, dtype=torch.bool)
    cfg = TrainConfig()
    unknown = target.clone()
    unknown[:, 2] = -1
    assert fpn_loss(logits, unknown, valid, cfg).item() == pytest.approx(
        fpn_loss(logits[:, :2], target[:, :2], valid, cfg).item()
    )
    only = TrainConfig.from_dict({"surface_only": True})
    expected = torch.nn.functional.binary_cross_entropy_with_logits(logits[:, 2], target[:, 2]).item()
    assert fpn_loss(logits, target, valid, only).item() == pytest.approx(expected, rel=1e-5)


def test_a_surface_head_added_to_a_trained_fpn_keeps_its_recorded_architecture(tmp_path):
    from csboundary.models.checkpoint import save_checkpoint
    from csboundary.models.fpn import FPN, FPNConfig
    from csboundary.models.training.fpn import starting_fpn

    source = TrainConfig.from_dict({"fpn": {**TINY_FPN}})

    trained = FPNConfig.from_dict({**TINY_FPN, "pretrained": True})
    save_checkpoint(
        tmp_path / "fpn.pt",
        "fpn",
        fpn=FPN(trained).state_dict(),
        fpn_config=trained.to_dict(),
        train_config=source.to_dict(),
    )
    model, config = starting_fpn(
        TrainConfig.from_dict({"init_fpn": str(tmp_path / "fpn.pt"), "surface": True}), torch.device("cpu")
    )
    assert config.surface and config.pretrained  # as the trained FPN was recorded, plus the head
    assert hasattr(model, "surface_head")
