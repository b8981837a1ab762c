"""The three steps of apply_edits alone: parse_edit reads a feature without judging it,
check_edits refuses what does not fit the graph (the first bad edit of the log, messages worked
out by hand), apply_checked makes the graph; composed they are apply_edits."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.graph.review_edits import (
    CheckedEdits,
    Edit,
    EditError,
    apply_checked,
    apply_edits,
    check_edits,
    parse_edit,
)
from helpers import square_graph

EXTENT = (0.0, 0.0, 20.0, 20.0)


def _feature(props: dict, kind: str | None = None, coordinates=None) -> dict:
    return {"type": "Feature", "properties": props, "geometry": kind and {"type": kind, "coordinates": coordinates}}


def test_parse_reads_a_feature_without_judging_its_content():
    edit = parse_edit(3, _feature({"action": "delete", "edge": True}, "Point", [1, "x"]))
    assert edit == Edit(3, "delete", True, "Point", [1, "x"]) and edit.what == "edit 3 (delete)"
    assert parse_edit(0, _feature({"action": "move", "vertex": 2, "edge": 7})).index == 2  # a move names a vertex
    assert parse_edit(0, {"properties": None, "geometry": None}) == Edit(0, None, None, None, None)


@pytest.mark.parametrize(
    "feature, message",
    [
        ("delete", "edit 4: not a GeoJSON feature"),
        ({"properties": ["action"]}, "edit 4: properties and geometry must be objects"),
        ({"properties": {}, "geometry": "Point"}, "edit 4: properties and geometry must be objects"),
    ],
)
def test_parse_refuses_what_is_not_a_feature(feature, message):
    with pytest.raises(EditError) as refused:
        parse_edit(4, feature)
    assert str(refused.value) == message


def test_check_turns_edits_into_indices_and_graph_pixels():
    edits = [
        Edit(0, "delete", 0, "LineString", [[105.0, 200.0], [100.0, 200.0]]),  # edge 0 drawn the other way round
        Edit(1, "accept", 1, "LineString", [[105.0, 200.0], [105.0, 195.0]]),
        Edit(2, "move", 2, "Point", [106.0, 194.0]),  # pixel (12, 12)
        Edit(3, "add", None, "LineString", [[100.0, 200.0], [101.0, 199.0], [102.0, 200.0]]),
        Edit(4, "complete", None, "Polygon", [[[100.0, 200.0], [104.0, 200.0], [104.0, 196.0]]]),
    ]
    checked = check_edits(square_graph(), edits, EXTENT)
    assert checked.deleted == {0} and checked.accepted == {1}
    [(vertex, place)] = checked.moves
    assert vertex == 2 and place.tolist() == [12.0, 12.0]
    [line] = checked.added
    assert line.tolist() == [[0.0, 0.0], [2.0, 2.0], [4.0, 0.0]]
    assert checked.areas == ([[100.0, 200.0], [104.0, 200.0], [104.0, 196.0], [100.0, 200.0]],)  # closed


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            Edit(0, "delete", 0, "LineString", [[100.0, 200.0], [106.0, 200.0]]),  # ends at pixel (12, 0), not (10, 0)
            "edit 0 (delete): its geometry does not match edge 0 (ends 2.0 px apart): "
            "the edits were made on another graph",
        ),
        (  # the index is judged before the geometry
            Edit(1, "accept", 2, None, None),
            "edit 1 (accept): edge 2 is not an edge of the graph (0..1)",
        ),
        (
            Edit(2, "move", 1, "Point", [200.0, 200.0]),  # pixel (200, 0): beyond 20 + 100 px of margin
            "edit 2 (move): coordinates lie outside the imagery: are they in the prediction's CRS (EPSG:32618)?",
        ),
        (Edit(3, "move", 3, "Point", [100.0, 200.0]), "edit 3 (move): vertex 3 is not a vertex of the graph"),
        (
            Edit(4, "add", None, "LineString", [[100.0, None]]),
            "edit 4 (add): coordinates are not two numbers per position",
        ),
        (
            Edit(
                5, "complete", None, "Polygon", [[[112.0, 200.0], [114.0, 200.0], [114.0, 196.0]]]
            ),  # pixels 24..28: the margin
            "edit 5 (complete): the polygon covers no pixel of the imagery, only the margin around it",
        ),
        (
            Edit(6, "split", 0, None, None),
            "edit 6 (split): unknown action (one of delete, accept, move, add, complete)",
        ),
    ],
)
def test_check_refuses_with_the_message_worked_out_by_hand(edit, message):
    with pytest.raises(EditError) as refused:
        check_edits(square_graph(), [edit], EXTENT)
    assert str(refused.value) == message


def test_the_first_bad_feature_of_the_log_is_the_one_refused():
    features = [_feature({"action": "delete", "edge": 9}), "not a feature"]
    with pytest.raises(EditError, match="edit 0 \\(delete\\): edge 9"):
        apply_edits(square_graph(), features)


def test_apply_keeps_edges_in_order_then_adds_and_records():
    graph, record = apply_checked(
        square_graph(),
        CheckedEdits(
            deleted=frozenset({0}),
            accepted=frozenset({0, 1}),
            moves=((2, np.array([12.0, 12.0])), (2, np.array([11.0, 11.0]))),  # the last move wins
            added=(np.array([[0.5, 0.0], [3.0, 4.0], [30.0, 30.0]]),),
        ),
    )
    assert graph.edges.tolist() == [[1, 2], [0, 3]] and graph.edge_kinds == ["corner", "manual"]
    assert graph.vertices.tolist() == [[0.0, 0.0], [10.0, 0.0], [11.0, 11.0], [30.0, 30.0]]
    assert graph.vertex_kinds == ["vertex", "vertex", "vertex", "manual"]
    assert graph.edge_polylines[0].tolist() == [[10.0, 0.0], [12.0, 5.0], [11.0, 11.0]]  # follows the move
    assert graph.edge_polylines[1].tolist() == [[0.0, 0.0], [3.0, 4.0], [30.0, 30.0]]  # snapped onto vertex 0
    assert graph.edge_scores.tolist() == [0.9, 1.0] and graph.edge_patches.tolist() == [[-1, -1], [-1, -1]]
    assert record.to_dict() == {
        "deleted_edges": [0],
        "accepted_edges": [0],  # edge 0 was deleted; edge 1 is now edge 0
        "moved_vertices": [2],
        "added_edges": [1],
        "edge_index_map": {"1": 0},
        "complete_areas": [],
    }
    assert square_graph().edge_polylines[1].tolist() == [[10.0, 0.0], [12.0, 5.0], [10.0, 10.0]]


def test_an_added_edge_whose_ends_join_one_vertex_is_refused():
    with pytest.raises(EditError, match="^an added edge starts and ends on the same vertex$"):
        apply_checked(square_graph(), CheckedEdits(added=(np.array([[0.2, 0.0], [0.0, 0.5]]),)))


def test_the_steps_composed_are_apply_edits():
    features = [
        _feature({"action": "delete", "edge": 0}, "LineString", [[100.0, 200.0], [105.0, 200.0]]),
        _feature({"action": "move", "vertex": 1}, "Point", [105.5, 200.0]),
        _feature({"action": "add"}, "LineString", [[105.5, 200.0], [101.0, 190.0]]),
    ]
    graph = square_graph()
    edits = [parse_edit(n, f) for n, f in enumerate(features)]
    stepwise, stepwise_record = apply_checked(graph, check_edits(graph, edits, EXTENT))
    whole, whole_record = apply_edits(graph, features, extent=EXTENT)
    assert stepwise_record == whole_record and stepwise_record.added == [1]
    assert stepwise.vertices.tobytes() == whole.vertices.tobytes() and stepwise.edges.tolist() == [[1, 2], [1, 3]]
