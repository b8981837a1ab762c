"""The review page in a real browser (headless Chromium): it renders the imagery and the review
draft's boundaries, the least sure boundary first in the list; deleting it and exporting gives
edits that apply-review turns into a graph with exactly its edges less; cut and delete-below act
on boundaries. Plus apply_edits by hand."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from csboundary.graph import BoundaryGraph
from csboundary.graph.review_edits import EditError, apply_edits
from helpers import run_cli, square_graph

CHROMIUM, DRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")


@pytest.fixture(scope="module")
def reviewed(demo_run, tmp_path_factory):
    """A predicted demo city (its own copy) and its review page."""
    pred = tmp_path_factory.mktemp("review") / "pred"
    shutil.copytree(demo_run / "prediction", pred)
    done = run_cli("review", str(pred), "--quiet")
    assert done.returncode == 0, done.stderr
    assert "ground truth" in done.stdout  # the demo city's own, found through the prediction's inputs
    return pred


@pytest.fixture
def browser():
    webdriver = pytest.importorskip("selenium.webdriver")
    if not (CHROMIUM.exists() and DRIVER.exists()):
        reason = "needs Debian's chromium and chromium-driver: apt-get install chromium chromium-driver (.ci/run installs them)"
        if os.environ.get("CSBOUNDARY_BROWSER_TESTS") == "required":  # CI: a browser test never skips unseen
            pytest.fail(reason)
        pytest.skip(reason)
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-background-networking",
        "--disable-gpu",
        "--window-size=1400,900",
        "--allow-file-access-from-files",
    ):
        options.add_argument(flag)
    from selenium.webdriver.chrome.service import Service

    driver = webdriver.Chrome(service=Service(str(DRIVER)), options=options)
    yield driver
    driver.quit()


def _wait(driver, script: str, timeout: float = 20.0):
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for: {script}")


def test_delete_the_least_sure_boundary_in_the_browser_and_apply_it(reviewed, browser, tmp_path):
    import cv2
    from selenium.webdriver.common.by import By

    from csboundary.graph.boundaries import graph_boundaries
    from csboundary.metrics.review_time import ReviewCosts
    from csboundary.pipeline.outputs.review import review_boundaries

    graph = json.loads((reviewed / "graph.json").read_text())
    city = BoundaryGraph.read_json(reviewed / "graph.json")
    boundaries, draft, metres_per_px = review_boundaries(city)
    assert len(boundaries) == len(graph_boundaries(city)) < city.n_edges  # fewer things to look at than edges
    shown = [b for b, d in zip(boundaries, draft) if d]
    least = min(shown, key=lambda b: b.confidence)

    browser.get((reviewed / "review" / "index.html").as_uri())
    _wait(browser, "return window.review && window.review.loadedTiles() > 0")
    rows = [li for li in browser.find_elements(By.CSS_SELECTOR, "#edge-list li") if li.is_displayed()]
    assert len(rows) == len(shown) == browser.execute_script("return window.review.boundaryCount()")
    assert sorted(int(k) for k in rows[0].get_attribute("data-edges").split(",")) == sorted(least.edges.tolist())
    shot = cv2.imdecode(
        np.frombuffer(browser.find_element(By.ID, "view").screenshot_as_png, np.uint8), cv2.IMREAD_COLOR
    )
    assert shot.std() > 20  # imagery and lines, not an empty canvas

    costs = ReviewCosts()
    look = lambda b: (costs.look_seconds(b.length_px, metres_per_px) + costs.delete_s * (1 - b.confidence)) / 60  # noqa: E731
    left, minutes = browser.execute_script("return window.review.remaining()")
    assert left == len(shown) and minutes == pytest.approx(sum(look(b) for b in shown), rel=1e-6)
    status = browser.find_element(By.ID, "status").text
    assert f"{len(shown)} boundaries left to look at: about {minutes:.1f} min" in status

    rows[0].click()
    browser.find_element(By.ID, "delete").click()
    left_after, minutes_after = browser.execute_script("return window.review.remaining()")
    assert left_after == left - 1 and minutes_after == pytest.approx(minutes - look(least), rel=1e-6)
    browser.find_element(By.ID, "export").click()
    edits = browser.find_element(By.ID, "export-text").get_attribute("value")
    collection = json.loads(edits)
    assert sorted(f["properties"]["edge"] for f in collection["features"]) == sorted(least.edges.tolist())
    assert {f["properties"]["action"] for f in collection["features"]} == {"delete"}

    (tmp_path / "edits.geojson").write_text(edits)
    done = run_cli("apply-review", str(reviewed), str(tmp_path / "edits.geojson"))
    assert done.returncode == 0, done.stderr
    after = json.loads((reviewed / "graph.json").read_text())
    strip = lambda e: (e["u"], e["v"], e.get("score"), e.get("kind"))  # noqa: E731
    gone = set(least.edges.tolist())
    assert [strip(e) for e in after["edges"]] == [strip(e) for k, e in enumerate(graph["edges"]) if k not in gone]
    log = json.loads((reviewed / "review.json").read_text())["reviews"][-1]
    assert sorted(log["deleted_edges"]) == sorted(gone) and log["edges_after"] == len(graph["edges"]) - len(gone)


def test_cut_a_boundary_and_sweep_an_area_in_the_browser(reviewed, browser):
    """Cut splits the selected boundary at the vertex nearest the click: deleting one part
    exports only its edges. Delete below, over the whole imagery at confidence 1.01, deletes
    every boundary shown."""
    assert (
        run_cli("review", str(reviewed), "--quiet").returncode == 0
    )  # a fresh page: another test may have changed graph.json
    browser.get((reviewed / "review" / "index.html").as_uri())
    _wait(browser, "return window.review && window.review.loadedTiles() > 0")
    r = "window.review"
    long = browser.execute_script(f"return {r}.boundaries.findIndex((b) => b.draft && b.edges.length >= 4)")
    assert long >= 0
    edges = browser.execute_script(f"return {r}.boundaries[{long}].edges.slice()")
    vertices = browser.execute_script(f"return {r}.boundaryVertices({r}.boundaries[{long}])")
    assert len(vertices) == len(edges) + 1
    tail = browser.execute_script(f"""const r = {r}; r.select({long}); const p = REVIEW_DATA.vertices[{vertices[2]}];
                                      r.state.cutting = true; return r.cutAt([p[0] + 0.3, p[1]]);""")
    assert browser.execute_script(f"return {r}.boundaries[{long}].edges") == edges[:2]
    assert browser.execute_script(f"return {r}.boundaries[{tail}].edges") == edges[2:]
    browser.execute_script(f"{r}.select({tail}); {r}.remove();")
    exported = json.loads(browser.execute_script(f"return {r}.exportEdits()"))
    assert sorted(f["properties"]["edge"] for f in exported["features"]) == sorted(edges[2:])

    count = browser.execute_script(f"""const r = {r}, w = REVIEW_DATA.width, h = REVIEW_DATA.height;
                                       return r.sweep([[-1, -1], [w + 1, -1], [w + 1, h + 1], [-1, h + 1]], 1.01);""")
    shown = browser.execute_script(f"return {r}.boundaries.filter((b) => b.draft).length")
    assert count == shown - 1  # every shown boundary but the part deleted before
    left, _ = browser.execute_script(f"return {r}.remaining()")
    assert left == 0


def test_mark_the_view_complete_in_the_browser_and_apply_it(reviewed, browser, tmp_path):
    """View complete exports the imagery on screen as a closed Polygon in the prediction's CRS;
    apply-review records it in review.json, where fine-tuning finds its labels."""
    from selenium.webdriver.common.by import By

    assert (
        run_cli("review", str(reviewed), "--quiet").returncode == 0
    )  # a fresh page: another test may have changed graph.json
    browser.get((reviewed / "review" / "index.html").as_uri())
    _wait(browser, "return window.review && window.review.loadedTiles() > 0")
    browser.find_element(By.ID, "view-complete").click()
    browser.find_element(By.ID, "export").click()
    collection = json.loads(browser.find_element(By.ID, "export-text").get_attribute("value"))
    [feature] = collection["features"]
    ring = feature["geometry"]["coordinates"][0]
    assert feature["properties"] == {"action": "complete"} and feature["geometry"]["type"] == "Polygon"
    assert len(ring) == 5 and ring[0] == ring[-1]
    summary = json.loads((reviewed / "summary.json").read_text())
    graph = BoundaryGraph.read_json(reviewed / "graph.json")
    width, height = summary["mosaic_px"]
    t = graph.transform
    xs, ys = [t.c, t.c + t.a * width], [t.f, t.f + t.e * height]
    for x, y in ring:  # the whole image fits the view at first: the area is the imagery, clipped to it
        assert min(xs) - 1e-6 <= x <= max(xs) + 1e-6 and min(ys) - 1e-6 <= y <= max(ys) + 1e-6
    (tmp_path / "edits.geojson").write_text(json.dumps(collection))
    done = run_cli("apply-review", str(reviewed), str(tmp_path / "edits.geojson"))
    assert done.returncode == 0, done.stderr
    assert json.loads((reviewed / "review.json").read_text())["reviews"][-1]["complete_areas"] == [ring]


def test_edits_by_hand():
    features = [
        {
            "properties": {"action": "delete", "edge": 0},
            "geometry": {"type": "LineString", "coordinates": [[100.0, 200.0], [105.0, 200.0]]},
        },
        {
            "properties": {
                "action": "accept",
                "edge": 1,
            },  # drawn from its other end: the pair is checked either way round
            "geometry": {"type": "LineString", "coordinates": [[105.0, 195.0], [106.0, 197.5], [105.0, 200.0]]},
        },
        {
            "properties": {"action": "move", "vertex": 2},
            "geometry": {"type": "Point", "coordinates": [105.0, 194.0]},
        },  # pixel (10, 12)
        {
            "properties": {"action": "add"},
            "geometry": {"type": "LineString", "coordinates": [[100.2, 200.0], [90.0, 190.0]]},
        },
    ]
    graph, record = apply_edits(square_graph(), features)
    assert (
        graph.n_edges == 2
        and record.deleted == [0]
        and record.accepted == [0]
        and record.moved == [2]
        and record.added == [1]
    )
    assert np.allclose(graph.vertices[2], [10, 12])
    assert np.allclose(graph.edge_polylines[0][-1], [10, 12])  # the corner edge's polyline follows its moved end
    assert tuple(graph.edges[1]) == (0, 3)  # starts on vertex 0 (0.4 px away: snapped), ends on a new vertex
    assert np.allclose(graph.vertices[3], [-20, 20]) and graph.edge_kinds[1] == "manual" and graph.edge_scores[1] == 1.0
    assert record.kept == {1: 0}


def test_a_complete_area_is_recorded_and_changes_nothing():
    square = [[100.0, 200.0], [104.0, 200.0], [104.0, 196.0], [100.0, 196.0]]  # pixels (0, 0)-(8, 8), given unclosed
    graph, record = apply_edits(
        square_graph(),
        [{"properties": {"action": "complete"}, "geometry": {"type": "Polygon", "coordinates": [square]}}],
    )
    assert record.complete_areas == [[*square, square[0]]]
    assert (
        graph.n_edges == 2 and np.array_equal(graph.vertices, square_graph().vertices) and record.kept == {0: 0, 1: 1}
    )


@pytest.mark.parametrize(
    "feature, message",
    [
        (
            {
                "properties": {"action": "complete"},
                "geometry": {"type": "Polygon", "coordinates": [[[100, 200], [101, 199]]]},
            },
            "3 corners",
        ),
        (
            {
                "properties": {"action": "complete"},
                "geometry": {"type": "LineString", "coordinates": [[100, 200], [101, 199]]},
            },
            "Polygon",
        ),
        (
            {
                "properties": {"action": "complete"},
                "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [5000, 0], [5000, 5000]]]},
            },
            "outside the imagery",
        ),
        ({"properties": {"action": "delete", "edge": 5}}, "not an edge"),
        (
            {
                "properties": {"action": "move", "vertex": 0},
                "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1]]},
            },
            "Point",
        ),
        ({"properties": {"action": "paint"}}, "unknown action"),
        (
            {"properties": {"action": "add"}, "geometry": {"type": "LineString", "coordinates": [[100, 200]]}},
            "at least 2",
        ),
    ],
)
def test_bad_edits_are_refused(feature, message):
    with pytest.raises(EditError, match=message):
        apply_edits(square_graph(), [feature])


def test_review_works_from_another_folder_than_predict_ran_in(tmp_path):
    """predict records its inputs as absolute paths, so the review page finds the imagery from anywhere."""
    city = tmp_path / "work" / "city"
    assert (
        run_cli("synth", str(city), "--tile-size", "600", "--seed", "2", "--split", "valid", "--quiet").returncode == 0
    )
    tile = next((city / "tiles").glob("*.tif")).relative_to(tmp_path / "work")
    done = run_cli("predict", str(tile), "--out", "pred", "--device", "cpu", "--quiet", cwd=tmp_path / "work")
    assert done.returncode == 0, done.stderr
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    done = run_cli("review", str(tmp_path / "work" / "pred"), cwd=elsewhere)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "work" / "pred" / "review" / "index.html").exists()


def test_a_district_page_names_the_city_s_edges(reviewed, browser, tmp_path):
    """A page of the city's west half: its edges only, read from the GeoPackage; the edge deleted
    there is the city's edge of that number, and apply-review removes it from the whole city."""
    from selenium.webdriver.common.by import By
    from shapely.geometry import box

    from csboundary.graph import BoundaryGraph

    pred = tmp_path / "pred"
    shutil.copytree(reviewed, pred, ignore=shutil.ignore_patterns("review"))
    city = BoundaryGraph.read_json(pred / "graph.json")
    x0, y0, x1, y1 = _world_bounds(city)
    west = (x0, y0, (x0 + x1) / 2, y1)
    done = run_cli(
        "review", str(pred), "--bounds", ",".join(map(str, west)), "--out", str(tmp_path / "west"), "--quiet"
    )
    assert done.returncode == 0, done.stderr
    inside = [k for k, line in enumerate(city.to_linestrings(world=True)) if line.intersects(box(*west))]
    assert 0 < len(inside) < city.n_edges

    browser.get((tmp_path / "west" / "index.html").as_uri())
    _wait(browser, "return window.review && window.review.loadedTiles() > 0")
    assert browser.execute_script("return window.review.edgeCount()") == len(inside)
    rows = [li for li in browser.find_elements(By.CSS_SELECTOR, "#edge-list li") if li.is_displayed()]
    rows[0].click()
    browser.find_element(By.ID, "delete").click()
    browser.find_element(By.ID, "export").click()
    edits = json.loads(browser.find_element(By.ID, "export-text").get_attribute("value"))
    deleted = sorted(f["properties"]["edge"] for f in edits["features"])
    local = sorted(int(k) for k in rows[0].get_attribute("data-edges").split(","))
    ids = browser.execute_script("return REVIEW_DATA.edge_ids")
    assert deleted == sorted(ids[k] for k in local) and set(deleted) <= set(
        inside
    )  # the city's numbers of the boundary's edges

    (tmp_path / "edits.geojson").write_text(json.dumps(edits))
    done = run_cli("apply-review", str(pred), str(tmp_path / "edits.geojson"))
    assert done.returncode == 0, done.stderr
    after = BoundaryGraph.read_json(pred / "graph.json")
    assert after.n_edges == city.n_edges - len(deleted)
    assert sorted(json.loads((pred / "review.json").read_text())["reviews"][-1]["deleted_edges"]) == deleted


def _world_bounds(graph: BoundaryGraph) -> tuple[float, float, float, float]:
    world = graph.world_vertices()
    return float(world[:, 0].min()), float(world[:, 1].min()), float(world[:, 0].max()), float(world[:, 1].max())
