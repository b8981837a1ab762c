"""Writing outputs: a full disk is said as such, naming the folder, and leaves no temporary."""

from __future__ import annotations

import errno

import pytest

from csboundary.data.atomic import atomic_path, disk_full_error


def test_a_short_write_is_a_full_disk_naming_the_folder(tmp_path):
    numpy_words = OSError("3630000 requested and 1568704 written")  # what ndarray.tofile says, naming nothing
    full = disk_full_error(numpy_words, tmp_path / "maps" / "0_0.npy")
    assert full.errno == errno.ENOSPC and full.filename == str(tmp_path / "maps") and "no space left" in str(full)
    assert disk_full_error(OSError(errno.ENOSPC, "No space left on device"), tmp_path / "a.tif").errno == errno.ENOSPC
    assert disk_full_error(OSError(errno.EACCES, "Permission denied"), tmp_path / "a.tif") is None  # this disk has room


def test_atomic_path_turns_a_short_write_into_a_full_disk_and_cleans_up(tmp_path):
    final = tmp_path / "out" / "graph.json"
    with pytest.raises(OSError) as raised:
        with atomic_path(final) as tmp:
            tmp.write_text("half")
            raise OSError("100 requested and 50 written")
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(final.parent)
    assert list(final.parent.iterdir()) == []  # neither the final name nor the temporary


def test_the_command_line_says_it_in_one_line(tmp_path, monkeypatch):
    """main's handler prints the folder and the reason."""
    import subprocess
    import sys

    probe = (
        "import sys, numpy as np\nfrom csboundary.cli import main as m\n"
        "def boom(*a, **k):\n    raise OSError(28, 'no space left on device', '/data/run')\n"
        "m.command_line = lambda: boom\nsys.argv = ['csboundary']\nm.main()\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert done.returncode == 1
    assert done.stderr.strip() == "error: /data/run: no space left on device"
