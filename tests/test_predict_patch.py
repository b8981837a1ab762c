"""predict-patch and evaluate-model from the command line, with small untrained weights."""

from __future__ import annotations

import json

import pytest
import torch

from helpers import run_cli
from csboundary.models.afanet import AfANet, AfANetConfig
from csboundary.models.checkpoint import save_checkpoint
from csboundary.models.fpn import FPN, FPNConfig


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
    save_checkpoint(path, "bundle", fpn=fpn.state_dict(), fpn_config=fpn_config.to_dict(),
                    afanet=AfANet(afanet_config).state_dict(), afanet_config=afanet_config.to_dict(),
                    inference={"edge_threshold": 0.5, "max_degree": 2})
    return path


@pytest.fixture(scope="module")
def small_city(tmp_path_factory):
    out = tmp_path_factory.mktemp("c") / "city"
    result = run("synth", str(out), "--tile-size", "600", "--gsd", "0.3", "--seed", "1", "--split", "test", "--quiet")
    assert result.returncode == 0, result.stderr
    return out


def test_predict_patch_writes_graph_geojson_and_overlay(bundle, small_city, tmp_path):
    result = run("predict-patch", str(small_city / "tiles" / "tile_r00_c00.tif"), "--out", str(tmp_path / "p"), "--weights", str(bundle), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    graph = json.loads((tmp_path / "p" / "graph.json").read_text())
    assert graph["format"] == "csboundary-graph" and graph["crs"] == "EPSG:32618" and graph["transform"][0] == pytest.approx(0.3)
    geojson = json.loads((tmp_path / "p" / "boundaries.geojson").read_text())
    assert geojson["type"] == "FeatureCollection" and len(geojson["features"]) == len(graph["edges"])
    assert (tmp_path / "p" / "overlay.png").stat().st_size > 1000


def test_wrong_weights_file_is_one_line_error(small_city, tmp_path):
    junk = tmp_path / "weights.pt"
    junk.write_text("no weights here")
    result = run("predict-patch", str(small_city / "tiles" / "tile_r00_c00.tif"), "--out", str(tmp_path / "p"), "--weights", str(junk))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {junk}: not a readable weights file")
    assert not (tmp_path / "p" / "graph.json").exists()


def test_too_large_image_is_refused(bundle, tmp_path):
    out = tmp_path / "big"
    assert run("synth", str(out), "--tile-size", "1200", "--gsd", "0.3", "--quiet").returncode == 0
    result = run("predict-patch", str(out / "tiles" / "tile_r00_c00.tif"), "--out", str(tmp_path / "p"), "--weights", str(bundle))
    assert result.returncode == 2 and "at most 1100x1100" in result.stderr


def test_evaluate_model_scores_every_patch(bundle, small_city, tmp_path):
    result = run("evaluate-model", str(small_city), "--weights", str(bundle), "--json", str(tmp_path / "e.json"), "--quiet", "--device", "cpu")
    assert result.returncode == 0, result.stderr
    scores = json.loads((tmp_path / "e.json").read_text())
    assert scores["scale"] == "patch" and scores["counts"]["patches"] == 1
    assert all(0.0 <= v <= 1.0 for v in scores["metrics"].values() if v is not None)


def test_sixteen_bit_imagery_is_refused(bundle, tmp_path):
    import numpy as np
    from affine import Affine

    from csboundary.data.geotiff import write_geotiff

    path = write_geotiff(tmp_path / "u16.tif", np.full((4, 64, 64), 1000, np.uint16), Affine(0.3, 0, 0, 0, -0.3, 0), "EPSG:32618")
    result = run("predict-patch", str(path), "--out", str(tmp_path / "p"), "--weights", str(bundle))
    assert result.returncode == 2 and "8-bit" in result.stderr and str(path) in result.stderr
