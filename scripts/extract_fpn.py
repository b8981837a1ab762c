"""Extract a bundle's FPN as a float16 ``fpn`` checkpoint, keeping the bundle's provenance.

Usage: .venv/bin/python scripts/extract_fpn.py BUNDLE.pt DST.pt

Made csboundary/weights/ablation/fpn-first.pt from the first shipped bundle (commit 25ce974), the
FPN that Table IV's AfANets were trained on, so the ablation keeps running on its own FPN.
"""

import sys

import torch

src, dst = sys.argv[1:3]
bundle = torch.load(src, map_location="cpu", weights_only=False)
provenance = bundle["provenance"]["fpn"]
torch.save(
    {
        "format": bundle["format"],
        "kind": "fpn",
        "code_version": provenance["code_version"],
        "fpn": {k: v.half() if v.is_floating_point() else v for k, v in bundle["fpn"].items()},
        "fpn_config": bundle["fpn_config"],
        "train_config": provenance["train_config"],
        "step": provenance["step"],
        "validation": provenance["validation"],
        "stored_as": "float16",
        "extracted_from": src,
    },
    dst,
)
