#!/bin/sh
# The style-mix training runs of docs/styles.md, one after the other (2 CPU cores cannot run two):
# the shipped all-style model, then one model per left-out major style. Run in the background:
#   nohup sh experiments/scripts/train_worlds.sh > runs/worlds-queue.out 2>&1 &
set -e
cs=".venv/bin/csboundary"
$cs train fpn --config experiments/configs/fpn-worlds.json --out runs/worlds-fpn --quiet
$cs train afanet --config experiments/configs/afanet-worlds.json --out runs/worlds-afanet --quiet
for style in grid downtown suburb rural; do
    $cs train fpn --config experiments/configs/loso/fpn-without-$style.json --out runs/loso-$style-fpn --quiet
    $cs train afanet --config experiments/configs/loso/afanet-without-$style.json --out runs/loso-$style-afanet --quiet
done
echo queue done
