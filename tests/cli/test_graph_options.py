"""The graph options: declared once, taken by every command that predicts and by bundle-weights,
and shown as a user reads them (no ``<bool>`` beside a flag, arguments by name)."""

from __future__ import annotations

import dataclasses

import typer

from csboundary.cli.main import app, first_sentence, help_as_read
from csboundary.cli.options import GRAPH_OPTIONS, GRAPH_PANEL
from csboundary.graph.settings import GraphOverrides, GraphSettings
from csboundary.models.checkpoint import load_checkpoint
from helpers import run_cli, shipped_parts

TAKERS = ("predict", "predict-patch", "evaluate-model", "evaluate-set", "bundle-weights")


def test_every_predicting_command_takes_the_one_declaration_of_the_graph_options():
    group = help_as_read(typer.main.get_command(app))
    assert set(GRAPH_OPTIONS) == {f.name for f in dataclasses.fields(GraphOverrides)}
    flags = {p.opts[0] for p in group.commands["predict"].params if p.name in GRAPH_OPTIONS}
    assert len(flags) == len(GRAPH_OPTIONS) == 14
    for command, params in ((name, group.commands[name].params) for name in group.commands):
        declared = {p.opts[0] for p in params if p.param_type_name == "option"}
        if command in TAKERS:
            assert flags <= declared, command
            assert {p.rich_help_panel for p in params if p.opts[0] in flags} == {GRAPH_PANEL}, command
        else:
            assert not {"--edge-threshold", "--min-edge-support"} & declared, command


def test_help_reads_as_a_user_expects():
    done = run_cli("predict", "--help", "--weights", "x")  # --help wins over anything else
    text = done.stdout
    assert done.returncode == 0 and "predict [OPTIONS] IMAGERY..." in text
    assert "<bool>" not in text and "<list" not in text and "{" not in text.split("\n")[1]
    assert "--write-maps " in text and "Graph settings" in text and "--min-confidence" in text
    top = run_cli("--help").stdout
    flat = " ".join(top.replace("│", " ").split())
    assert "<bool>" not in top and "The paper's comparison (Tables I-IV, Fig. 7): every method" in flat
    assert first_sentence("Runs at 0.03 m, e.g. NYC. Then more.") == "Runs at 0.03 m, e.g. NYC."


def test_bundle_weights_stores_the_graph_options_as_the_bundle_s_settings(tmp_path):
    fpn, afanet = shipped_parts(tmp_path)
    done = run_cli(
        "bundle-weights",
        "--fpn",
        str(fpn),
        "--afanet",
        str(afanet),
        "--out",
        str(tmp_path / "b.pt"),
        "--min-edge-support",
        "0.2",
        "--max-degree",
        "0",
        "--attach-ends",
        "40",
        "--surface-check",
        "0.5",
    )
    assert done.returncode == 0, done.stderr
    table = load_checkpoint(tmp_path / "b.pt", ("bundle",))["inference"]
    settings = GraphSettings.from_bundle(table, "b.pt")
    assert (settings.support.min_support, settings.max_degree, settings.attach_px, settings.surface.strong) == (
        0.2,
        None,
        40.0,
        0.5,
    )
    assert (settings.edge_threshold, settings.min_fragment_px, settings.fill.active) == (
        0.5,
        0.0,
        False,
    )  # what was not given: off
    refused = run_cli(
        "bundle-weights",
        "--fpn",
        str(fpn),
        "--afanet",
        str(afanet),
        "--out",
        str(tmp_path / "c.pt"),
        "--min-confidence",
        "0.5",
    )
    assert refused.returncode == 2 and "--min-confidence" in refused.stderr and not (tmp_path / "c.pt").exists()
