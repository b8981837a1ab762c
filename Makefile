# Two entry points: `make demo` (the main job) and `make test` (`make lint`, then the tests); `make wheel-check` installs the built
# wheel alone in a fresh environment and runs the demo outside the checkout (CI runs all three).
# Both create and reuse a virtual environment in .venv on first use.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint wheel-check qgis-plugin qgis-test clean

$(STAMP): pyproject.toml constraints.txt
	@echo "installing csboundary and its dependencies (PyTorch CPU, ONNX Runtime, GDAL's rasterio, ...) into $(VENV): once, about 1.5 min"
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet -c constraints.txt -e '.[test]'
	touch $(STAMP)
	@echo "installed into $(VENV)"

demo: $(STAMP)
	$(BIN)/csboundary demo --out out/demo

test: $(STAMP) lint
	$(BIN)/pytest

# every tracked Python file (pyproject excludes only the generated folders): the layout is the formatter's, then the lint rules
lint: $(STAMP)
	$(BIN)/ruff format --check
	$(BIN)/ruff check

# the QGIS plugin's installable zip (Plugins > Manage and Install Plugins > Install from ZIP)
qgis-plugin: $(STAMP)
	$(BIN)/csboundary qgis-plugin --out build/csboundary_qgis.zip

# the plugin inside QGIS: installs Debian's QGIS 3.22 (as root) if it is missing, runs the tests marked qgis
# and renders docs/qgis-layers.jpg from the Detect run
qgis-test: $(STAMP) qgis-plugin
	command -v qgis_process >/dev/null || (apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q qgis python3-qgis)
	CSBOUNDARY_QGIS_PICTURE=$(CURDIR)/docs/qgis-layers.jpg $(BIN)/pytest -m qgis tests/qgis_plugin -n 0 -s

wheel-check: $(STAMP)
	rm -rf build/wheel-check && mkdir -p build/wheel-check
	$(BIN)/pip wheel --quiet --no-deps . -w build/wheel-check/dist
	$(PYTHON) -m venv build/wheel-check/venv
	build/wheel-check/venv/bin/pip install --quiet -c constraints.txt build/wheel-check/dist/csboundary-*.whl
	cd /tmp && $(CURDIR)/build/wheel-check/venv/bin/csboundary demo --out $(CURDIR)/build/wheel-check/demo --device cpu
	cd /tmp && $(CURDIR)/build/wheel-check/venv/bin/csboundary qgis-plugin --out $(CURDIR)/build/wheel-check/csboundary_qgis.zip
	$(PYTHON) -c "import sys, zipfile; names = zipfile.ZipFile(sys.argv[1]).namelist(); \
	    assert {'csboundary_qgis/metadata.txt', 'csboundary_qgis/icon.svg', 'csboundary_qgis/algorithms.py'} <= set(names), names" \
	    build/wheel-check/csboundary_qgis.zip

clean:
	rm -rf $(VENV) out build
