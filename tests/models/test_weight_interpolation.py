"""Weight interpolation between a fine-tuned FPN and the weights it started from."""

from __future__ import annotations

import pytest
import torch

from csboundary.errors import InputError
from csboundary.models.checkpoint import load_checkpoint, save_checkpoint
from csboundary.models.weight_interpolation import interpolate_fpn, interpolate_state_dicts


def test_the_ends_are_the_two_networks_and_the_middle_their_mean():
    start = {"w": torch.tensor([0.0, 2.0]), "bn.num_batches_tracked": torch.tensor(3)}
    tuned = {"w": torch.tensor([4.0, 6.0]), "bn.num_batches_tracked": torch.tensor(9)}
    assert torch.equal(interpolate_state_dicts(start, tuned, 0.0)["w"], start["w"])
    assert torch.equal(interpolate_state_dicts(start, tuned, 1.0)["w"], tuned["w"])
    half = interpolate_state_dicts(start, tuned, 0.5)
    assert torch.equal(half["w"], torch.tensor([2.0, 4.0]))
    assert torch.equal(interpolate_state_dicts(start, tuned, 0.25)["w"], torch.tensor([1.0, 3.0]))
    assert half["bn.num_batches_tracked"].item() == 9  # counts are not averaged


def test_networks_of_other_names_or_shapes_and_alpha_outside_0_1_are_refused():
    with pytest.raises(ValueError, match="differ"):
        interpolate_state_dicts({"a": torch.zeros(2)}, {"b": torch.zeros(2)}, 0.5)
    with pytest.raises(ValueError, match="shape"):
        interpolate_state_dicts({"a": torch.zeros(2)}, {"a": torch.zeros(3)}, 0.5)
    with pytest.raises(ValueError, match="alpha"):
        interpolate_state_dicts({"a": torch.zeros(2)}, {"a": torch.zeros(2)}, 1.5)


def test_an_interpolated_checkpoint_records_both_files_and_alpha(tmp_path):
    config = {"backbone": "resnet", "surface": False}
    save_checkpoint(tmp_path / "start.pt", "fpn", fpn={"w": torch.zeros(3)}, fpn_config=config)
    save_checkpoint(
        tmp_path / "tuned.pt", "fpn", fpn={"w": torch.ones(3)}, fpn_config=config, train_config={"seed": 0}, step=800
    )
    interpolate_fpn(tmp_path / "start.pt", tmp_path / "tuned.pt", 0.7, tmp_path / "mixed.pt")
    mixed = load_checkpoint(tmp_path / "mixed.pt", ("fpn",))
    assert torch.allclose(mixed["fpn"]["w"], torch.full((3,), 0.7))
    assert mixed["interpolation"]["alpha"] == 0.7 and len(mixed["interpolation"]["start_sha256"]) == 64
    assert mixed["step"] == 800 and mixed["train_config"] == {"seed": 0}
    save_checkpoint(tmp_path / "other.pt", "fpn", fpn={"w": torch.ones(3)}, fpn_config={**config, "surface": True})
    with pytest.raises(InputError, match="not built like"):
        interpolate_fpn(tmp_path / "start.pt", tmp_path / "other.pt", 0.5, tmp_path / "no.pt")
