"""predict-patch, predict and evaluate-model from the command line, with small untrained weights."""

from __future__ import annotations

import json

import pytest
import torch

from csboundary.models.afanet import AfANet, AfANetConfig
from csboundary.models.checkpoint import save_checkpoint
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.pipeline.prediction.options import PredictionOptions
from helpers import run_cli

run = run_cli


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    torch.manual_seed(0)
    fpn_config = FPNConfig(widths=(8, 8, 8, 8), blocks=(1, 1, 1, 1), pyramid=8, stem=8)
    afanet_config = AfANetConfig(global_size=64, roi=16, encoder_widths=(8, 8), dim=32, layers=1)
    fpn = FPN(fpn_config)
    with torch.no_grad():  # keypoint logits: a few confident spots, so vertices exist and stay few
        fpn.head[-1].bias.fill_(-3.0)
    path = tmp_path_factory.mktemp("w") / "bundle.pt"
    save_checkpoint(
        path,
        "bundle",
        fpn=fpn.state_dict(),
        fpn_config=fpn_config.to_dict(),
        afanet=AfANet(afanet_config).state_dict(),
        afanet_config=afanet_config.to_dict(),
        inference={"edge_threshold": 0.5, "max_degree": 2},
        pixel_size_m=0.3,
    )  # the test city's pixel size
    return path


@pytest.fixture(scope="module")
def small_city(tmp_path_factory):
    out = tmp_path_factory.mktemp("c") / "city"
    result = run("synth", str(out), "--tile-size", "600", "--gsd", "0.3", "--seed", "1", "--split", "test", "--quiet")
    assert result.returncode == 0, result.stderr
    return out


def test_predict_patch_writes_graph_geojson_and_overlay(bundle, small_city, tmp_path):
    result = run(
        "predict-patch",
        str(small_city / "tiles" / "tile_r00_c00.tif"),
        "--out",
        str(tmp_path / "p"),
        "--weights",
        str(bundle),
        "--device",
        "cpu",
    )
    assert result.returncode == 0, result.stderr
    graph = json.loads((tmp_path / "p" / "graph.json").read_text())
    assert (
        graph["format"] == "csboundary-graph"
        and graph["crs"] == "EPSG:32618"
        and graph["transform"][0] == pytest.approx(0.3)
    )
    geojson = json.loads((tmp_path / "p" / "boundaries.geojson").read_text())
    assert geojson["type"] == "FeatureCollection" and len(geojson["features"]) == len(graph["edges"])
    assert (tmp_path / "p" / "overlay.png").stat().st_size > 1000


