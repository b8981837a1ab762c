"""Adapting a weights bundle to a user's own unlabelled imagery (``csboundary adapt``).

Self-training (:mod:`csboundary.models.training.self_training`) adapts the FPN from the bundle's on
windows drawn from the user's mosaics, beside synthetic cities of the bundle's own mix; then
AfANet is tuned, as ``finetune`` does, on the vertices the adapted FPN extracts from those
synthetic cities (the user's imagery has no edges to learn from). The result is a bundle like
any other: the bundle's inference settings and edge confidence, the adapted networks, and a
provenance naming the base weights and every image by its sha256.

Everything lands in a work folder; the same command continues a stopped run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from csboundary.config import Config
from csboundary.data import city_layout
from csboundary.data.model_view import model_view
from csboundary.data.raster import Mosaic
from csboundary.data.units import MODEL_GSD
from csboundary.errors import InputError
from csboundary.labels.mask_import import SET_FILE
from csboundary.models.checkpoint import code_version, file_sha256, load_checkpoint, save_checkpoint, shipped_weights
from csboundary.models.device import resolve_device
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.self_training import AdaptConfig, train_adapt
from csboundary.models.training.unlabelled import DRAWS, UnlabelledImagery
from csboundary.pipeline.outputs.review import prediction_inputs
from csboundary.pipeline.prediction.city_scores import set_cities
from csboundary.pipeline.training.finetune import (
    FinetuneBudget,
    check_budget,
    checked_base,
    locked_work,
    train_or_resume,
    training_configs,
)

RASTER_SUFFIXES = (".tif", ".tiff")


@dataclass
class AdaptBudget(Config):
    """How much adapting: sized so that 14 crops of 700 px take under 15 minutes on a 2-core
    CPU (docs/adapt.md has the measured times)."""

    config_name = "adapt budget"

    fpn_steps: int = 800
    afanet_steps: int = 300
    synthetic_cities: int = 12  # of the bundle's training mix, 2500 px each
    fpn_lr: float = 1e-4
    afanet_lr: float = 3e-4
    crop: int = 256

    def __post_init__(self) -> None:
        check_budget(self)


def default_work(out: Path) -> Path:
    return out.with_name(out.stem + "-adapt")


def imagery_groups(paths: list[Path]) -> list[list[Path]]:
    """The raster files of each mosaic that ``paths`` name: a GeoTIFF is one mosaic; a folder of
    GeoTIFFs one; a city directory its tiles; a set (``set.json``, or a folder of cities) each of
    its cities; a prediction folder the imagery it was predicted from. Labels are never read."""
    groups: list[list[Path]] = []
    for path in map(Path, paths):
        if not path.exists():
            raise InputError(path, "does not exist")
        if path.is_file():
            if path.suffix.lower() not in RASTER_SUFFIXES:
                raise InputError(path, "not a GeoTIFF (.tif), a folder of them, a city, a set or a prediction folder")
            groups.append([path])
        elif city_layout.is_city_dir(path):
            groups.append(sorted(city_layout.tiles_dir(path).glob("*.tif")))
        elif (path / "summary.json").exists():
            groups.append(prediction_inputs(path))
        elif (path / SET_FILE).exists() or any(city_layout.is_city_dir(p) for p in path.iterdir()):
            groups += [sorted(city_layout.tiles_dir(c).glob("*.tif")) for c in set_cities(path)]
        else:
            rasters = sorted(p for p in path.iterdir() if p.suffix.lower() in RASTER_SUFFIXES)
            if not rasters:
                raise InputError(path, "holds no GeoTIFF, city, set or prediction")
            groups.append(rasters)
    seen = [p.resolve() for group in groups for p in group]
    twice = next((p for p in seen if seen.count(p) > 1), None)
    if twice is not None:
        raise InputError(twice, "given twice")
    return groups


def open_imagery_views(groups: list[list[Path]], gsd: float | None, model_gsd: float) -> tuple[list, list]:
    """Each group's mosaic as the model sees it (``model_view``) and the mosaics to close."""
    views, mosaics = [], []
    try:
        for group in groups:
            mosaic = Mosaic.open(group)
            mosaics.append(mosaic)
            views.append(model_view(mosaic, gsd, model_gsd).mosaic)
    except Exception:
        for mosaic in mosaics:
            mosaic.close()
        raise
    return views, mosaics


