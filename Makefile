# make demo: set up .venv and run the main job on the bundled data (writes out/demo/)
# make test: set up .venv and run the tests
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench setup clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e ".[test]"
	@# CHOLMOD is faster; it builds only where SuiteSparse headers exist (scipy otherwise)
	-$(BIN)/pip install -q "scikit-sparse==0.4.16" 2>/dev/null || echo "note: scikit-sparse not installed; using scipy's sparse solver"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/mimica demo --out out/demo

test: $(STAMP)
	$(BIN)/python -m pytest tests

bench: $(STAMP)
	$(BIN)/pip install -q -e ".[bench]"
	$(BIN)/python bench/transfer.py

clean:
	rm -rf out $(VENV)
