"""Review edits that cannot damage a prediction (apply-review run as a user runs it): each edit
names its edge and carries its geometry, the pair is checked; the file carries the fingerprint of
the graph it was made on; the same file applied twice changes nothing the second time; coordinates
must be finite numbers inside the imagery; every refusal is one line and leaves the outputs as
they were."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest

from csboundary.data.windows import pixel_to_world
from csboundary.graph import BoundaryGraph
from csboundary.graph.chains import edge_line
from helpers import run_cli


@pytest.fixture
def prediction(demo_run, tmp_path) -> Path:
    out = tmp_path / "prediction"
    shutil.copytree(demo_run / "prediction", out)
    return out


def world_line(graph: BoundaryGraph, k: int) -> list[list[float]]:
    line = edge_line(graph, k)
    xs, ys = pixel_to_world(graph.transform, line[:, 0], line[:, 1])
    return [[float(x), float(y)] for x, y in zip(xs, ys)]


def edits_file(path: Path, prediction: Path, features: list[dict], fingerprint: bool = True) -> Path:
    props = {"crs": json.loads((prediction / "graph.json").read_text()).get("crs"), "tool": "test"}
    if fingerprint:
        props["graph_sha256"] = hashlib.sha256((prediction / "graph.json").read_bytes()).hexdigest()
    path.write_text(json.dumps({"type": "FeatureCollection", "properties": props, "features": features}))
    return path


def delete(graph: BoundaryGraph, k: int) -> dict:
    return {
        "type": "Feature",
        "properties": {"action": "delete", "edge": k},
        "geometry": {"type": "LineString", "coordinates": world_line(graph, k)},
    }


def refused(prediction: Path, edits: Path, phrase: str) -> None:
    before = (prediction / "graph.json").read_bytes()
    done = run_cli("apply-review", str(prediction), str(edits))
    assert done.returncode != 0, done.stdout
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and phrase in lines[0], done.stderr
    assert (prediction / "graph.json").read_bytes() == before


def test_the_same_edits_twice_change_nothing_the_second_time(prediction, tmp_path):
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    edits = edits_file(tmp_path / "e.geojson", prediction, [delete(graph, 3)])
    first = run_cli("apply-review", str(prediction), str(edits))
    assert first.returncode == 0, first.stderr
    after = (prediction / "graph.json").read_bytes()
    assert BoundaryGraph.read_json(prediction / "graph.json").n_edges == graph.n_edges - 1
    second = run_cli("apply-review", str(prediction), str(edits))
    assert second.returncode == 0, second.stderr
    assert "already applied" in second.stdout
    assert (prediction / "graph.json").read_bytes() == after


def test_edits_made_on_another_graph_are_refused(prediction, tmp_path):
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    old = edits_file(tmp_path / "old.geojson", prediction, [delete(graph, 5)])
    assert (
        run_cli(
            "apply-review", str(prediction), str(edits_file(tmp_path / "e.geojson", prediction, [delete(graph, 3)]))
        ).returncode
        == 0
    )
    refused(prediction, old, "another version of graph.json")


def test_an_edge_whose_geometry_does_not_match_is_refused(prediction, tmp_path):
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    wrong = delete(graph, 3)
    wrong["properties"]["edge"] = 4  # the geometry of edge 3 under the id of edge 4
    refused(
        prediction, edits_file(tmp_path / "e.geojson", prediction, [wrong], fingerprint=False), "does not match edge 4"
    )


@pytest.mark.parametrize(
    "edit, phrase",
    [
        ({"properties": {"action": "delete", "edge": True}}, "not an edge"),
        ({"properties": {"action": "delete", "edge": 0}}, "no geometry"),
        (
            {"properties": {"action": "move", "vertex": 0}, "geometry": {"type": "Point", "coordinates": ["a", "b"]}},
            "not two numbers",
        ),
        (
            {"properties": {"action": "move", "vertex": 0}, "geometry": {"type": "Point", "coordinates": [5.0]}},
            "not two numbers",
        ),
        (
            {
                "properties": {"action": "move", "vertex": 0},
                "geometry": {"type": "Point", "coordinates": [float("nan"), float("nan")]},
            },
            "not finite",
        ),
        (
            {"properties": {"action": "move", "vertex": 0}, "geometry": {"type": "Point", "coordinates": [1e12, 1e12]}},
            "outside the imagery",
        ),
        (
            {
                "properties": {"action": "add"},
                "geometry": {"type": "LineString", "coordinates": [[-74.0, 40.7], [-74.001, 40.7]]},
            },
            "outside the imagery",
        ),
        (
            {"properties": {"action": "add"}, "geometry": {"type": "LineString", "coordinates": [[1, "x"], [2, 3]]}},
            "not two numbers",
        ),
    ],
)
def test_malformed_edits_are_one_line_each(prediction, tmp_path, edit, phrase):
    feature = {"type": "Feature", "geometry": None, **edit}
    raw = json.dumps({"type": "FeatureCollection", "features": [feature]}, allow_nan=True)
    (tmp_path / "e.geojson").write_text(raw)
    refused(prediction, tmp_path / "e.geojson", phrase)