def adapt(
    imagery: list[Path],
    out: Path,
    *,
    weights: Path | None = None,
    work: Path | None = None,
    budget: AdaptBudget = AdaptBudget(),
    method: AdaptConfig = AdaptConfig(),
    seed: int = 0,
    cache: Path | None = None,
    gsd: float | None = None,
    device: str = "auto",
    progress: bool = True,
) -> dict:
    """The checks every caller gets (the command line and the Python API alike), then
    :func:`_adapt` holding the work folder's lock: a second run into the same work folder is
    refused in one line instead of spoiling this one's runs."""
    if not imagery:
        raise InputError("<imagery>", "no imagery given: name at least one")
    out = Path(out)
    work = Path(work) if work else default_work(out)
    with locked_work(work):
        return _adapt(
            imagery,
            out,
            weights=weights,
            work=work,
            budget=budget,
            method=method,
            seed=seed,
            cache=cache,
            gsd=gsd,
            device=device,
            progress=progress,
        )


def _adapt(
    imagery: list[Path],
    out: Path,
    *,
    weights: Path | None = None,
    work: Path | None = None,
    budget: AdaptBudget = AdaptBudget(),
    method: AdaptConfig = AdaptConfig(),
    seed: int = 0,
    cache: Path | None = None,
    gsd: float | None = None,
    device: str = "auto",
    progress: bool = True,
) -> dict:
    """Adapt the bundle ``weights`` (default: the shipped one) to the unlabelled ``imagery`` and
    write the adapted bundle ``out``. ``work`` keeps the runs (default ``OUT-adapt/``), ``cache``
    the synthetic cities (default: in ``work``); ``gsd`` is the pixel size of imagery without a
    CRS. Returns what was done and how long each stage took."""
    out, base_path = Path(out), Path(weights) if weights else shipped_weights()
    work = Path(work) if work else default_work(out)
    base = adaptable_base(base_path, method)
    groups = imagery_groups(imagery)
    views, mosaics = open_imagery_views(groups, gsd, float(base.get("pixel_size_m", MODEL_GSD)))
    try:  # the mosaics stay open while the FPN draws windows from them, and no longer
        target = checked_target(views, groups, budget, seed)
        records = [{"path": str(p.resolve()), "sha256": file_sha256(p)} for group in groups for p in group]
        synthetic = Path(cache) if cache else work / "synthetic"
        fpn_config, afanet_config = adapt_configs(base, base_path, budget, method, records, seed, synthetic)
        resolved = resolve_device(device)
        seconds = {}
        start = time.perf_counter()
        fpn = self_train_fpn(fpn_config, target, work / "fpn", resolved, progress)
        seconds["fpn"] = time.perf_counter() - start
    finally:
        for mosaic in mosaics:
            mosaic.close()
    afanet_config.fpn_weights = str(fpn.resolve())
    start = time.perf_counter()
    afanet = (
        train_or_resume("afanet", afanet_config, work / "afanet", resolved, progress) if budget.afanet_steps else None
    )
    seconds["afanet"] = time.perf_counter() - start
    adapted_fpn = load_checkpoint(fpn, ("fpn",))
    adapted_afanet = load_checkpoint(afanet, ("afanet",)) if afanet else None
    record = adapt_record(base_path, records, budget, method, seed)
    save_checkpoint(out, "bundle", **adapted_bundle(base, adapted_fpn, adapted_afanet, record))
    return {
        "out": out,
        "images": len(records),
        "pixels": target.pixels,
        "work": work,
        "seconds": seconds,
        "steps": {"fpn": budget.fpn_steps, "afanet": budget.afanet_steps},
    }


def adaptable_base(base_path: Path, method: AdaptConfig) -> dict:
    """The base bundle's payload (:func:`~csboundary.pipeline.training.finetune.checked_base`),
    refused before any imagery is opened when ``method`` mixes or anchors through a road-surface
    head its FPN does not have."""
    base = checked_base(base_path)
    if not base["fpn_config"].get("surface") and (method.mix or method.surface_anchor):
        raise InputError(
            base_path,
            "its FPN has no road-surface head, which mixing and the surface anchor need "
            "(give --no-mix --no-surface-anchor, or a bundle with one)",
        )
    return base


