"""One config reader for every config: a misspelt key is refused, naming it; JSON lists become
the tuples the dataclasses hold; nested tables are built the same way."""

from __future__ import annotations

import pytest

from csboundary.config import config_from_dict
from csboundary.data.grid import GridConfig
from csboundary.data.synth.config import SynthConfig
from csboundary.labels.config import LabelConfig
from csboundary.models.afanet import AfANetConfig
from csboundary.models.augmentation import AugmentConfig
from csboundary.models.baselines.icurb import ICurbConfig
from csboundary.models.baselines.orientation_refine import Options as OrientationOptions
from csboundary.models.baselines.sat2graph import Sat2GraphOptions
from csboundary.models.fpn import FPNConfig
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.data import CitySpec, WorldsConfig

CONFIGS = [
    FPNConfig,
    AfANetConfig,
    AugmentConfig,
    LabelConfig,
    SynthConfig,
    WorldsConfig,
    TrainConfig,
    ICurbConfig,
    Sat2GraphOptions,
    OrientationOptions,
]


@pytest.mark.parametrize("cls", CONFIGS, ids=lambda c: c.__name__)
def test_a_misspelt_key_is_refused_by_every_config(cls):
    with pytest.raises(ValueError, match="unknown .*option.*: widht"):
        cls.from_dict({"widht": 3})


@pytest.mark.parametrize("cls", CONFIGS, ids=lambda c: c.__name__)
def test_every_config_round_trips_through_json(cls):
    import dataclasses
    import json

    default = cls()
    assert cls.from_dict(json.loads(json.dumps(dataclasses.asdict(default)))) == default


def test_lists_become_tuples_and_nested_tables_are_built():
    labels = config_from_dict(LabelConfig, {"grid": {"core": 500, "margin": 25}, "aux_spacing_px": 100})
    assert labels.grid == GridConfig(500, 25) and labels.aux_spacing_px == 100
    fpn = FPNConfig.from_dict({"widths": [8, 8, 8, 8]})
    assert fpn.widths == (8, 8, 8, 8)
    train = TrainConfig.from_dict({"valid_city": {"split": "valid", "seed": 1, "tiles": [1, 2], "tile_size": 400}})
    assert train.valid_city == CitySpec("valid", 1, (1, 2), 400)
    with pytest.raises(ValueError, match=r"unknown training.train_city option\(s\): sead"):
        TrainConfig.from_dict({"train_city": {"split": "train", "sead": 1}})
    with pytest.raises(ValueError, match="expected a table"):
        config_from_dict(FPNConfig, [1, 2])
