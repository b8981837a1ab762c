"""Build the QGIS plugin's installable zip (Plugins > Manage and Install Plugins > Install from
ZIP): ``python qgis_plugin/build_zip.py [OUT.zip]`` (``make qgis-plugin``)."""

import re
import sys
import zipfile
from pathlib import Path

PLUGIN = Path(__file__).resolve().parent / "csboundary_qgis"


def version() -> str:
    return re.search(r"^version=(.+)$", (PLUGIN / "metadata.txt").read_text(), re.M).group(1).strip()


def build(out: Path) -> Path:
    """The zip QGIS installs: one top folder, the plugin's name, with no caches."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.partial")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for path in sorted(PLUGIN.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc":
                archive.write(path, Path(PLUGIN.name) / path.relative_to(PLUGIN))
    tmp.replace(out)
    return out


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("build") / f"csboundary_qgis-{version()}.zip"
    print(build(target))
