"""Store a checkpoint's model weights as float16 (inference loads them back into float32 parameters).

Usage: .venv/bin/python experiments/scripts/half_weights.py SRC.pt DST.pt KIND   (KIND: the state dict key, e.g. afanet)
"""

import sys

import torch

src, dst, kind = sys.argv[1:4]
payload = torch.load(src, map_location="cpu", weights_only=False)
payload[kind] = {k: v.half() if v.is_floating_point() else v for k, v in payload[kind].items()}
payload["stored_as"] = "float16"
torch.save(payload, dst)
