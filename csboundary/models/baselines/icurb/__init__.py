"""Enhanced-iCurb (Xu et al. 2021), the paper's iterative-graph-growing baseline (Section V-D).

An agent grows every road boundary vertex by vertex: from a start on the window border it looks
at an ``roi`` x ``roi`` window centred on its current vertex and predicts the next vertex (an
offset) and whether to stop. "Enhanced": besides the 4 image bands the ROI holds a segmentation
probability map, here csBoundary's own FPN (channel 1), so the baseline sees the same evidence.

Choices where the iCurb paper is not specific:

* A history channel draws the last ``history`` accepted vertices as a ~2 px polyline into the
  ROI (without it the agent cannot tell where it came from). The network is a small stride-2
  conv stack, flattened rather than pooled so the head knows where things are in the ROI.
* Expert (:class:`Expert`): project the current vertex onto the nearest ground-truth segment,
  orient the boundary to agree with the travel direction, and go ``step_px`` further along it;
  the target is cut short, with stop, where the boundary ends, leaves the window, or (a closed
  ring) comes back to the episode's start.
* Starts: at training, ground-truth crossings of the window border, heading inwards; at
  inference, where the skeleton of the thresholded segmentation meets the border (iCurb starts
  from predicted boundary ends on the image border); at a mosaic edge the imagery's edge is the
  border. Boundaries lying wholly inside a window are therefore never traced, as in iCurb.
* Tracing stops on the stop flag, on leaving the window (the vertex is clipped to the border),
  after ``max_steps``, or on coming within ``step_px / 2`` of an already traced polyline, which
  is then joined (its segment split at the foot point); when two heads meet both end.
* DAgger: an episode rolls every start of a random window out at once, taking the expert's
  action with probability beta (1 -> ``beta_min``) and the agent's otherwise, and labels every
  visited state with the expert's action. States are aggregated in a uint8 ring buffer (inputs
  are 8-bit imagery and probabilities anyway) and batches are drawn from it: MSE on offsets in
  units of roi / 2, BCE on stop (``stop_pos_weight``: about one state in 25 is a stop).
* Resume restores weights, optimizer and every random stream (``resume_run``), but the buffer
  is not checkpointed (hundreds of MB): it is rebuilt by fresh roll-outs, so a resumed run is
  not bit-identical to an uninterrupted one.

Modules, one job each: :mod:`.config` (the agent's settings and the training options),
:mod:`.agent` (the network and its input), :mod:`.geometry` (box and segment helpers),
:mod:`.expert` (the demonstrator), :mod:`.tracing` (roll-outs and start vertices),
:mod:`.inference` (:class:`Model`) and :mod:`.training` (DAgger, ``train``).
"""

from __future__ import annotations

from csboundary.models.baselines.icurb.agent import Agent, history_channel
from csboundary.models.baselines.icurb.config import KIND, TRAIN_OPTIONS, ICurbConfig, split_options
from csboundary.models.baselines.icurb.expert import Expert
from csboundary.models.baselines.icurb.inference import Model
from csboundary.models.baselines.icurb.tracing import Traces, border_starts, clip_step, rollout
from csboundary.models.baselines.icurb.training import train

__all__ = [
    "KIND",
    "TRAIN_OPTIONS",
    "Agent",
    "Expert",
    "ICurbConfig",
    "Model",
    "Traces",
    "border_starts",
    "clip_step",
    "history_channel",
    "rollout",
    "split_options",
    "train",
]
