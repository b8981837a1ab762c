"""Fine-tuning a weights bundle on a user's labelled cities (``csboundary finetune``).

Both networks are tuned, in the order inference needs them: first the FPN, starting from the
bundle's, on batches drawn ``user_share`` from the user's cities and the rest from synthetic
cities of the bundle's own training mix (so that what it learnt elsewhere is not forgotten);
then AfANet, starting from the bundle's, on the vertices the tuned FPN extracts, as it will meet
them at inference. The result is a bundle like any other: the bundle's inference settings and
edge confidence, the tuned networks, and a provenance that names the base weights and every
labelled input by its hash.

Everything lands in a work folder (the two training runs, the reviewed cities, the synthetic
cities), so a run stopped at any point continues where it stopped when given again.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from csboundary.config import Config
from csboundary.data import city_layout
from csboundary.data.atomic import atomic_path
from csboundary.data.folder_lock import LOCK_FILE, locked_folder
from csboundary.errors import InputError
from csboundary.models.checkpoint import code_version, file_sha256, load_checkpoint, save_checkpoint, shipped_weights
from csboundary.models.device import resolve_device
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.data import CitySpec, WorldsConfig
from csboundary.pipeline.training.labelled_inputs import labelled_cities


@dataclass
class FinetuneBudget(Config):
    """How much fine-tuning: sized so that a handful of patches takes under 20 minutes on a
    2-core CPU (docs/finetune.md has the measured times)."""

    config_name = "finetune budget"

    fpn_steps: int = 1000
    afanet_steps: int = 500
    user_share: float = 0.5  # share of samples from the user's cities; the rest from synthetic ones
    synthetic_cities: int = 12  # of the bundle's training mix, 2500 px each
    fpn_lr: float = 1e-4
    afanet_lr: float = 3e-4
    crop: int = 256
    batch: int = 4
    refit_confidence: bool = (
        True  # refit the edge confidence with the tuned networks when the labelled cities give enough edges
    )

    def __post_init__(self) -> None:
        check_budget(self)


MAX_STEPS = 1_000_000  # far beyond any budget measured; a typo's billion steps would run for years on a CPU


def check_budget(budget) -> None:
    """A training budget's values in their ranges (fine-tuning's and adapting's alike), each
    refused in the command line's one line, named by its option."""
    for name in ("fpn_steps", "afanet_steps"):
        value = getattr(budget, name)
        low = 1 if name == "fpn_steps" else 0
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= MAX_STEPS:
            raise InputError(
                "--" + name.replace("_", "-"), f"must be a whole number from {low} to {MAX_STEPS:,}, got {value!r}"
            )
    for name in ("fpn_lr", "afanet_lr"):
        value = getattr(budget, name)
        if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise InputError("--" + name.replace("_", "-"), f"must be a finite number above 0, got {value!r}")
    if not isinstance(budget.synthetic_cities, int) or budget.synthetic_cities < 0:
        raise InputError("--synthetic-cities", f"must be a whole number >= 0, got {budget.synthetic_cities!r}")
    share = getattr(budget, "user_share", 0.5)
    if not isinstance(share, (int, float)) or not 0 <= share <= 1:
        raise InputError("--user-share", f"must be from 0 to 1, got {share!r}")


FINETUNE_VALID = CitySpec(
    split="valid", seed=0, tiles=(1, 1), tile_size=1500
)  # a small synthetic city: forgetting shows there


def default_work(out: Path) -> Path:
    return out.with_name(out.stem + "-finetune")


