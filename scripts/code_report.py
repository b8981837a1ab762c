"""Figures of the code's shape that a reader feels: functions with many parameters (outside cli/),
the longest functions, modules over 400 lines and private names imported from another module.

Usage: python scripts/code_report.py [PACKAGE_DIR]   (default: csboundary)
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path


def functions(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def parameter_count(node: ast.FunctionDef) -> int:
    a = node.args
    names = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    return len([n for n in names if n.arg not in ("self", "cls")])


def private_imports(path: Path, tree: ast.AST) -> list[tuple[int, str, list[str]]]:
    """(line, module, names) of every ``from csboundary... import _name`` of another module."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("csboundary"):
            names = [a.name for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
            if names:
                found.append((node.lineno, node.module, names))
    return found


def main(root: Path) -> None:
    many, lengths, long_modules, private = [], [], [], []
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root.parent)
        text = path.read_text()
        tree = ast.parse(text)
        if (lines := len(text.splitlines())) > 400:
            long_modules.append((lines, str(relative)))
        for node in functions(tree):
            where = f"{relative}:{node.lineno} {node.name}"
            if parameter_count(node) > 8 and "cli" not in relative.parts:
                many.append((parameter_count(node), where))
            lengths.append((node.end_lineno - node.lineno + 1, where))
        private += [(str(relative), line, module, names) for line, module, names in private_imports(path, tree)]
    print(f"functions with more than 8 parameters outside cli/: {len(many)}")
    for n, where in sorted(many, reverse=True):
        print(f"  {n:3d}  {where}")
    print("longest functions:")
    for n, where in sorted(lengths, reverse=True)[:5]:
        print(f"  {n:4d} lines  {where}")
    print(f"modules over 400 lines: {len(long_modules)}")
    for n, where in sorted(long_modules, reverse=True):
        print(f"  {n:4d}  {where}")
    names = {(module, name) for _, _, module, ns in private for name in ns}
    print(f"private names imported across modules: {len(names)} names in {len(private)} import lines")
    for where, line, module, ns in private:
        print(f"  {where}:{line} from {module} import {', '.join(ns)}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "csboundary"))
