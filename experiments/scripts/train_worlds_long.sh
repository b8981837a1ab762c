#!/bin/sh
# The longer style-mix schedule (FPN 5000 steps instead of 1500; AfANet on its maps). Run in the
# background at low priority from a pinned worktree so the recorded code version is clean:
#   nohup nice -n 19 sh experiments/scripts/train_worlds_long.sh > runs/worlds-long-queue.out 2>&1 &
set -e
cs="${CSBOUNDARY:-.venv/bin/csboundary}"
$cs train fpn --config experiments/configs/fpn-worlds-long.json --out runs/worlds-long-fpn --quiet
$cs train afanet --config experiments/configs/afanet-worlds-long.json --out runs/worlds-long-afanet --quiet
echo queue done
