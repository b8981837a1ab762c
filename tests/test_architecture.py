"""The package's layers only import downward, so data can be followed one way:

    errors < config < data < graph < labels, metrics, viz < models < pipeline, qgis_plugin < api, cli

and so do the sub-packages inside the two largest layers (:data:`SUB_LAYERS`):

    models:   the networks and their files (models/*.py) < training < baselines
    pipeline: prediction < outputs < jobs < training < evaluation

Every ``import`` of every module is read (top-level and inside functions alike); an import of a
higher layer or sub-package, or between two peers, fails with the module and line named.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import csboundary

LAYERS = {
    "errors": 0,
    "config": 1,
    "data": 2,
    "graph": 3,
    "labels": 4,
    "metrics": 4,
    "viz": 4,
    "models": 5,
    "pipeline": 6,
    "qgis_plugin": 6,
    "api": 7,
    "cli": 7,
    "__main__": 8,
}
# inside a layer: the order of its sub-packages; "." is the layer's own modules (models/fpn.py)
SUB_LAYERS = {
    "models": {".": 0, "training": 1, "baselines": 2},
    "pipeline": {"prediction": 0, "outputs": 1, "jobs": 2, "training": 3, "evaluation": 4},
}
PACKAGE = Path(csboundary.__file__).parent


def layer_of(module: str) -> str | None:
    """The top-level part of a ``csboundary.X...`` module name (None for the package itself)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "csboundary" else None


def imports_of(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every csboundary import in a source file."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # ``from csboundary import X``: a layer when X is one (``__version__`` is the package's own)
            names = (
                [node.module]
                if node.module != "csboundary"
                else [f"csboundary.{a.name}" for a in node.names if a.name in LAYERS]
            )
            found += [(node.lineno, name) for name in names if name.startswith("csboundary")]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.startswith("csboundary")]
    return found


def upward_imports(root: Path = PACKAGE) -> list[str]:
    problems = []
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root)
        source = relative.parts[0].removesuffix(".py") if relative.parts else ""
        if source not in LAYERS:
            if source != "__init__":
                problems.append(f"{relative}: not in any layer (add it to LAYERS)")
            continue
        for line, module in imports_of(path):
            target = layer_of(module)
            if target is None or target == source:
                continue
            if target not in LAYERS:
                problems.append(f"{relative}:{line} imports {module}: not in any layer")
            elif LAYERS[target] >= LAYERS[source]:
                problems.append(f"{relative}:{line} imports {module}: {target} is not below {source}")
    return problems


def test_every_import_points_down():
    assert upward_imports() == []


def sub_layer_of(parts: tuple[str, ...], root: Path = PACKAGE) -> str:
    """The sub-package of a module inside a layer (``("models", "training", "fpn")`` ->
    ``training``), "." for the layer's own modules."""
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and (root / parts[0] / parts[1]).is_dir()) else "."


