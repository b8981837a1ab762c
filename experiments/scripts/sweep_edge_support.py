"""Scores of one weights bundle on validation sets for a grid of edge-support settings.

    python experiments/scripts/sweep_edge_support.py WEIGHTS SET_OR_CITY... [--support 0,0.2,0.3] [--length 0,300] [--gap 0,40]
    [--vertex-threshold 0.35,0.5] [--fill 0,40] [--surface 0,0.5 --surface-weak 0.2] [--fragments 0,240]
    [--attach-backed 0,60,100] [--gate 0,8] [--both-sides 0,0.7]

Every setting not given is the bundle's own, so ``--vertex-threshold 0.4`` alone scores the
bundle as shipped but for its vertex threshold.

Each SET is a folder of cities (``csboundary import-masks``) scored with ``evaluate-set``'s mean,
or one city directory scored at city scale. Prints one row per setting (F1@5, APLS, TLTS per
set): the measurement behind the shipped ``min_support`` / ``max_length_px`` / ``max_gap_px`` and
the vertex-threshold probes of the model card (docs/real-imagery.md, csboundary/weights/README.md).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import torch

from csboundary.data import city_layout
from csboundary.pipeline.evaluation.evaluate_set import evaluate_set
from csboundary.pipeline.prediction.city_scores import evaluate_city_dir
from csboundary.pipeline.prediction.patch import PatchPredictor


def score_row(sets: list[str], predictor: PatchPredictor) -> list[str]:
    """ "F1@5/APLS/TLTS" of ``predictor`` on each set (a set's mean) or city (city scale)."""
    row = []
    for s in sets:
        m = (
            evaluate_city_dir(Path(s), predictor)["metrics"]
            if city_layout.is_city_dir(s)
            else evaluate_set(s, predictor, progress=False)["mean"]
        )
        row.append(f"{m['f1@5']:.3f}/{m['apls']:.3f}/{m['tlts']:.3f}")
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("sets", nargs="+")
    parser.add_argument("--support", default="", help="mean boundary probability along an edge (default: the bundle's)")
    parser.add_argument("--length", default="", help="longest edge, px, 0 = no limit (default: the bundle's)")
    parser.add_argument(
        "--gap", default="", help="longest stretch below the gap level, px, 0 = no check (default: the bundle's)"
    )
    parser.add_argument(
        "--gap-level",
        type=float,
        default=None,
        help="boundary probability below which a sample is a gap (default: the bundle's)",
    )
    parser.add_argument(
        "--vertex-threshold", default="", help="keypoint probability of vertex extraction (default: the bundle's)"
    )
    parser.add_argument("--edge-threshold", default="", help="AfANet edge probability (default: the bundle's)")
    parser.add_argument("--crossings", type=int, default=0, help="grid-crossing vertices every N px (0 = off)")
    parser.add_argument(
        "--fill-cover",
        type=float,
        default=None,
        help="distance at which an edge covers the skeleton, px (default: FillConfig's)",
    )
    parser.add_argument(
        "--fill-snap",
        type=float,
        default=None,
        help="distance at which a filled end joins a vertex, px (default: FillConfig's)",
    )
    parser.add_argument(
        "--fill-threshold",
        type=float,
        default=None,
        help="boundary probability of the filled skeleton (default: FillConfig's)",
    )
    parser.add_argument(
        "--fill", default="", help="shortest uncovered skeleton stretch filled in, px, 0 = off (default: the bundle's)"
    )
    parser.add_argument(
        "--surface",
        default="",
        help="surface check: sure level of roadway beside an edge, 0 = off (default: the bundle's)",
    )
    parser.add_argument(
        "--surface-weak", default="", help="surface check: floor below which an edge goes (default: the bundle's)"
    )
    parser.add_argument(
        "--surface-offset",
        type=float,
        default=None,
        help="surface check: distance beside an edge, px (default: the bundle's)",
    )
    parser.add_argument(
        "--join", default="", help="longest join between two dangling ends, px, 0 = off (default: the bundle's)"
    )
    parser.add_argument(
        "--fragments",
        default="",
        help="shortest connected piece of the city graph kept, px, 0 = keep all (default: the bundle's)",
    )
    parser.add_argument(
        "--attach-backed",
        default="",
        help="farthest line ahead a dangling end joins over backed boundary, px, 0 = off (default: the bundle's)",
    )
    parser.add_argument("--gate", default="", help="surface gate radius, px, 0 = off (default: the bundle's)")
    parser.add_argument(
        "--both-sides",
        default="",
        help="surface check: poorer-side roadway at which an edge is inside the roadway, 0 = off (default: the bundle's)",
    )
    parser.add_argument(
        "--join-support",
        type=float,
        default=None,
        help="mean boundary probability along a join (default: EndJoinConfig's)",
    )
    parser.add_argument(
        "--join-gap",
        type=float,
        default=None,
        help="longest stretch of a join below its gap level, px (default: EndJoinConfig's)",
    )
    parser.add_argument(
        "--join-turn",
        type=float,
        default=None,
        help="largest turn from an end's heading, degrees (default: EndJoinConfig's)",
    )
    args = parser.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    predictor.settings = dataclasses.replace(
        predictor.settings, crossings=dataclasses.replace(predictor.settings.crossings, spacing_px=args.crossings)
    )
    for name, value in (("cover_px", args.fill_cover), ("snap_px", args.fill_snap), ("threshold", args.fill_threshold)):
        if value is not None:
            predictor.settings = dataclasses.replace(
                predictor.settings, fill=dataclasses.replace(predictor.settings.fill, **{name: value})
            )
    for name, value in (
        ("min_support", args.join_support),
        ("max_turn_deg", args.join_turn),
        ("max_gap_px", args.join_gap),
    ):
        if value is not None:
            predictor.settings = dataclasses.replace(
                predictor.settings, join=dataclasses.replace(predictor.settings.join, **{name: value})
            )
    gap_level = predictor.settings.support.gap_level if args.gap_level is None else args.gap_level
    if args.surface_offset is not None:
        predictor.settings = dataclasses.replace(
            predictor.settings, surface=dataclasses.replace(predictor.settings.surface, offset_px=args.surface_offset)
        )
    print(
        "edge vthr support length gap fill surface weak join  frag attach gate both "
        + " ".join(f"{Path(s).name[:14]:>14s}:F1@5/APLS/TLTS" for s in args.sets)
    )

    def values(arg: str, bundle_value: float) -> list[float]:
        """A comma-separated list from the command line, or the bundle's own setting."""
        return [float(v) for v in arg.split(",")] if arg else [float(bundle_value)]

    support = predictor.settings.support
    grid = [
        (e, t, s, n, g, f, r, w, j, m, a, gr, b)
        for e in values(args.edge_threshold, predictor.settings.edge_threshold)
        for t in values(args.vertex_threshold, predictor.settings.vertices.threshold)
        for s in values(args.support, support.min_support)
        for n in values(args.length, support.max_length_px)
        for g in values(args.gap, support.max_gap_px)
        for f in values(args.fill, predictor.settings.fill.min_length_px)
        for r in values(args.surface, predictor.settings.surface.strong)
        for w in values(args.surface_weak, predictor.settings.surface.weak)
        for j in values(args.join, predictor.settings.join.max_px)
        for m in values(args.fragments, predictor.settings.min_fragment_px)
        for a in values(args.attach_backed, predictor.settings.join.attach_px)
        for gr in values(args.gate, predictor.settings.gate.radius_px)
        for b in values(args.both_sides, predictor.settings.surface.both_sides)
    ]
    for edge, vthr, support, length, gap, fill, strong, weak, join, fragment, attach, gate, both in grid:
        if (gate > 0 or strong > 0) and not predictor.fpn.config.surface:
            raise SystemExit("the surface check and gate need an FPN with a surface head")
        base, replace = predictor.settings, dataclasses.replace
        predictor.settings = replace(
            base,
            edge_threshold=edge,
            min_fragment_px=fragment,
            gate=replace(base.gate, radius_px=gate),
            join=replace(base.join, max_px=join, attach_px=attach),
            fill=replace(base.fill, min_length_px=fill),
            surface=replace(base.surface, strong=strong, weak=weak, both_sides=both),
            vertices=replace(base.vertices, threshold=vthr),
            support=replace(
                base.support, min_support=support, max_length_px=length, max_gap_px=gap, gap_level=gap_level
            ),
        )
        row = score_row(args.sets, predictor)
        print(
            f"{edge:4.2f} {vthr:4.2f} {support:7.2f} {length:6.0f} {gap:3.0f} {fill:4.0f} {strong:7.2f} {weak:4.2f} {join:4.0f}  "
            f"{fragment:5.0f} {attach:6.0f} {gate:4.0f} {both:4.2f} " + " ".join(f"{r:>29s}" for r in row),
            flush=True,
        )


if __name__ == "__main__":
    main()
