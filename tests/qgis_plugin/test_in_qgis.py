"""The QGIS plugin inside QGIS (Debian's 3.22, headless): installed from its zip into a fresh
profile, run by ``qgis_process`` and through the QGIS Python API (qgis_session.py, run by QGIS's
own Python). Marked ``qgis``: out of the default run, skipped where QGIS is absent; ``make
qgis-test`` installs QGIS and runs them (and writes docs/qgis-layers.jpg from the Detect run)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SESSION = Path(__file__).with_name("qgis_session.py")
CSBOUNDARY = Path(sys.executable).parent / "csboundary"
QGIS_PYTHON = "/usr/bin/python3"
# Debian's qgis_process wrapper passes --noversioncheck, which 3.22's executable refuses: run the executable itself
QGIS_PROCESS = shutil.which("qgis_process.bin") or shutil.which("qgis_process")

pytestmark = [
    pytest.mark.qgis,
    pytest.mark.skipif(QGIS_PROCESS is None or not Path(QGIS_PYTHON).exists(), reason="QGIS is not installed"),
]


@pytest.fixture(scope="module")
def qgis(tmp_path_factory) -> dict:
    """A fresh QGIS profile with the plugin installed from the zip that ``make qgis-plugin`` builds,
    and the environment the plugin finds csboundary in."""
    home = tmp_path_factory.mktemp("qgis")
    archive = home / "csboundary_qgis.zip"
    from helpers import run_cli

    assert run_cli("qgis-plugin", "--out", str(archive)).returncode == 0
    plugins = home / "data" / "QGIS" / "QGIS3" / "profiles" / "default" / "python" / "plugins"
    plugins.mkdir(parents=True)
    with zipfile.ZipFile(archive) as zipped:
        zipped.extractall(plugins)
    runtime = home / "runtime"
    runtime.mkdir(mode=0o700)
    env = dict(
        os.environ,
        QT_QPA_PLATFORM="offscreen",
        XDG_DATA_HOME=str(home / "data"),
        XDG_RUNTIME_DIR=str(runtime),
        CSBOUNDARY_COMMAND=str(CSBOUNDARY),
    )
    env.pop("PYTHONPATH", None)
    enabled = subprocess.run(
        [QGIS_PROCESS, "plugins", "enable", "csboundary_qgis"], env=env, capture_output=True, text=True
    )
    assert enabled.returncode == 0, enabled.stdout + enabled.stderr
    return {"env": env, "plugins": plugins, "home": home}


def session(qgis: dict, request: dict, tmp_path: Path) -> dict:
    (tmp_path / "request.json").write_text(json.dumps(request))
    done = subprocess.run(
        [
            QGIS_PYTHON,
            str(SESSION),
            str(qgis["plugins"]),
            str(tmp_path / "request.json"),
            str(tmp_path / "report.json"),
        ],
        env=qgis["env"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return json.loads((tmp_path / "report.json").read_text())


def tiles(demo_run: Path) -> list[str]:
    return sorted(str(p) for p in (demo_run / "city" / "tiles").glob("*.tif"))


def test_qgis_process_lists_the_algorithms_and_runs_detect_on_the_demo_city(qgis, demo_run, tmp_path):
    listed = subprocess.run([QGIS_PROCESS, "list"], env=qgis["env"], capture_output=True, text=True)
    names = {line.split()[0] for line in listed.stdout.splitlines() if line.strip().startswith("csboundary:")}
    assert names == {
        "csboundary:detect",
        "csboundary:evaluate",
        "csboundary:exportlanelet2",
        "csboundary:applyreview",
        "csboundary:finetune",
        "csboundary:adapt",
    }
    out = tmp_path / "detect"
    args = [
        QGIS_PROCESS,
        "--json",
        "run",
        "csboundary:detect",
        "--",
        *[f"INPUT={t}" for t in tiles(demo_run)],
        f"OUTPUT={out}",
    ]
    done = subprocess.run(args, env=qgis["env"], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    results = json.loads(done.stdout[done.stdout.index("{") :])["results"]
    assert (
        results["OUTPUT"] == str(out) and results["REVIEW_BOUNDARIES"] == f"{out / 'review.gpkg'}|layername=boundaries"
    )
    assert results["REVIEW_HELD_BACK"] == f"{out / 'review.gpkg'}|layername=held_back"
    import pyogrio

    from csboundary.graph import BoundaryGraph
    from csboundary.graph.boundaries import graph_boundaries

    graph = json.loads((out / "graph.json").read_text())
    boundaries = len(graph_boundaries(BoundaryGraph.read_json(out / "graph.json")))
    counts = [pyogrio.read_info(out / "review.gpkg", layer=name)["features"] for name in ("boundaries", "held_back")]
    assert sum(counts) == boundaries and 0 < boundaries < len(graph["edges"])
    assert pyogrio.read_info(out / "review.gpkg", layer="complete")["geometry_type"] == "Polygon"
    # the lanelet2 export and the evaluation, through qgis_process too
    osm = tmp_path / "map.osm"
    done = subprocess.run(
        [
            QGIS_PROCESS,
            "--json",
            "run",
            "csboundary:exportlanelet2",
            "--",
            f"PREDICTION={out}",
            f"OUTPUT={osm}",
            "MIN_CONFIDENCE=0.2",
        ],
        env=qgis["env"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0 and osm.exists() and "road_border" in osm.read_text(), done.stderr[-2000:]
    scores = tmp_path / "scores.json"
    done = subprocess.run(
        [
            QGIS_PROCESS,
            "--json",
            "run",
            "csboundary:evaluate",
            "--",
            f"PREDICTION={out}",
            f"GROUND_TRUTH={demo_run / 'city' / 'ground_truth.gpkg'}",
            f"OUTPUT={scores}",
        ],
        env=qgis["env"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    results = json.loads(done.stdout[done.stdout.index("{") :])["results"]
    city = json.loads((demo_run / "scores.json").read_text())["city"]["metrics"]  # the demo's own city-scale scores
    assert abs(results["F1_5"] - city["f1@5"]) < 0.02 and abs(results["APLS"] - city["apls"]) < 0.05, (results, city)
    print(
        json.dumps({"evaluate through qgis_process": results, "demo": {k: city[k] for k in ("f1@5", "apls", "tlts")}})
    )
    # a ground-truth layer in another CRS is reprojected to the prediction's first
    import geopandas as gpd

    degrees = tmp_path / "gt-4326.gpkg"
    gpd.read_file(demo_run / "city" / "ground_truth.gpkg", layer="road_boundaries").to_crs("EPSG:4326").to_file(
        degrees, driver="GPKG"
    )
    done = subprocess.run(
        [
            QGIS_PROCESS,
            "--json",
            "run",
            "csboundary:evaluate",
            "--",
            f"PREDICTION={out}",
            f"GROUND_TRUTH={degrees}",
            f"OUTPUT={tmp_path / 'scores-4326.json'}",
        ],
        env=qgis["env"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    again = json.loads(done.stdout[done.stdout.index("{") :])["results"]
    assert abs(again["F1_5"] - results["F1_5"]) < 0.005 and abs(again["APLS"] - results["APLS"]) < 0.01, (
        again,
        results,
    )


def test_detect_loads_the_boundaries_and_review_layers_styled_by_confidence(qgis, demo_run, tmp_path):
    picture = os.environ.get("CSBOUNDARY_QGIS_PICTURE") or str(tmp_path / "qgis-layers.jpg")
    # outside /tmp, which QGIS counts as temporary (there it would name layers by their file either way)
    out = Path(tempfile.mkdtemp(dir="/var/tmp" if Path("/var/tmp").is_dir() else None)) / "detect"
    try:
        report = session(
            qgis,
            {"mode": "detect", "parameters": {"INPUT": tiles(demo_run), "OUTPUT": str(out)}, "picture": picture},
            tmp_path,
        )
        graph = json.loads((out / "graph.json").read_text())
    finally:
        shutil.rmtree(out.parent, ignore_errors=True)
    layers = {layer["name"]: layer for layer in report["layers"]}
    assert set(layers) == {"road boundaries", "boundaries to review", "held back from the review", "areas checked"}
    edges, held = layers["boundaries to review"], layers["held back from the review"]
    boundaries, areas = layers["road boundaries"], layers["areas checked"]
    assert (
        edges["features"] + held["features"] == boundaries["features"]
        and edges["geometry_type"] == 1
        and edges["crs"] == "EPSG:32618"
    )
    assert 0 < boundaries["features"] < len(graph["edges"]) and areas["features"] == 0 and areas["geometry_type"] == 2
    assert edges["visible"] and not held["visible"]  # the held-back boundaries are off until asked for
    for layer, field in ((edges, "confidence"), (held, "confidence"), (boundaries, "confidence_mean")):
        assert layer["renderer"] == "graduatedSymbol" and layer["class_attribute"] == f'coalesce("{field}", -1)'
        drawn, lowest, highest = layer["classes"][0], layer["classes"][1], layer["classes"][-1]
        assert drawn["lower"] < -1 < drawn["upper"] < 0 and lowest["lower"] == 0 and highest["upper"] >= 1
        assert layer["null_colour"] == drawn["colour"], (
            "a line drawn by the reviewer (confidence NULL) would not show grey"
        )
        red, blue = (int(lowest["colour"][1:3], 16), int(lowest["colour"][5:7], 16))
        assert red > 2 * blue, f"the least sure class is not warm: {lowest['colour']}"
    assert report["stages"][0] == "predict patches" and report["percents"][-1] == 100
    assert Path(picture).stat().st_size > 50_000


def test_apply_review_of_a_layer_edited_with_qgis_gives_the_page_s_graph(qgis, demo_run, tmp_path):
    """Delete a boundary, drag a junction (every boundary ending there), draw a line, draw a
    checked area: with QGIS's editing API on the review GeoPackage, then Apply review; the same
    edits exported by the review page and applied by the command give the same graph, and the
    edited file's layers leave the project."""
    from csboundary.data.windows import pixel_to_world
    from csboundary.graph import BoundaryGraph
    from helpers import run_cli

    sys.path.insert(0, str(ROOT / "tests" / "pipeline" / "outputs"))
    from test_review_edits_checked import edits_file, world_line

    gis, page = tmp_path / "gis", tmp_path / "page"
    shutil.copytree(demo_run / "prediction", gis)
    shutil.copytree(demo_run / "prediction", page)
    assert run_cli("review", str(gis), "--gpkg", str(gis / "review.gpkg")).returncode == 0
    graph = BoundaryGraph.read_json(gis / "graph.json")

    def world(points):
        xs, ys = pixel_to_world(graph.transform, points[:, 0], points[:, 1])
        return np.stack([np.atleast_1d(xs), np.atleast_1d(ys)], axis=-1)

    from csboundary.graph.boundaries import graph_boundaries
    from csboundary.pipeline.outputs.review import review_boundaries

    degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    deleted = 3
    gone = next(b for b in graph_boundaries(graph) if deleted in b.edges)
    vertex = int(
        next(i for i in range(graph.n_vertices) if degree[i] == 3 and i not in graph.edges[gone.edges].ravel())
    )
    moved_from = world(graph.vertices[vertex][None])[0].tolist()
    moved_to = world((graph.vertices[vertex] + np.array([4.0, -3.0]))[None])[0].tolist()
    chains, draft, _ = review_boundaries(graph)
    ends_here = sum(
        int(np.allclose(b.polyline[j], graph.vertices[vertex])) for b, d in zip(chains, draft) if d for j in (0, -1)
    )
    drawn = world(np.array([[500.0, 500.0], [540.0, 520.0], [600.0, 520.0]])).tolist()
    area = world(np.array([[100.0, 100.0], [900.0, 100.0], [900.0, 900.0], [100.0, 900.0], [100.0, 100.0]])).tolist()
    report = session(
        qgis,
        {
            "mode": "review",
            "edited": str(gis / "review.gpkg"),
            "prediction": str(gis),
            "next_review": str(gis / "review-2.gpkg"),
            "delete_edge": deleted,
            "move_from": moved_from,
            "move_to": moved_to,
            "draw": drawn,
            "area": area,
        },
        tmp_path,
    )
    assert report["line_ends_moved"] == ends_here > 0
    assert report["refusals"]["same_file"].endswith("the next review GeoPackage must be a new file, not the edited one")
    assert (
        report["refusals"]["unsaved"]
        == "boundaries to review has unsaved edits: save them (Save Layer Edits) before Apply review"
    )
    features = [
        {
            "type": "Feature",
            "properties": {"action": "delete", "edge": k},
            "geometry": {"type": "LineString", "coordinates": world_line(graph, k)},
        }
        for k in sorted(gone.edges.tolist())
    ]
    features += [
        {
            "type": "Feature",
            "properties": {"action": "move", "vertex": vertex},
            "geometry": {"type": "Point", "coordinates": moved_to},
        },
        {"type": "Feature", "properties": {"action": "add"}, "geometry": {"type": "LineString", "coordinates": drawn}},
        {
            "type": "Feature",
            "properties": {"action": "complete"},
            "geometry": {"type": "Polygon", "coordinates": [area]},
        },
    ]
    done = run_cli("apply-review", str(page), str(edits_file(tmp_path / "edits.geojson", page, features)))
    assert done.returncode == 0, done.stderr
    a, b = BoundaryGraph.read_json(page / "graph.json"), BoundaryGraph.read_json(gis / "graph.json")
    assert a.n_edges == b.n_edges and a.n_vertices == b.n_vertices
    assert (
        np.allclose(a.vertices, b.vertices, atol=1e-6) and (a.edges == b.edges).all() and a.edge_kinds == b.edge_kinds
    )
    page_record, gis_record = (json.loads((p / "review.json").read_text())["reviews"][-1] for p in (page, gis))
    for key in ("deleted_edges", "moved_vertices", "added_edges", "edge_index_map", "held_back_deleted"):
        assert page_record[key] == gis_record[key], key
    assert len(gis_record["complete_areas"]) == len(page_record["complete_areas"]) == 1
    import pyogrio

    next_round = sum(
        pyogrio.read_info(gis / "review-2.gpkg", layer=name)["features"] for name in ("boundaries", "held_back")
    )
    assert next_round == len(graph_boundaries(b))  # the next round's layers
    assert not any(
        str(gis / "review.gpkg") in source for source in report["sources_after"]
    )  # the edited file's layers are gone


