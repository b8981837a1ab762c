"""The public API's names are listed once (``csboundary.__all__``): the package and ``csboundary.api``
export the same names, each one is importable from the package, every public function of the API
module is listed, and docs/api.md names every one."""

from __future__ import annotations

import inspect
from pathlib import Path

import csboundary
import csboundary.api as api

DOC = Path(__file__).parents[1] / "docs" / "api.md"


def test_the_package_and_the_api_module_share_one_list():
    assert api.__all__ is csboundary.__all__
    assert len(set(csboundary.__all__)) == len(csboundary.__all__)


def test_every_listed_name_is_the_api_modules_own_object():
    for name in csboundary.__all__:
        assert getattr(csboundary, name) is getattr(api, name), name


def test_every_public_function_of_the_api_module_is_listed():
    functions = {
        name
        for name, value in vars(api).items()
        if inspect.isfunction(value) and value.__module__ == api.__name__ and not name.startswith("_")
    }
    listed_functions = {name for name in csboundary.__all__ if inspect.isfunction(getattr(api, name))}
    assert functions == listed_functions


def test_an_unlisted_name_is_not_found_on_the_package():
    import pytest

    with pytest.raises(AttributeError, match="no attribute 'InputError'"):
        csboundary.InputError  # noqa: B018 (the access is the test)


def test_the_api_doc_names_every_listed_name():
    import re

    text = DOC.read_text()
    assert [name for name in csboundary.__all__ if not re.search(rf"\b{name}\b", text)] == []
