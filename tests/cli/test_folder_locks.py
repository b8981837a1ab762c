"""Issue 65: every command that writes into a folder another run could write into takes the
folder lock ``predict`` takes (data/folder_lock.py): a second run is one line, and the folder
it would have made is not left behind."""

from __future__ import annotations

import numpy as np
import pytest
from affine import Affine
from test_hostile_inputs import one_error

from csboundary.data.folder_lock import folder_lock
from csboundary.data.geotiff import write_geotiff
from helpers import run_cli


def _masks(folder):
    """One image and its road-edge mask, in the form import-masks reads."""
    folder.mkdir()
    write_geotiff(
        folder / "a_image.tif",
        np.full((3, 64, 64), 90, np.uint8),
        Affine(0.152, 0, 500000, 0, -0.152, 4400000),
        "EPSG:32618",
    )
    mask = np.zeros((1, 64, 64), np.uint8)
    mask[0, 30:33, 5:60] = 255
    write_geotiff(folder / "a_mask.tif", mask, Affine(0.152, 0, 500000, 0, -0.152, 4400000), "EPSG:32618")
    return folder


@pytest.mark.parametrize("command", ["synth", "import-masks", "review", "evaluate-finetune"])
def test_a_second_run_into_a_folder_in_use_is_one_line(command, tmp_path, demo_run):
    out = tmp_path / "out"
    args = {
        "synth": ["synth", str(out), "--tiles", "1x1", "--tile-size", "128", "--quiet"],
        "import-masks": [
            "import-masks",
            str(_masks(tmp_path / "masks")) if command == "import-masks" else "",
            "--out",
            str(out),
            "--image-pattern",
            "{id}_image.tif",
            "--mask-pattern",
            "{id}_mask.tif",
        ],
        "review": ["review", str(demo_run / "prediction"), "--out", str(out), "--quiet"],
        "evaluate-finetune": ["evaluate-finetune", str(tmp_path / "set"), "--out", str(out), "--quiet"],
    }[command]
    (tmp_path / "set").mkdir()
    out.mkdir()
    with folder_lock(out):  # another run writing there
        one_error(run_cli(*args), str(out), "in use by another csboundary run")
    assert [p.name for p in out.iterdir()] == []  # nothing written by the refused run
