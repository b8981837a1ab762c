"""The agent's settings (:class:`ICurbConfig`, stored in the checkpoint) and the training-only
options, split from a training config's ``options``."""

from __future__ import annotations

from dataclasses import dataclass

from csboundary.config import Config
from csboundary.errors import reject_unknown

KIND = "icurb"
# training-only options (TrainConfig.options); the rest of the options are ICurbConfig fields
TRAIN_OPTIONS = {
    "window": 512,
    "beta_min": 0.1,
    "beta_decay": 0.5,
    "buffer": 8000,
    "batch": 64,
    "rollout_every": 2,
    "stop_pos_weight": 5.0,
}


@dataclass(frozen=True)
class ICurbConfig(Config):
    """The agent and how it traces (stored in the checkpoint: inference needs all of it)."""

    config_name = "icurb"

    roi: int = 64
    widths: tuple[int, ...] = (16, 32, 64, 64)  # stride-2 conv stages
    hidden: int = 256
    history: int = 5  # vertices drawn into the history channel (>= 2)
    step_px: float = 20.0
    max_steps: int = 150
    seg_threshold: float = 0.5
    border_px: int = 4  # skeleton pixels this close to the window border give start vertices


def split_options(options: dict) -> tuple[ICurbConfig, dict]:
    """TrainConfig.options -> (agent config, training options); a misspelt key is an error."""
    reject_unknown(options, {*ICurbConfig.__dataclass_fields__, *TRAIN_OPTIONS}, "icurb")
    return ICurbConfig.from_dict({k: v for k, v in options.items() if k not in TRAIN_OPTIONS}), {
        k: options.get(k, v) for k, v in TRAIN_OPTIONS.items()
    }
