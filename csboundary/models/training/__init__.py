"""Training loops for the FPN and AfANet (paper V-B), nanoGPT-style: plain loops.

FPN: random crops of the train city, Adam (paper: lr 1e-3, decay 1e-4), BCE on the keypoint
heat and the segmentation with ``pos_weight`` against class imbalance (boundary pixels are ~3%
of a crop, keypoint peaks far fewer). AfANet: "we first pre-train the network with ground-truth
graph vertices, and then train AfANet with the graph vertices extracted from predicted keypoint
maps": stage ``gt`` then stage ``pred``, BCE on the adjacency label of each vertex set, positives
weighted by the negative/positive ratio (capped). Seeded; validation every N steps on the valid
city; checkpoints hold config, code version and validation metrics and resume exactly.

* :mod:`.config`: :class:`TrainConfig` (what a run depends on) and the cities it names.
* :mod:`.data`: training samples drawn from synthetic (or imported) cities.
* :mod:`.loop`: the loop every trainer shares (``optimize``), its log, checkpoints and resume.
* :mod:`.fpn`, :mod:`.afanet`: the two networks' losses, samples, validation and trainers.
"""