def sideways_imports(root: Path = PACKAGE) -> list[str]:
    """Imports inside a layer of :data:`SUB_LAYERS` that point to a higher or peer sub-package."""
    problems = []
    for layer, order in SUB_LAYERS.items():
        for path in sorted((root / layer).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__" and len(parts) == 2:
                continue
            source = sub_layer_of(parts, root)
            if source not in order:
                problems.append(f"{path.relative_to(root)}: not in any {layer} sub-layer (add it to SUB_LAYERS)")
                continue
            for line, module in imports_of(path):
                target_parts = tuple(module.split(".")[1:])
                if target_parts[:1] != (layer,) or len(target_parts) < 2:
                    continue
                target = sub_layer_of(target_parts, root)
                if target == source:
                    continue
                if target not in order:
                    problems.append(f"{path.relative_to(root)}:{line} imports {module}: not in any {layer} sub-layer")
                elif order[target] >= order[source]:
                    problems.append(
                        f"{path.relative_to(root)}:{line} imports {module}: {layer}/{target} is not below {layer}/{source}"
                    )
    return problems


def test_every_import_inside_models_and_pipeline_points_down():
    assert sideways_imports() == []


def test_an_upward_import_between_sub_packages_is_caught(tmp_path):
    for folder in ("models/training", "models/baselines", "pipeline/prediction", "pipeline/outputs"):
        (tmp_path / folder).mkdir(parents=True)
    (tmp_path / "models" / "fpn.py").write_text("from csboundary.models.training.loop import optimize\n")
    (tmp_path / "models" / "training" / "loop.py").write_text("from csboundary.models.fpn import LiteFPN\n")
    (tmp_path / "models" / "training" / "runs.py").write_text("from csboundary.models.baselines import METHODS\n")
    (tmp_path / "pipeline" / "prediction" / "run.py").write_text(
        "def f():\n    from csboundary.pipeline.outputs.files import write\n"
    )
    (tmp_path / "pipeline" / "outputs" / "files.py").write_text("from csboundary.pipeline.prediction.run import f\n")
    assert sideways_imports(tmp_path) == [
        "models/fpn.py:1 imports csboundary.models.training.loop: models/training is not below models/.",
        "models/training/runs.py:1 imports csboundary.models.baselines: models/baselines is not below models/training",
        "pipeline/prediction/run.py:2 imports csboundary.pipeline.outputs.files: "
        "pipeline/outputs is not below pipeline/prediction",
    ]


def test_an_upward_import_is_caught(tmp_path):
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "fine.py").write_text("from csboundary.errors import InputError\n")
    (tmp_path / "data" / "bad.py").write_text(
        "def f():\n    from csboundary.pipeline.jobs.prediction_run import run_prediction\n"
    )
    (tmp_path / "viz").mkdir()
    (tmp_path / "viz" / "peer.py").write_text("import csboundary.metrics.apls\n")
    assert upward_imports(tmp_path) == [
        "data/bad.py:2 imports csboundary.pipeline.jobs.prediction_run: pipeline is not below data",
        "viz/peer.py:1 imports csboundary.metrics.apls: metrics is not below viz",
    ]


@pytest.mark.parametrize("module, layer", [("csboundary.models.fpn", "models"), ("csboundary", None), ("numpy", None)])
def test_layer_of(module, layer):
    assert layer_of(module) == layer


def module_name(path: Path, root: Path = PACKAGE) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(("csboundary", *(parts[:-1] if parts[-1] == "__init__" else parts)))


def import_cycles(root: Path = PACKAGE) -> list[list[str]]:
    """Groups of modules that import each other in a circle, directly or through others (every
    import counts, also one inside a function): sorted names of each strongly connected group.
    An import of the root package itself (``import csboundary`` for its ``__all__``) is no edge:
    Python imports a package before any of its modules, so every module depends on it anyway."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    modules = {module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    names = sorted(modules)
    index = {n: i for i, n in enumerate(names)}
    root_package = module_name(root / "__init__.py", root)
    pairs = [
        (index[n], index[m])
        for n, p in modules.items()
        for _, m in imports_of(p)
        if m in index and m != n and m != root_package
    ]
    rows, cols = zip(*pairs) if pairs else ((), ())
    graph = csr_matrix(([1] * len(pairs), (rows, cols)), shape=(len(names), len(names)))
    _, labels = connected_components(graph, directed=True, connection="strong")
    groups = [[names[i] for i in range(len(names)) if labels[i] == label] for label in set(labels)]
    return sorted(g for g in groups if len(g) > 1)


def test_no_modules_import_each_other_in_a_circle():
    assert import_cycles() == []


def test_a_circle_is_caught(tmp_path):
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "a.py").write_text("from csboundary.models.b import X\n")
    (tmp_path / "models" / "b.py").write_text("def f():\n    from csboundary.models.c import Y\n")
    (tmp_path / "models" / "c.py").write_text("import csboundary.models.a\n")
    (tmp_path / "models" / "d.py").write_text("import csboundary.models.a\n")
    assert import_cycles(tmp_path) == [["csboundary.models.a", "csboundary.models.b", "csboundary.models.c"]]


MAX_MODULE_LINES = 450  # a module longer than this holds more than one job: split it by what it does


def test_no_module_is_too_long_to_hold_one_job():
    long = {
        str(p.relative_to(PACKAGE)): n
        for p in PACKAGE.rglob("*.py")
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    }
    assert long == {}