def checked_target(views: list, groups: list[list[Path]], budget: AdaptBudget, seed: int) -> UnlabelledImagery:
    """The imagery ``views`` (of the mosaics ``groups``) as self-training draws its windows,
    refused before any work when it cannot fill four windows or is all no-data where windows fall:
    such imagery would otherwise fail mid-training."""
    target = UnlabelledImagery(views, [str(g[0]) for g in groups])
    least = 4 * budget.crop**2
    if target.pixels < least:
        raise InputError(
            groups[0][0],
            f"too little imagery to learn from: {target.pixels} px at the model's pixel size, "
            f"adapt needs at least {least} (four {budget.crop} px windows)",
        )
    try:
        target.sample(np.random.default_rng(seed), budget.crop)
    except ValueError:
        raise InputError(
            groups[0][0],
            f"{DRAWS} random {budget.crop} px windows of the imagery held no valid pixel: it is all "
            "no-data where they fall",
        ) from None
    return target


def adapt_configs(
    base: dict,
    base_path: Path,
    budget: AdaptBudget,
    method: AdaptConfig,
    records: list[dict],
    seed: int,
    synthetic: Path,
) -> tuple[TrainConfig, TrainConfig]:
    """The FPN and AfANet runs as ``finetune`` sets them up with no labelled city, the synthetic
    cities cached in ``synthetic``. The FPN run's options carry the self-training ``method`` (its
    trainer reads them there) and the imagery ``records``, so a work folder of other imagery or
    settings is refused rather than resumed."""
    tune = FinetuneBudget(
        fpn_steps=budget.fpn_steps,
        afanet_steps=budget.afanet_steps,
        user_share=0.5,
        synthetic_cities=budget.synthetic_cities,
        fpn_lr=budget.fpn_lr,
        afanet_lr=budget.afanet_lr,
        crop=budget.crop,
        batch=method.source_batch,
    )
    fpn_config, afanet_config = training_configs(base, base_path, [], tune, seed, synthetic)
    fpn_config.options = {"method": method.to_dict(), "imagery": records}
    return fpn_config, afanet_config


def self_train_fpn(config: TrainConfig, target: UnlabelledImagery, run: Path, device, progress: bool) -> Path:
    """The FPN self-trained on windows of ``target`` beside the synthetic cities
    (:func:`~csboundary.models.training.self_training.train_adapt`) in ``run``, a stopped run
    continued and a finished one taken as it is: its final weights."""
    return train_or_resume(
        "adapt",
        config,
        run,
        device,
        progress,
        final_name="fpn.pt",
        trainer=lambda config, run, dev, resume, progress: train_adapt(config, target, run, dev, resume, progress),
    )


def adapt_record(base_path: Path, records: list[dict], budget: AdaptBudget, method: AdaptConfig, seed: int) -> dict:
    """The adapt's own provenance: the base weights and every image by sha256, and the settings,
    so that the adapted bundle says what it was made from."""
    return {
        "base_weights": str(base_path.resolve()),
        "base_sha256": file_sha256(base_path),
        "imagery": records,
        "budget": budget.to_dict(),
        "method": method.to_dict(),
        "seed": seed,
        "code_version": code_version(),
        "edge_confidence": "the base bundle's, fitted on its own predictions (docs/adapt.md: its AUC with the adapted networks)",
    }


def adapted_bundle(base: dict, adapted_fpn: dict, adapted_afanet: dict | None, record: dict) -> dict:
    """The payload of the adapted bundle: the ``base`` bundle's settings and edge confidence with
    the adapted networks, and AfANet's as the base had it when it was not tuned
    (``adapted_afanet`` None). The provenance keeps each run's, the base's and the adapt
    ``record``."""
    keys = ("code_version", "code_version_at_start", "train_config", "step", "validation")
    payload = {k: v for k, v in base.items() if k not in ("format", "kind", "code_version")}
    provenance = {"fpn": {k: adapted_fpn.get(k) for k in keys}, "base": base.get("provenance") or {}, "adapt": record}
    provenance["afanet"] = (
        {k: adapted_afanet.get(k) for k in keys}
        if adapted_afanet is not None
        else (base.get("provenance") or {}).get("afanet")
    )
    afanet = (
        adapted_afanet
        if adapted_afanet is not None
        else {"afanet": base["afanet"], "afanet_config": base["afanet_config"]}
    )
    payload.update(
        fpn=adapted_fpn["fpn"],
        fpn_config=adapted_fpn["fpn_config"],
        afanet=afanet["afanet"],
        afanet_config=afanet["afanet_config"],
        provenance=provenance,
    )
    return payload


__all__ = ["AdaptBudget", "adapt", "imagery_groups"]
