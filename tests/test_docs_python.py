"""The Python example of docs/architecture.md runs as written (on a small synthetic city) and
does what the commands it stands for do."""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig

DOC = Path(__file__).parents[1] / "docs" / "architecture.md"


def test_the_architecture_doc_python_example_runs(tmp_path, monkeypatch):
    block = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S).group(1)
    synthesize_city(tmp_path / "my_city", 3, "test", (1, 1), SynthConfig(tile_size=1100), progress=False)
    monkeypatch.chdir(tmp_path)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(block, str(DOC), "exec"), {})
    graph = json.loads((tmp_path / "prediction" / "graph.json").read_text())
    text = printed.getvalue()
    assert f"{len(graph['edges'])} edges in prediction/graph.json" in text
    assert re.search(r"^city\s+\d", text, re.M) and re.search(r"^patch\s+\d", text, re.M)  # both scales scored