def training_configs(
    base: dict, base_path: Path, cities: list[Path], budget: FinetuneBudget, seed: int, cache: Path
) -> tuple[TrainConfig, TrainConfig]:
    """The FPN and AfANet training configs of a fine-tune of the bundle ``base`` (its payload,
    read from ``base_path``, where both networks start) on ``cities``: the bundle's own recipe
    (style mix, losses, surface head) with the budget's steps, rates and user share."""
    recipe = ((base.get("provenance") or {}).get("fpn") or {}).get("train_config") or {}
    worlds = {**(recipe.get("worlds") or {}), "cities": budget.synthetic_cities}
    worlds.setdefault("tile_size", 2500)
    shared = dict(
        seed=seed,
        cache=str(cache),
        train_city=None,
        worlds=worlds,
        valid_city=FINETUNE_VALID,
        extra_train_cities=[str(c) for c in cities],
        extra_share=budget.user_share,
        validation_samples=4,
    )
    fpn = TrainConfig(
        model="fpn",
        steps=budget.fpn_steps,
        lr=budget.fpn_lr,
        validate_every=max(1, min(100, budget.fpn_steps)),
        init_fpn=str(base_path.resolve()),
        surface=bool(base["fpn_config"].get("surface")),
        crop=budget.crop,
        batch=budget.batch,
        augment=recipe.get("augment", {}),
        hard_negative_weight=float(recipe.get("hard_negative_weight", 0.0)),
        hard_negative_margin_px=int(recipe.get("hard_negative_margin_px", 6)),
        pos_weight_keypoint=float(recipe.get("pos_weight_keypoint", 20.0)),
        pos_weight_segmentation=float(recipe.get("pos_weight_segmentation", 10.0)),
        **shared,
    )
    afanet_recipe = ((base.get("provenance") or {}).get("afanet") or {}).get("train_config") or {}
    afanet = TrainConfig(
        model="afanet",
        steps=budget.afanet_steps,
        gt_steps=0,
        lr=budget.afanet_lr,
        init_afanet=str(base_path.resolve()),
        validate_every=max(1, min(200, budget.afanet_steps)),
        vertex_threshold=float(base["inference"].get("vertex_threshold", 0.5)),  # the vertices it meets at inference
        window=int(afanet_recipe.get("window", 1100)),
        max_vertices=int(afanet_recipe.get("max_vertices", 160)),
        max_pos_weight=float(afanet_recipe.get("max_pos_weight", 30.0)),
        augment=afanet_recipe.get("augment", {}),
        **shared,
    )
    return fpn, afanet


def checked_base(path: Path) -> dict:
    """The base bundle's payload, after every check ``predict`` makes of it (networks, settings,
    edge confidence): a bundle predict would refuse is refused before training, not after."""
    import torch

    from csboundary.pipeline.prediction.patch import PatchPredictor

    PatchPredictor.load(path, torch.device("cpu"))
    return load_checkpoint(path, ("bundle",))


def train_or_resume(
    kind: str, config: TrainConfig, run: Path, device, progress: bool, trainer=None, final_name: str | None = None
) -> Path:
    """One training run in ``run`` (``trainer(config, run, device, resume, progress)``, by
    default the trainer of ``kind``), resumed from its last checkpoint when one is there; a run
    whose final weights (``final_name``, default ``<kind>.pt``) exist under the same config is
    not repeated."""
    from csboundary.models.training.afanet import train_afanet
    from csboundary.models.training.fpn import train_fpn

    final, last, recorded = run / (final_name or f"{kind}.pt"), run / f"{kind}-last.pt", run / "config.json"
    wanted = json.dumps(config.to_dict(), indent=2) + "\n"
    if recorded.exists() and recorded.read_text() != wanted:
        raise InputError(
            run, "holds a fine-tune with other inputs or settings: give another --work folder or remove it"
        )
    if final.exists():
        return final
    run.mkdir(parents=True, exist_ok=True)
    with atomic_path(recorded) as tmp:
        tmp.write_text(wanted)
    trainer = trainer or {"fpn": train_fpn, "afanet": train_afanet}[kind]
    return trainer(config, run, device, str(last) if last.exists() else None, progress)


def labelled_record(city: Path) -> dict:
    """A labelled input as provenance: its name, its ground truth's and its tiles' sha256."""
    return {
        "city": str(Path(city).resolve()),
        "ground_truth_sha256": file_sha256(city_layout.ground_truth_path(city)),
        "tiles_sha256": {p.name: file_sha256(p) for p in sorted(city_layout.tiles_dir(city).glob("*.tif"))},
    }


def finetune(
    labelled: list[Path],
    out: Path,
    *,
    weights: Path | None = None,
    work: Path | None = None,
    budget: FinetuneBudget = FinetuneBudget(),
    seed: int = 0,
    cache: Path | None = None,
    device: str = "auto",
    progress: bool = True,
) -> dict:
    """The checks every caller gets (the command line and the Python API alike), then
    :func:`_finetune` holding the work folder's lock: a second run into the same work folder is
    refused in one line instead of spoiling this one's runs."""
    if not labelled:
        raise InputError("<labelled>", "no labelled cities given: name at least one")
    out = Path(out)
    work = Path(work) if work else default_work(out)
    with locked_work(work):
        return _finetune(
            labelled,
            out,
            weights=weights,
            work=work,
            budget=budget,
            seed=seed,
            cache=cache,
            device=device,
            progress=progress,
        )


def locked_work(work: Path):
    """The training work folder ``work``, made if missing and held under its lock for the block
    (:func:`~csboundary.data.folder_lock.locked_folder`)."""
    return locked_folder(work, "--work")


