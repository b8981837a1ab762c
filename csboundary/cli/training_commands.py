"""Commands that make models: training runs, the weights bundle that ships, and fine-tuning it on a
user's own labelled imagery."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from csboundary.cli.options import (
    DeviceOption,
    QuietOption,
    WeightsOption,
    finite,
    out_dir,
    out_file,
    positive,
    with_graph_options,
)
from csboundary.graph.settings import GraphOverrides, GraphSettings


def train(
    model: str = typer.Argument(..., help="fpn | afanet | a baseline: orientation-refine | sat2graph | icurb."),
    config: Path = typer.Option(
        ...,
        "--config",
        help="Training config JSON (configs/shipped: the shipped weights; configs/paper: the paper and its baselines).",
    ),
    out: Path = typer.Option(..., "--out", help="Run folder: checkpoints, train.log."),
    resume: Optional[Path] = typer.Option(None, help="Checkpoint (*-last.pt) to resume from."),
    steps: Optional[int] = typer.Option(None, min=1, help="Override the config's step count."),
    fpn_weights: Optional[Path] = typer.Option(None, help="AfANet only: the trained FPN (overrides the config)."),
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """Train the FPN, AfANet or a baseline on synthetic cities (built on first use under the config's cache)."""
    from csboundary.pipeline.training.train_run import MODELS, train_from_file

    if model not in MODELS:
        raise typer.BadParameter(f"model must be one of {', '.join(MODELS)}")
    out_dir(out)
    weights, cfg = train_from_file(
        model, config, out, resume=resume, steps=steps, fpn_weights=fpn_weights, device=device, progress=not quiet
    )
    typer.echo(f"{weights}: trained {model} ({cfg.steps} steps); log in {out / 'train.log'}")


@with_graph_options
def bundle_weights(
    fpn: Path = typer.Option(..., help="Trained FPN checkpoint (fpn.pt)."),
    afanet: Path = typer.Option(..., help="Trained AfANet checkpoint (afanet.pt)."),
    out: Path = typer.Option(..., "--out", help="Bundle to write (e.g. csboundary/weights/csboundary-synthetic.pt)."),
    graph: GraphOverrides = GraphOverrides(),
    gap_level: float = typer.Option(
        0.3, callback=finite, min=0.0, max=1.0, help="Boundary probability below which a point of an edge is a gap."
    ),
    surface_weak: float = typer.Option(
        0.2,
        "--surface-weak",
        callback=finite,
        min=0.0,
        max=1.0,
        help="Surface check: edges below this are dropped even when connected to a sure one.",
    ),
    surface_both_sides: float = typer.Option(
        0.0,
        "--surface-both-sides",
        callback=finite,
        min=0.0,
        max=1.0,
        help="Surface check: edges with at least this mean road-surface probability on their poorer "
        "side lie inside the roadway and are dropped (0 = off).",
    ),
    grid_crossings: int = typer.Option(
        0,
        min=0,
        help="Add vertices where the boundary crosses grid lines this far apart (0 = off; 250 = the label grid).",
    ),
    vertex_threshold: float | None = typer.Option(
        None,
        callback=finite,
        min=0.01,
        max=1.0,
        help="Keypoint probability of a vertex (default: the one AfANet was trained with, 0.5 unless its config says).",
    ),
) -> None:
    """Bundle a trained FPN and AfANet (weights + provenance) into one weights file. Its graph
    settings are the graph options given (each one not given: off, edge threshold 0.5, at most 2
    edges per vertex)."""
    from csboundary.models.training.bundle import afanet_checkpoint, make_bundle, trained_vertex_threshold

    if graph.min_confidence is not None:
        raise typer.BadParameter(
            "a confidence threshold is chosen when predicting, not stored in a bundle", param_hint="--min-confidence"
        )
    out_file(out, (".pt",))
    if vertex_threshold is None:
        vertex_threshold = trained_vertex_threshold(afanet_checkpoint(afanet))
    settings = GraphSettings().replaced(
        grid_crossings=grid_crossings,
        vertex_threshold=vertex_threshold,
        edge_gap_level=gap_level,
        surface_weak=surface_weak,
        surface_both_sides=surface_both_sides,
    )
    path = make_bundle(fpn, afanet, out, settings.overridden(graph))
    typer.echo(f"{path}: {path.stat().st_size / 1e6:.1f} MB")


def fit_confidence(
    cities: list[Path] = typer.Argument(
        ..., help="Labelled city directories (synth, make-city, import-masks), or folders of them."
    ),
    out: Path = typer.Option(..., "--out", help="Bundle to write: the weights with the fitted edge confidence."),
    weights: Optional[Path] = typer.Option(
        None, help="Weights bundle whose predictions are scored (default: the shipped one)."
    ),
    seed: int = typer.Option(0, min=0, help="Seed of the trees' row sampling."),
    trees: int = typer.Option(200, min=1, max=5000, help="Boosted trees."),
    depth: int = typer.Option(2, min=1, max=8, help="Depth of each tree."),
    assume_model_gsd: bool = typer.Option(
        False, "--assume-model-gsd", help="Imagery without a pixel size is at the model's (imported crops)."
    ),
    engine: str = typer.Option("auto", help="auto | torch | onnx."),
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """Fit the edge confidence, the calibrated probability that an edge is a true boundary, on
    labelled cities predicted with WEIGHTS, and write it into a copy of the bundle
    (docs/confidence.md). Fit on cities the networks never trained on."""
    from csboundary.data import city_layout
    from csboundary.metrics.confidence_quality import confidence_report
    from csboundary.models.checkpoint import shipped_weights
    from csboundary.pipeline.prediction.city_scores import set_cities
    from csboundary.pipeline.prediction.patch import load_predictor
    from csboundary.pipeline.training.confidence_fit import fit_bundle_confidence

    out_file(out, (".pt",))
    found: list[Path] = []
    for path in cities:
        found += [path] if city_layout.is_city_dir(path) else set_cities(path)
    source = weights or shipped_weights()
    predictor = load_predictor(source, device, engine=engine)
    model, per_city = fit_bundle_confidence(
        found,
        source,
        out,
        predictor,
        seed=seed,
        progress=not quiet,
        n_trees=trees,
        depth=depth,
        assume_model_gsd=assume_model_gsd,
    )
    for c in per_city:
        r = confidence_report(model.probability(c.evidence), c.truth_share, c.graph.edge_lengths())
        typer.echo(
            f"{c.name}: {r['edges']} edges, {r['share_true']:.2f} true, AUC {r['auc']:.3f}, ECE {r['ece']:.3f} (fitted on)"
        )
    typer.echo(
        f"{out}: edge confidence of {model.n_trees} trees over {len(model.features)} features, from {len(per_city)} cities"
    )


def _budget(**given):
    """The fine-tuning budget: the options given, the defaults of FinetuneBudget for the rest."""
    from csboundary.pipeline.training.finetune import FinetuneBudget

    return FinetuneBudget.from_dict({k: v for k, v in given.items() if v is not None})


def finetune(
    labelled: list[Path] = typer.Argument(
        ...,
        help="Labelled inputs: city directories (make-city, import-masks), sets of them, "
        "or reviewed prediction folders (their areas marked complete).",
    ),
    out: Path = typer.Option(
        ..., "--out", help="Bundle to write: the fine-tuned weights, used as any bundle (predict --weights OUT)."
    ),
    weights: WeightsOption = None,
    work: Optional[Path] = typer.Option(
        None,
        help="Folder of the training runs; give the same command again to continue a stopped "
        "run (default: OUT-finetune/ beside OUT).",
    ),
    fpn_steps: Optional[int] = typer.Option(None, min=1, help="FPN steps (default 1000)."),
    afanet_steps: Optional[int] = typer.Option(None, min=1, help="AfANet steps (default 500)."),
    user_share: Optional[float] = typer.Option(
        None,
        callback=finite,
        min=0.05,
        max=1.0,
        help="Share of training samples from LABELLED (default 0.5); the rest come from synthetic "
        "cities of the weights' mix.",
    ),
    synthetic_cities: Optional[int] = typer.Option(
        None, min=1, help="Synthetic cities mixed in (default 12; built on first use, 2500 px each)."
    ),
    cache: Optional[Path] = typer.Option(None, help="Folder of the synthetic cities (default: in WORK)."),
    refit_confidence: bool = typer.Option(
        True,
        "--refit-confidence/--keep-confidence",
        help="Refit the edge confidence with the tuned networks on LABELLED and the synthetic "
        "cities, when LABELLED gives enough edges (100, with 20 true and 20 false); else keep "
        "the weights'.",
    ),
    seed: int = typer.Option(0, min=0, help="Seed of the sample draws."),
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """Fine-tune the weights on your own labelled imagery: the FPN, then AfANet on the tuned
    FPN's vertices, with synthetic cities mixed in so nothing learnt is forgotten
    (docs/finetune.md). The default budget takes about 11 minutes on a 2-core CPU."""
    from csboundary.pipeline.training.finetune import default_work
    from csboundary.pipeline.training.finetune import finetune as run

    out_file(out, (".pt",))
    budget = _budget(
        fpn_steps=fpn_steps,
        afanet_steps=afanet_steps,
        user_share=user_share,
        synthetic_cities=synthetic_cities,
        refit_confidence=refit_confidence,
    )
    done = run(
        labelled,
        out,
        weights=weights,
        work=work or default_work(out),
        budget=budget,
        seed=seed,
        cache=cache,
        device=device,
        progress=not quiet,
    )
    minutes = sum(done["seconds"].values()) / 60
    typer.echo(
        f"{out}: fine-tuned on {len(done['cities'])} labelled cities ({budget.fpn_steps} FPN + {budget.afanet_steps} AfANet steps, "
        f"{minutes:.1f} min); runs in {done['work']}"
    )
    typer.echo(f"edge confidence: {done['confidence']['reason']}")


def adapt(
    imagery: list[Path] = typer.Argument(
        ...,
        help="Your unlabelled imagery: GeoTIFFs, folders of them, city folders, sets or "
        "prediction folders (any labels in them are ignored).",
    ),
    out: Path = typer.Option(
        ..., "--out", help="Bundle to write: the adapted weights, used as any bundle (predict --weights OUT)."
    ),
    weights: WeightsOption = None,
    work: Optional[Path] = typer.Option(
        None,
        help="Folder of the training runs; give the same command again to continue a stopped "
        "run (default: OUT-adapt/ beside OUT).",
    ),
    fpn_steps: Optional[int] = typer.Option(None, min=1, help="FPN self-training steps (default 800)."),
    afanet_steps: Optional[int] = typer.Option(
        None, min=0, help="AfANet steps on the adapted FPN's vertices (default 300; 0 keeps the bundle's AfANet)."
    ),
    synthetic_cities: Optional[int] = typer.Option(
        None, min=1, help="Synthetic cities mixed in (default 12; built on first use, 2500 px each)."
    ),
    mix: bool = typer.Option(
        True, "--mix/--no-mix", help="Paste synthetic roadway, with its labels, into your windows."
    ),
    surface_anchor: bool = typer.Option(
        True,
        "--surface-anchor/--no-surface-anchor",
        help="Teach a boundary only near the edge of the teacher's roadway.",
    ),
    cache: Optional[Path] = typer.Option(None, help="Folder of the synthetic cities (default: in WORK)."),
    gsd: Optional[float] = typer.Option(None, callback=positive, help="Pixel size in metres of imagery without a CRS."),
    seed: int = typer.Option(0, min=0, help="Seed of the sample draws."),
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """Adapt the weights to your city from its own unlabelled imagery: self-training of the FPN
    by an averaged teacher, with synthetic cities mixed in, then AfANet on the adapted FPN's
    vertices (docs/adapt.md). The default budget takes about 13 minutes on a 2-core CPU."""
    from csboundary.models.training.self_training import AdaptConfig
    from csboundary.pipeline.training.adapt import AdaptBudget, default_work
    from csboundary.pipeline.training.adapt import adapt as run

    out_file(out, (".pt",))
    given = dict(fpn_steps=fpn_steps, afanet_steps=afanet_steps, synthetic_cities=synthetic_cities)
    budget = AdaptBudget.from_dict({k: v for k, v in given.items() if v is not None})
    method = AdaptConfig(mix=mix, surface_anchor=surface_anchor)
    done = run(
        imagery,
        out,
        weights=weights,
        work=work or default_work(out),
        budget=budget,
        method=method,
        seed=seed,
        cache=cache,
        gsd=gsd,
        device=device,
        progress=not quiet,
    )
    minutes = sum(done["seconds"].values()) / 60
    typer.echo(
        f"{out}: adapted to {done['images']} images ({done['pixels'] / 1e6:.2f} Mpx; {budget.fpn_steps} FPN + "
        f"{budget.afanet_steps} AfANet steps, {minutes:.1f} min); runs in {done['work']}"
    )


def evaluate_finetune(
    set_dir: Path = typer.Argument(
        ..., help="A set of labelled cities (import-masks output, or a folder of city directories)."
    ),
    out: Path = typer.Option(
        ..., "--out", help="Folder of the folds' runs, bundles and scores; give it again to continue."
    ),
    folds: int = typer.Option(2, min=2, help="Folds: each is held out once while the others fine-tune."),
    weights: WeightsOption = None,
    fpn_steps: Optional[int] = typer.Option(None, min=1, help="FPN steps per fold (default 1000)."),
    afanet_steps: Optional[int] = typer.Option(None, min=1, help="AfANet steps per fold (default 500)."),
    user_share: Optional[float] = typer.Option(
        None, callback=finite, min=0.05, max=1.0, help="Share of training samples from the set (default 0.5)."
    ),
    synthetic_cities: Optional[int] = typer.Option(None, min=1, help="Synthetic cities mixed in (default 12)."),
    cache: Optional[Path] = typer.Option(None, help="Folder of the synthetic cities (default: in OUT)."),
    seed: int = typer.Option(0, min=0, help="Seed of the sample draws and of the scores' vertex pairs."),
    engine: str = typer.Option("auto", help="auto | torch | onnx."),
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """What fine-tuning on a labelled set is worth: K-fold cross-validation, base against
    fine-tuned scores on every held-out city, with the 95 % interval of the gain."""
    from csboundary.pipeline.evaluation.finetune_cv import evaluate_finetune as run
    from csboundary.pipeline.evaluation.finetune_cv import format_finetune

    out_dir(out, [set_dir])
    budget = _budget(
        fpn_steps=fpn_steps, afanet_steps=afanet_steps, user_share=user_share, synthetic_cities=synthetic_cities
    )
    result = run(
        set_dir,
        out,
        folds=folds,
        weights=weights,
        budget=budget,
        seed=seed,
        cache=cache,
        device=device,
        engine=engine,
        progress=not quiet,
    )
    typer.echo(format_finetune(result))
    typer.echo(f"{out / 'evaluate-finetune.json'}: every score")