def test_cancel_stops_detect_within_5_s_and_running_it_again_continues(qgis, demo_run, tmp_path):
    parameters = {
        "INPUT": tiles(demo_run),
        "OUTPUT": str(tmp_path / "detect"),
        "ENGINE": 1,
    }  # torch: slow enough to cancel mid-run
    report = session(qgis, {"mode": "cancel", "parameters": parameters}, tmp_path)
    assert report["outcome"].startswith("canceled"), report
    assert report["seconds_to_cancel"] < 5, report
    assert any(line.startswith("interrupted (SIGTERM)") for line in report["lines"]), report["lines"]
    work = json.loads((tmp_path / "detect" / "summary.json").read_text())["work"]
    assert work["patches_reused"] >= 1 and work["patches_reused"] + work["patches_predicted"] == 9, work
    print(json.dumps({k: report[k] for k in ("outcome", "seconds_before_cancel", "seconds_to_cancel")}))


def test_a_missing_csboundary_is_one_clear_message_in_qgis(qgis, demo_run, tmp_path):
    report = session(
        qgis,
        {
            "mode": "missing_command",
            "command": str(tmp_path / "nowhere" / "csboundary"),
            "parameters": {"INPUT": tiles(demo_run)[:1], "OUTPUT": str(tmp_path / "out")},
        },
        tmp_path,
    )
    assert report["outcome"].startswith(f"csboundary: {tmp_path / 'nowhere' / 'csboundary'}: not an executable file"), (
        report
    )
    assert "\n" not in report["outcome"] and "Traceback" not in report["outcome"]