def _finetune(
    labelled: list[Path],
    out: Path,
    *,
    weights: Path | None = None,
    work: Path | None = None,
    budget: FinetuneBudget = FinetuneBudget(),
    seed: int = 0,
    cache: Path | None = None,
    device: str = "auto",
    progress: bool = True,
) -> dict:
    """Fine-tune the bundle ``weights`` (default: the shipped one) on the ``labelled`` cities,
    sets or reviewed predictions, and write the tuned bundle ``out``. ``work`` keeps the runs
    (default: ``OUT-finetune/`` beside ``out``); ``cache`` the synthetic cities (default: in
    ``work``). Returns what was done and how long each stage took."""
    out, base_path = Path(out), Path(weights) if weights else shipped_weights()
    work = Path(work) if work else default_work(out)
    base = checked_base(base_path)
    made = not any(p.name != LOCK_FILE for p in work.iterdir())  # nothing of an earlier run in it
    try:
        cities = labelled_cities(labelled, work)  # every input checked before anything is made
    except InputError:
        if made:  # the refused input of a second reviewed prediction comes after the first one's city was made
            shutil.rmtree(work, ignore_errors=True)
        raise
    fpn_config, afanet_config = training_configs(
        base, base_path, cities, budget, seed, Path(cache) if cache else work / "synthetic"
    )
    resolved = resolve_device(device)
    seconds = {}
    start = time.perf_counter()
    fpn = train_or_resume("fpn", fpn_config, work / "fpn", resolved, progress)
    seconds["fpn"] = time.perf_counter() - start
    afanet_config.fpn_weights = str(fpn.resolve())
    start = time.perf_counter()
    afanet = train_or_resume("afanet", afanet_config, work / "afanet", resolved, progress)
    seconds["afanet"] = time.perf_counter() - start
    tuned_fpn, tuned_afanet = load_checkpoint(fpn, ("fpn",)), load_checkpoint(afanet, ("afanet",))
    record = {
        "base_weights": str(base_path.resolve()),
        "base_sha256": file_sha256(base_path),
        "labelled": [labelled_record(c) for c in cities],
        "budget": budget.to_dict(),
        "seed": seed,
        "code_version": code_version(),
        "edge_confidence": {"refitted": False, "reason": "the base bundle's (refit switched off)"},
    }
    keys = ("code_version", "code_version_at_start", "train_config", "step", "validation")
    payload = {k: v for k, v in base.items() if k not in ("format", "kind", "code_version")}
    payload.update(
        fpn=tuned_fpn["fpn"],
        fpn_config=tuned_fpn["fpn_config"],
        afanet=tuned_afanet["afanet"],
        afanet_config=tuned_afanet["afanet_config"],
        provenance={
            "fpn": {k: tuned_fpn.get(k) for k in keys},
            "afanet": {k: tuned_afanet.get(k) for k in keys},
            "base": base.get("provenance") or {},
            "finetune": record,
        },
    )
    save_checkpoint(out, "bundle", **payload)
    confidence = record["edge_confidence"]
    if budget.refit_confidence:
        start = time.perf_counter()
        confidence = refit_tuned_confidence(out, cities, fpn_config, resolved, seed, progress)
        seconds["confidence"] = time.perf_counter() - start
    return {
        "out": out,
        "cities": cities,
        "work": work,
        "seconds": seconds,
        "steps": {"fpn": budget.fpn_steps, "afanet": budget.afanet_steps},
        "confidence": confidence,
    }


def refit_tuned_confidence(
    out: Path, cities: list[Path], fpn_config: TrainConfig, device, seed: int, progress: bool
) -> dict:
    """Refit the tuned bundle ``out``'s edge confidence on the labelled ``cities`` and the
    synthetic cities the FPN mixed in, when they hold enough edges
    (:func:`csboundary.pipeline.training.confidence_fit.refit_for_tuned`); the outcome goes into the
    bundle's provenance either way."""
    from csboundary.pipeline.training.confidence_fit import refit_for_tuned

    synthetic = [
        spec.ensure(fpn_config.cache, progress=False) for spec in WorldsConfig.from_dict(fpn_config.worlds).specs()
    ]
    outcome = refit_for_tuned(out, cities, synthetic, device, seed=seed, progress=progress)
    payload = load_checkpoint(out, ("bundle",))
    payload["provenance"]["finetune"]["edge_confidence"] = outcome
    save_checkpoint(out, "bundle", **{k: v for k, v in payload.items() if k not in ("format", "kind")})
    return outcome
