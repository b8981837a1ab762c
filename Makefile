# Two entry points: `make demo` (the main job) and `make test`.
# Both create and reuse a virtual environment in .venv on first use.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/csboundary demo --out out/demo

test: $(STAMP)
	$(BIN)/pytest

clean:
	rm -rf $(VENV) out
