"""The examples of docs/api.md run as written, on a small synthetic city, and do what the commands
they stand for do; the training calls reach ``finetune`` and ``adapt`` with what they were given."""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig

DOC = Path(__file__).parents[1] / "docs" / "api.md"


def test_the_api_doc_examples_run(tmp_path, monkeypatch):
    import csboundary.pipeline.training.adapt as adapt_module
    import csboundary.pipeline.training.finetune as finetune_module

    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) == 4
    synthesize_city(tmp_path / "my_set" / "my_city", 3, "test", (1, 1), SynthConfig(tile_size=1000), progress=False)
    monkeypatch.chdir(tmp_path)
    calls = []

    def stand_in(name):
        def run(inputs, out, **options):
            calls.append((name, [str(p) for p in inputs], str(out), options))
            Path(out).write_bytes(_shipped().read_bytes())
            return {"work": str(tmp_path / "work")}

        return run

    monkeypatch.setattr(finetune_module, "finetune", stand_in("finetune"))
    monkeypatch.setattr(adapt_module, "adapt", stand_in("adapt"))
    namespace: dict = {}
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        for block in blocks:
            exec(compile(block, str(DOC), "exec"), namespace)
    text = printed.getvalue()
    graph = json.loads((tmp_path / "prediction" / "graph.json").read_text())
    assert f"{len(graph['edges'])} edges," in text and len(graph["edges"]) >= 8  # a street network, not a stub
    assert f"{len(graph['vertices'])} vertices in" in text
    assert "0.5 300.0" in text  # the overrides reached the settings
    assert Path("patch/graph.json").exists()
    kept = json.loads(Path("patch/graph.json").read_text())["edges"]
    assert kept and all(e["score"] >= 0.5 for e in kept)  # the edge confidence is the score graph.json carries
    assert "['city', 'patch']" in text and "['my_city']" in text
    assert [c[:3] for c in calls] == [
        ("finetune", ["my_set/my_city"], "tuned.pt"),
        ("adapt", ["my_set/my_city/tiles"], "adapted.pt"),
    ]
    assert (
        calls[0][3]["budget"].fpn_steps == 1000
        and calls[0][3]["device"] == "cpu"
        and calls[1][3]["weights"] == "tuned.pt"
    )
    assert namespace["tuned"].settings == namespace["model"].settings  # the stand-in wrote the shipped bundle


def _shipped() -> Path:
    from csboundary.models.checkpoint import shipped_weights

    return shipped_weights()