def test_wrong_weights_file_is_one_line_error(small_city, tmp_path):
    junk = tmp_path / "weights.pt"
    junk.write_text("no weights here")
    result = run(
        "predict-patch",
        str(small_city / "tiles" / "tile_r00_c00.tif"),
        "--out",
        str(tmp_path / "p"),
        "--weights",
        str(junk),
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {junk}: not a readable weights file")
    assert not (tmp_path / "p" / "graph.json").exists()


def test_too_large_image_is_refused(bundle, tmp_path):
    out = tmp_path / "big"
    assert run("synth", str(out), "--tile-size", "1200", "--gsd", "0.3", "--quiet").returncode == 0
    result = run(
        "predict-patch", str(out / "tiles" / "tile_r00_c00.tif"), "--out", str(tmp_path / "p"), "--weights", str(bundle)
    )
    assert result.returncode == 2 and "at most 1100x1100" in result.stderr


def test_evaluate_model_scores_every_patch(bundle, small_city, tmp_path):
    result = run(
        "evaluate-model",
        str(small_city),
        "--weights",
        str(bundle),
        "--json",
        str(tmp_path / "e.json"),
        "--quiet",
        "--device",
        "cpu",
    )
    assert result.returncode == 0, result.stderr
    scores = json.loads((tmp_path / "e.json").read_text())
    assert scores["patch"]["scale"] == "patch" and scores["patch"]["counts"]["patches"] == 1
    assert scores["city"]["scale"] == "city"
    for scale in ("patch", "city"):
        assert all(0.0 <= v <= 1.0 for v in scores[scale]["metrics"].values() if v is not None)
    assert "patch" in result.stdout and "city" in result.stdout


def test_sixteen_bit_imagery_is_stretched_with_a_warning(bundle, tmp_path):
    import numpy as np
    from affine import Affine

    from csboundary.data.geotiff import write_geotiff

    ramp = np.tile(np.linspace(0, 4000, 64, dtype=np.uint16), (4, 64, 1))
    path = write_geotiff(tmp_path / "u16.tif", ramp, Affine(0.3, 0, 0, 0, -0.3, 0), "EPSG:32618")
    result = run("predict-patch", str(path), "--out", str(tmp_path / "p"), "--weights", str(bundle))
    assert result.returncode == 0, result.stderr
    assert f"{path}: uint16 imagery stretched to 8 bits" in result.stderr
    assert (tmp_path / "p" / "graph.json").exists()


@pytest.fixture(scope="module")
def four_patch_city(tmp_path_factory):
    out = tmp_path_factory.mktemp("c4") / "city"
    result = run(
        "synth",
        str(out),
        "--tiles",
        "2x2",
        "--tile-size",
        "600",
        "--gsd",
        "0.3",
        "--seed",
        "2",
        "--split",
        "test",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    return out


def test_predict_writes_georeferenced_outputs_and_a_summary(bundle, four_patch_city, tmp_path):
    import geopandas as gpd
    import numpy as np
    import pyogrio
    import rasterio

    out = tmp_path / "pred"
    result = run(
        "predict",
        str(four_patch_city / "tiles"),
        "--out",
        str(out),
        "--weights",
        str(bundle),
        "--write-maps",
        "--quiet",
        "--device",
        "cpu",
    )
    assert result.returncode == 0, result.stderr
    names = {p.name for p in out.iterdir()}
    assert names == {
        "boundaries.gpkg",
        "boundaries.geojson",
        "graph.json",
        "overview.png",
        "detail.png",
        "maps.tif",
        "summary.json",
    }
    summary = json.loads((out / "summary.json").read_text())
    graph = json.loads((out / "graph.json").read_text())
    assert summary["patches"] == 4 and summary["grid"] == [2, 2] and summary["mosaic_px"] == [1200, 1200]
    assert summary["counts"]["edges"] == len(graph["edges"]) and summary["counts"]["vertex_pairs_within_1px"] == 0
    kinds = [e["kind"] for e in graph["edges"]]
    assert [summary["counts"][f"{k}_edges"] for k in ("corner", "skeleton", "attach")] == [
        kinds.count(k) for k in ("corner", "skeleton", "attach")
    ]
    assert set(summary["seconds_per_patch"]) >= {
        "fpn",
        "map_stitching",
        "vertex_extraction",
        "afanet",
        "graph_stitching",
        "total",
    }
    assert summary["area_km2"] == pytest.approx(1200 * 1200 * 0.09 / 1e6)
    assert {layer for layer, _ in pyogrio.list_layers(out / "boundaries.gpkg")} == {"road_boundaries", "edges"}
    lines = gpd.read_file(out / "boundaries.gpkg", layer="road_boundaries")
    assert lines.crs.to_epsg() == 32618
    with rasterio.open(
        four_patch_city / "tiles" / sorted(p.name for p in (four_patch_city / "tiles").iterdir())[0]
    ) as src:
        x0, y1 = src.transform @ (0, 0)
    if len(lines):  # world coordinates inside the 360 m x 360 m city
        minx, miny, maxx, maxy = lines.total_bounds
        assert x0 - 20 <= minx and maxx <= x0 + 380 and y1 - 380 <= miny and maxy <= y1 + 20
    with rasterio.open(out / "maps.tif") as maps:
        assert maps.count == 2 and maps.dtypes == ("uint8", "uint8") and (maps.width, maps.height) == (1200, 1200)
        assert maps.crs.to_epsg() == 32618 and maps.profile["tiled"] and maps.overviews(1)
        assert maps.descriptions == ("keypoint_probability", "segmentation_probability")
        assert np.isclose(maps.transform.c, x0) and np.isclose(maps.transform.f, y1)


def test_an_fpn_with_a_surface_head_writes_a_third_map_band_and_its_check_drops_edges_beside_no_roadway(
    bundle, four_patch_city, tmp_path
):
    import rasterio

    payload = torch.load(bundle, weights_only=True)
    config = FPNConfig.from_dict({**payload["fpn_config"], "surface": True})
    torch.manual_seed(0)
    fpn = FPN(config)
    fpn.load_state_dict(payload["fpn"], strict=False)

    def predicted(road_bias: float, name: str) -> dict:
        with torch.no_grad():
            fpn.head[-1].bias[1] = 5.0  # boundary everywhere: its skeleton is filled in as edges
            fpn.surface_head[-1].bias.fill_(road_bias)
        weights = tmp_path / f"{name}.pt"
        content = {k: v for k, v in payload.items() if k not in ("format", "kind", "code_version", "inference")}
        save_checkpoint(
            weights,
            "bundle",
            **{
                **content,
                "fpn": fpn.state_dict(),
                "fpn_config": config.to_dict(),
                "inference": {"edge_threshold": 0.5, "max_degree": 2, "fill_min_length_px": 40},
            },
        )
        out = tmp_path / name
        result = run(
            "predict",
            str(four_patch_city / "tiles"),
            "--out",
            str(out),
            "--weights",
            str(weights),
            "--write-maps",
            "--quiet",
            "--device",
            "cpu",
            "--surface-check",
            "0.5",
            "--engine",
            "torch",
        )  # two networks: no ONNX export of each
        assert result.returncode == 0, result.stderr
        return json.loads((out / "summary.json").read_text())

    assert predicted(10.0, "road")["counts"]["edges"] > 0  # roadway everywhere: every filled edge has it beside it
    assert predicted(-10.0, "lawn")["counts"]["edges"] == 0  # roadway nowhere: the check drops them all
    with rasterio.open(tmp_path / "lawn" / "maps.tif") as maps:
        assert maps.count == 3 and maps.descriptions[2] == "road_surface_probability"
        assert maps.read(3).max() == 0  # sigmoid(-10) rounds to 0 of 255


def test_an_interrupted_predict_leaves_no_final_file(bundle, four_patch_city, tmp_path, monkeypatch):
    from csboundary.data.raster import Mosaic
    from csboundary.pipeline.jobs import prediction_run as job
    from csboundary.pipeline.prediction import map_stitching
    from csboundary.pipeline.prediction.patch import PatchPredictor

    out = tmp_path / "pred"
    out.mkdir()
    (out / "summary.json").write_text("{}")  # from an earlier run: must not vouch for this one
    calls = []
    original = map_stitching.WindowSchedule.add_maps

    def add_then_interrupt(self, index):
        calls.append(index)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return original(self, index)

    monkeypatch.setattr(map_stitching.WindowSchedule, "add_maps", add_then_interrupt)
    predictor = PatchPredictor.load(bundle, torch.device("cpu"))
    with Mosaic.open(four_patch_city / "tiles") as mosaic, pytest.raises(KeyboardInterrupt):
        job.run_prediction(mosaic, predictor, out, PredictionOptions(write_maps=True, progress=False))
    assert [p.name for p in out.iterdir()] == [
        ".csboundary-run"
    ]  # no outputs, no scratch maps, no stale summary; the work kept


def test_predict_on_a_non_raster_is_one_line_error(tmp_path):
    bad = tmp_path / "notes.tif"
    bad.write_text("not an image")
    result = run("predict", str(bad), "--out", str(tmp_path / "o"), "--device", "cpu", "--quiet")
    assert result.returncode == 2 and result.stderr.strip().count("\n") == 0 and "notes.tif" in result.stderr
