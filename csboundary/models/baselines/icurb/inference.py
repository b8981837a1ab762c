"""Enhanced-iCurb at inference (:class:`Model`, a ``PatchModel``): csBoundary's FPN gives the
segmentation, its skeleton the starts, and the agent traces from them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from csboundary.data.units import MODEL_GSD
from csboundary.graph import BoundaryGraph
from csboundary.graph.settings import GraphSettings
from csboundary.models.baselines.icurb.agent import Agent
from csboundary.models.baselines.icurb.config import KIND, ICurbConfig
from csboundary.models.baselines.icurb.tracing import Traces, border_starts, rollout
from csboundary.models.checkpoint import load_checkpoint, load_fpn, restore_model, shipped_weights
from csboundary.models.fpn import FPN
from csboundary.models.maps import image_tensor, predict_probabilities


def segmentation_fpn(path: str | Path | None, device: torch.device) -> FPN:
    """csBoundary's FPN whose segmentation the agent reads, from an ``fpn`` checkpoint or a
    bundle (default: the shipped bundle)."""
    return load_fpn(path or shipped_weights(), device)


class Model:
    """Enhanced-iCurb as a :class:`~csboundary.models.patch_model.PatchModel`."""

    settings = GraphSettings()  # the city graph's steps all off
    confidence = None
    collect_evidence = False
    pixel_size_m = MODEL_GSD

    def __init__(self, agent: Agent, config: ICurbConfig, fpn: FPN, device: torch.device):
        self.agent, self.config, self.fpn, self.device = agent.eval(), config, fpn, device

    @classmethod
    def load(cls, path: str | Path, device: torch.device, seg_weights: str | Path | None = None) -> "Model":
        """The agent of an ``icurb`` checkpoint plus the FPN ``seg_weights`` (default: the one it
        was trained with, else the shipped bundle)."""
        payload = load_checkpoint(path, (KIND,), map_location=device)
        agent = restore_model(path, KIND, payload, lambda c: Agent(ICurbConfig.from_dict(c))).to(device)
        config = ICurbConfig.from_dict(payload[f"{KIND}_config"])
        return cls(
            agent,
            config,
            segmentation_fpn(seg_weights or payload["train_config"].get("fpn_weights") or None, device),
            device,
        )

    def patch_maps(self, patches: list, images: list[np.ndarray]) -> list[np.ndarray]:
        """(1, S, S) segmentation probability per patch (the FPN's channel 1)."""
        return [p[1:2] for p in predict_probabilities(self.fpn, np.stack(images), self.device)]

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        starts = border_starts(maps[0], self.config.seg_threshold, self.config.border_px)
        return BoundaryGraph(starts, vertex_kinds=["start"] * len(starts))

    @torch.no_grad()
    def connect(self, patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        """Trace from ``found``'s starts. Where the window reaches beyond the imagery (a mosaic
        edge: zero padding), the imagery's edge is the border instead: the starts are taken
        again on it and tracing stops there."""
        has = image.any(axis=0)
        rows, cols = np.flatnonzero(has.any(axis=1)), np.flatnonzero(has.any(axis=0))
        if len(rows) == 0:
            return Traces(np.zeros((0, 2))).graph()
        frame = (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
        starts = found.vertices
        if frame != (0, 0, image.shape[2], image.shape[1]):
            starts = border_starts(maps[0], self.config.seg_threshold, self.config.border_px, frame)
        seg = torch.from_numpy(np.ascontiguousarray(maps[:1], dtype=np.float32)).to(self.device)
        tensor = torch.cat([image_tensor(image, self.device), seg])
        return rollout(self.agent, tensor, starts, self.config, frame=frame)[0].graph()
