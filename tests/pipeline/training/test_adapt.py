"""Adapting to unlabelled imagery: what the inputs name (labels never read), the refusals, and one
tiny run end to end: a bundle with its provenance, a second command that trains nothing again,
and a work folder of other settings refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rasterio
import torch
from rasterio.transform import from_origin

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.styles import style_config
from csboundary.errors import InputError
from csboundary.models.training.self_training import AdaptConfig
from csboundary.pipeline.training.adapt import AdaptBudget, adapt, imagery_groups

SIZE = 600


@pytest.fixture(scope="module")
def city(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("adapt") / "city"
    synthesize_city(out, seed=4, split="valid", config=style_config("classic", tile_size=SIZE), progress=False)
    return out


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    """One cache of synthetic cities for the module's runs: each builds the same cities."""
    return tmp_path_factory.mktemp("adapt-synthetic")


def _geotiff(path: Path, size: int) -> Path:
    data = np.random.default_rng(0).integers(0, 255, (3, size, size), dtype=np.uint8)
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=size,
        height=size,
        count=3,
        dtype="uint8",
        crs="EPSG:32618",
        transform=from_origin(500000, 4500000, 0.152, 0.152),
    ) as ds:
        ds.write(data)
    return path


def test_inputs_name_mosaics_and_never_their_labels(city, tmp_path):
    tiles = sorted((city / "tiles").glob("*.tif"))
    assert imagery_groups([city]) == [tiles]
    single = _geotiff(tmp_path / "a.tif", 64)
    folder = tmp_path / "folder"
    folder.mkdir()
    second = [_geotiff(folder / "b.tif", 64), _geotiff(folder / "c.tif", 64)]
    assert imagery_groups([single, folder]) == [[single], second]
    prediction = tmp_path / "pred"
    prediction.mkdir()
    (prediction / "summary.json").write_text(json.dumps({"inputs": [str(t.resolve()) for t in tiles]}))
    assert imagery_groups([prediction]) == [[t.resolve() for t in tiles]]
    with pytest.raises(InputError, match="given twice"):
        imagery_groups([city, prediction])
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match="not a GeoTIFF"):
        imagery_groups([tmp_path / "notes.txt"])
    with pytest.raises(InputError, match="does not exist"):
        imagery_groups([tmp_path / "missing.tif"])


def test_too_little_imagery_is_refused_before_anything_is_made(tmp_path):
    small = _geotiff(tmp_path / "small.tif", 200)
    with pytest.raises(InputError, match="too little imagery to learn from: 40000 px"):
        adapt([small], tmp_path / "out.pt", work=tmp_path / "work", device="cpu", progress=False)
    assert not (tmp_path / "work").exists() and not (tmp_path / "out.pt").exists()


def test_the_command_refuses_bad_input_in_one_line(tmp_path):
    from helpers import run_cli

    (tmp_path / "notes.txt").write_text("x")
    result = run_cli("adapt", str(tmp_path / "notes.txt"), "--out", str(tmp_path / "a.pt"))
    assert result.returncode == 2 and not (tmp_path / "a.pt").exists()
    assert result.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'notes.txt'}: not a GeoTIFF (.tif), a folder of them, a city, a set or a prediction folder"
    ]


