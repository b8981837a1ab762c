"""DAgger imitation of the expert: the uint8 replay buffer of visited states, the window data
(tensor and expert), the imitation loss, validation by pure agent roll-outs, and ``train``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from csboundary.labels.boundaries import Boundary
from csboundary.labels.select import near_window
from csboundary.models.baselines.icurb.agent import Agent
from csboundary.models.baselines.icurb.config import KIND, ICurbConfig, split_options
from csboundary.models.baselines.icurb.expert import Expert
from csboundary.models.baselines.icurb.inference import segmentation_fpn
from csboundary.models.baselines.icurb.tracing import rollout
from csboundary.models.maps import predict_mosaic_maps, unit_bands
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.data import TrainingCity
from csboundary.models.training.loop import RunLog, TrainingRun, optimize, seed_everything


class ReplayBuffer:
    """Aggregated DAgger states in a ring: inputs as uint8, expert offsets and stops."""

    def __init__(self, capacity: int, roi: int):
        self.x = torch.zeros((capacity, 6, roi, roi), dtype=torch.uint8)
        self.offset, self.stop = np.zeros((capacity, 2), np.float32), np.zeros(capacity, np.float32)
        self.size = self.head = 0

    def add(self, x: torch.Tensor, offset: np.ndarray, stop: np.ndarray) -> None:
        index = (self.head + np.arange(len(x))) % len(self.x)
        self.x[torch.from_numpy(index)] = (x.cpu() * 255).round().clamp(0, 255).to(torch.uint8)
        self.offset[index], self.stop[index] = offset, stop
        self.head = int(index[-1] + 1) % len(self.x) if len(x) else self.head
        self.size = min(self.size + len(x), len(self.x))

    def batch(self, index: np.ndarray, device: torch.device):
        return (
            self.x[torch.from_numpy(index)].to(device).float() / 255,
            torch.from_numpy(self.offset[index]).to(device),
            torch.from_numpy(self.stop[index]).to(device),
        )


def _window_data(city: TrainingCity, window, config: ICurbConfig, device: torch.device):
    """The window's tensor (bands, FPN segmentation) and its expert."""
    seg = np.zeros((1, window.height, window.width), np.float32)
    part = window.intersection(city.mosaic.window)
    if part is not None:
        (rows, cols), (lrows, lcols) = part.slices(), part.relative_to(window).slices()
        seg[0, lrows, lcols] = city.maps[rows, cols]
    tensor = torch.from_numpy(np.concatenate([unit_bands(city.mosaic.read(window).data), seg])).to(device)
    offset = np.array([window.col_off, window.row_off], float)
    tracks = [
        Boundary(city.labels.boundaries[k].points - offset, city.labels.boundaries[k].closed)
        for k in near_window(city.labels.bounds, window, pad=config.step_px)
    ]
    return tensor, Expert(tracks, (window.width, window.height), config.step_px)


def _imitation_loss(agent: Agent, x, offset, stop, stop_pos_weight: float) -> torch.Tensor:
    pred, logit = agent(x)
    target = (offset / agent.half).clamp(-1, 1)
    weight = torch.tensor(stop_pos_weight, device=x.device)
    return F.mse_loss(pred / agent.half, target) + F.binary_cross_entropy_with_logits(logit, stop, pos_weight=weight)


@torch.no_grad()
def validate(agent: Agent, city: TrainingCity, windows, config: ICurbConfig, opts: dict, device) -> dict[str, float]:
    """Pure agent roll-outs (beta = 0) from the ground-truth starts of fixed valid windows: the
    loss and the offset error against the expert on the visited states, and the drift (mean
    distance of the traced vertices to the ground truth)."""
    agent.eval()
    losses, errors, drift = [], [], []
    for window in windows:
        tensor, expert = _window_data(city, window, config, device)
        if starts := expert.starts():
            traces, records = rollout(
                agent,
                tensor,
                np.array([s[0] for s in starts]),
                config,
                expert.teacher(starts),
                0.0,
                np.random.default_rng(0),
            )
            for x, offset, stop in records:
                x, offset, stop = x.to(device), torch.from_numpy(offset).to(device), torch.from_numpy(stop).to(device)
                losses.append(float(_imitation_loss(agent, x, offset, stop, opts["stop_pos_weight"])))
                errors += (agent(x)[0] - offset).norm(dim=1).tolist()
            drift += [expert.nearest(p)[2] for p in traces.points]
    return {
        f"val_{k}": float(np.mean(v)) if v else float("nan")
        for k, v in (("loss", losses), ("offset_px", errors), ("drift_px", drift))
    }


def train(
    config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True
) -> Path:
    """DAgger imitation of the expert on the train city (see the module docstring)."""
    seed_everything(config.seed)
    out_dir = Path(out_dir)
    log = RunLog(out_dir / "train.log")
    model_config, opts = split_options(config.options)
    fpn = segmentation_fpn(config.fpn_weights or None, device)
    cities = {}
    for name, spec in (("train", config.train_city), ("valid", config.valid_city)):
        city = TrainingCity(spec.ensure(config.cache))
        city.maps = predict_mosaic_maps(fpn, city.mosaic, city.labels.grid, device, progress)[
            1
        ].copy()  # segmentation only
        cities[name] = city
    del fpn
    agent = Agent(model_config).to(device)
    optimizer = torch.optim.Adam(agent.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_windows = [cities["valid"].random_window(valid_rng, opts["window"]) for _ in range(config.validation_samples)]
    rng = np.random.default_rng(config.seed)
    run = TrainingRun(KIND, agent, model_config, config, out_dir, optimizer, rng, log).resumed(resume)
    buffer = ReplayBuffer(opts["buffer"], model_config.roi)  # not checkpointed: rebuilt after a resume
    log.write(
        event="start",
        model=KIND,
        step=run.step,
        parameters=sum(p.numel() for p in agent.parameters()),
        config=config.to_dict(),
    )

    def loss_at(step: int):
        beta = max(opts["beta_min"], 1 - (1 - opts["beta_min"]) * step / max(1.0, opts["beta_decay"] * config.steps))
        for attempt in range(200):
            if buffer.size >= opts["batch"] and (attempt > 0 or step % opts["rollout_every"]):
                break
            tensor, expert = _window_data(
                cities["train"], cities["train"].random_window(rng, opts["window"]), model_config, device
            )
            starts = expert.starts()
            if starts:
                agent.eval()
                _, records = rollout(
                    agent, tensor, np.array([s[0] for s in starts]), model_config, expert.teacher(starts), beta, rng
                )
                for record in records:
                    buffer.add(*record)
        else:
            raise RuntimeError("no ground-truth boundary crosses the training windows")
        agent.train()
        x, offset, stop = buffer.batch(rng.integers(0, buffer.size, opts["batch"]), device)
        return _imitation_loss(agent, x, offset, stop, opts["stop_pos_weight"]), {"beta": beta, "buffer": buffer.size}

    return optimize(
        run, loss_at, lambda step: validate(agent, cities["valid"], valid_windows, model_config, opts, device), progress
    )
