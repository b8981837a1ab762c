"""The QGIS plugin, shipped inside the package so that ``pip install csboundary`` is enough:
``csboundary qgis-plugin --out FILE.zip`` writes the zip that QGIS installs (Plugins > Manage and
Install Plugins > Install from ZIP). The plugin itself (``csboundary_qgis/``) runs inside QGIS's
Python and imports nothing from this package: it runs the ``csboundary`` command (docs/qgis.md).
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

from csboundary.data.atomic import atomic_path

PLUGIN = Path(__file__).resolve().parent / "csboundary_qgis"


def plugin_version() -> str:
    """The plugin's version, from its metadata.txt (QGIS reads it from there)."""
    return re.search(r"^version=(.+)$", (PLUGIN / "metadata.txt").read_text(), re.M).group(1).strip()


def write_plugin_zip(out: str | Path) -> Path:
    """The zip QGIS installs: one top folder named as the plugin, without caches; written under a
    temporary name and renamed when complete."""
    out = Path(out)
    with atomic_path(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for path in sorted(PLUGIN.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc":
                archive.write(path, Path(PLUGIN.name) / path.relative_to(PLUGIN))
    return out