def test_a_tiny_adapt_writes_a_bundle_with_provenance_and_resumes_without_training_again(city, synthetic, tmp_path):
    from csboundary.models.checkpoint import file_sha256, load_checkpoint, shipped_weights
    from csboundary.pipeline.prediction.patch import load_predictor

    budget = AdaptBudget(fpn_steps=2, afanet_steps=2, synthetic_cities=1, crop=128)
    kwargs = dict(work=tmp_path / "work", budget=budget, cache=synthetic, device="cpu", progress=False)
    done = adapt([city], tmp_path / "adapted.pt", **kwargs)
    bundle = load_checkpoint(tmp_path / "adapted.pt", ("bundle",))
    record = bundle["provenance"]["adapt"]
    tiles = sorted((city / "tiles").glob("*.tif"))
    assert record["base_sha256"] == file_sha256(shipped_weights())
    assert record["imagery"] == [{"path": str(t.resolve()), "sha256": file_sha256(t)} for t in tiles]
    assert record["method"] == AdaptConfig().to_dict() and record["budget"]["fpn_steps"] == 2 and record["seed"] == 0
    assert bundle["provenance"]["fpn"]["step"] == 2 and bundle["provenance"]["afanet"]["step"] == 2
    shipped = load_checkpoint(shipped_weights(), ("bundle",))
    assert bundle["inference"] == shipped["inference"] and bundle["confidence"] == shipped["confidence"]
    assert not all(torch.equal(bundle["fpn"][k], shipped["fpn"][k]) for k in shipped["fpn"])  # the FPN did learn
    run = load_checkpoint(done["work"] / "fpn" / "adapt-last.pt", ("adapt",))
    teacher = {k[len("teacher.") :]: v for k, v in run["adapt"].items() if k.startswith("teacher.")}
    assert all(torch.equal(bundle["fpn"][k], teacher[k]) for k in bundle["fpn"])  # the teacher is what ships
    assert load_predictor(tmp_path / "adapted.pt", "cpu", engine="torch") is not None
    stamps = {p: p.stat().st_mtime_ns for p in (done["work"] / "fpn" / "fpn.pt", done["work"] / "afanet" / "afanet.pt")}
    adapt([city], tmp_path / "again.pt", **kwargs)  # the same work folder: both runs are done already
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    with pytest.raises(InputError, match="other inputs or settings"):
        adapt([city], tmp_path / "other.pt", method=AdaptConfig(mix=False), **kwargs)


def test_adapt_and_finetune_take_each_others_bundles(city, synthetic, tmp_path):
    """Either order works: finetune starts from an adapted bundle, adapt from a fine-tuned one,
    and each provenance names the bundle it started from."""
    from csboundary.models.checkpoint import file_sha256, load_checkpoint
    from csboundary.pipeline.training.finetune import FinetuneBudget, finetune

    cache = synthetic
    adapt(
        [city],
        tmp_path / "adapted.pt",
        work=tmp_path / "a",
        budget=AdaptBudget(fpn_steps=2, afanet_steps=0, synthetic_cities=1, crop=128),
        cache=cache,
        device="cpu",
        progress=False,
    )
    finetune(
        [city],
        tmp_path / "adapted-tuned.pt",
        weights=tmp_path / "adapted.pt",
        work=tmp_path / "b",
        budget=FinetuneBudget(fpn_steps=2, afanet_steps=1, synthetic_cities=1, crop=128, batch=2),
        cache=cache,
        device="cpu",
        progress=False,
    )
    tuned = load_checkpoint(tmp_path / "adapted-tuned.pt", ("bundle",))
    assert tuned["provenance"]["finetune"]["base_sha256"] == file_sha256(tmp_path / "adapted.pt")
    assert tuned["provenance"]["base"]["adapt"]["method"]["mix"] is True  # the adaptation stays on record
    adapt(
        [city],
        tmp_path / "tuned-adapted.pt",
        weights=tmp_path / "adapted-tuned.pt",
        work=tmp_path / "c",
        budget=AdaptBudget(fpn_steps=2, afanet_steps=0, synthetic_cities=1, crop=128),
        cache=cache,
        device="cpu",
        progress=False,
    )
    again = load_checkpoint(tmp_path / "tuned-adapted.pt", ("bundle",))
    assert again["provenance"]["adapt"]["base_sha256"] == file_sha256(tmp_path / "adapted-tuned.pt")
    assert all(
        torch.equal(again["afanet"][k], tuned["afanet"][k]) for k in tuned["afanet"]
    )  # --afanet-steps 0 keeps the AfANet
