# make demo: set up .venv and run the main job on the bundled data (writes out/demo/)
# make test: set up .venv and run the tests against the installed wheel
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
WHEEL_STAMP := $(VENV)/.wheel
# the one data setting: the shared data beside this checkout unless MIMICA_DATA says otherwise
# (the installed wheel does not know where the checkout is)
MIMICA_DATA ?= $(abspath $(CURDIR)/..)/shared/data
export MIMICA_DATA
SOURCES := $(shell find src -type f -not -name '*.pyc' -not -path '*.egg-info*') pyproject.toml README.md

.PHONY: demo test test-lowest bench docs setup wheel clean blender

setup: $(WHEEL_STAMP)

# the dependencies at CI's exact versions (constraints/ci.txt); cholespy gives CHOLMOD's speed
# from a self-contained wheel; scikit-sparse, faster still, builds only where SuiteSparse's
# headers exist (Debian: libsuitesparse-dev, which .ci/run installs)
$(STAMP): pyproject.toml constraints/ci.txt
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c constraints/ci.txt setuptools wheel ".[test,cholmod]"
	$(BIN)/pip uninstall -q -y mimica
	-$(BIN)/pip install -q -c constraints/ci.txt scikit-sparse 2>/dev/null || echo "note: scikit-sparse not built (no SuiteSparse headers); cholespy's CHOLMOD is used"
	touch $(STAMP)

# mimica itself from its wheel, as a user installs it (never -e: package data must be declared)
$(WHEEL_STAMP): $(STAMP) $(SOURCES)
	rm -rf dist build
	$(BIN)/pip wheel -q --no-deps --no-build-isolation -w dist .
	$(BIN)/pip install -q --no-deps --force-reinstall dist/mimica-*.whl
	rm -rf build src/*.egg-info
	touch $(WHEEL_STAMP)

wheel: $(WHEEL_STAMP)

# the Khronos glTF-Validator (npm) that the tests run on every kind of GLB mimica writes; without
# Node.js the test is skipped here and fails under CI
GLTF_STAMP := tools/gltf/node_modules/.installed
$(GLTF_STAMP): tools/gltf/package.json tools/gltf/package-lock.json
	@if command -v npm >/dev/null 2>&1; then cd tools/gltf && npm ci --no-audit --no-fund --loglevel=error && touch node_modules/.installed; \
	else echo "note: npm not found; the glTF-Validator test will be skipped"; fi

# Blender as a Python module (bpy, Python 3.11 only, about 800 MB) in a venv of its own, for the
# add-on's test inside Blender and FBX (read and written through Blender): bpy needs numpy < 2,
# mimica numpy >= 2.  Made under CI; elsewhere `make blender` makes both and the tests then run,
# else they are skipped.
# the LTS the tests have used (4.5) and the current 5.x: the add-on and mimica's files in both.
# $(1): the venv, $(2): bpy's version
define bpy_venv
$(1)/.installed:
	$$(PY) -m venv $(1)
	$(1)/bin/pip install -q --upgrade pip
	$(1)/bin/pip install -q "bpy==$(2)"
	touch $(1)/.installed
endef
BLENDER_STAMP := .venv-blender/.installed
BLENDER5_STAMP := .venv-blender5/.installed
$(eval $(call bpy_venv,.venv-blender,4.5.15))
$(eval $(call bpy_venv,.venv-blender5,5.0.1))

blender: $(BLENDER_STAMP) $(BLENDER5_STAMP)

TEST_NEEDS := $(WHEEL_STAMP) $(GLTF_STAMP)
ifneq ($(CI),)
TEST_NEEDS += $(BLENDER_STAMP) $(BLENDER5_STAMP)
endif

demo: $(WHEEL_STAMP)
	$(BIN)/mimica demo --out out/demo

test: $(TEST_NEEDS)
	MIMICA_TEST_INSTALLED=1 $(BIN)/python -m pytest tests

# the lowest versions pyproject.toml allows, in a venv of their own
test-lowest:
	$(PY) -m venv out/venv-lowest
	out/venv-lowest/bin/pip install -q --upgrade pip
	out/venv-lowest/bin/pip install -q -c constraints/lowest.txt ".[test,cholmod]"
	out/venv-lowest/bin/python -m pytest tests

# the documentation site (MkDocs Material, the API pages from the docstrings by mkdocstrings, which
# reads the sources without importing them), in a venv of its own; strict: a warning, a broken
# link or reference fails the build
DOCS_STAMP := .venv-docs/.installed
$(DOCS_STAMP): constraints/ci.txt
	$(PY) -m venv .venv-docs
	.venv-docs/bin/pip install -q -c constraints/ci.txt mkdocs mkdocs-material "mkdocstrings[python]"
	touch $(DOCS_STAMP)

# the gallery's pictures are made by the build (docs/hooks/gallery.py) with mimica's own venv
docs: $(DOCS_STAMP) $(WHEEL_STAMP)
	MIMICA_PYTHON=$(abspath $(BIN)/python) NO_MKDOCS_2_WARNING=1 .venv-docs/bin/mkdocs build --strict --quiet
	@echo "the site: out/site/index.html"

# every benchmark, one after the other (never while tests run: the timings would mean nothing);
# each one's output in out/bench/NAME.txt, and at the end each one's line of figures
BENCHES := $(sort $(wildcard bench/*.py))
bench: $(WHEEL_STAMP) $(BLENDER_STAMP)
	$(BIN)/pip install -q -c constraints/ci.txt ".[bench]"
	$(BIN)/pip install -q --no-deps --force-reinstall dist/mimica-*.whl
	@mkdir -p out/bench
	@for b in $(BENCHES); do n=$$(basename $$b .py); echo "== $$b (out/bench/$$n.txt)"; \
	  MIMICA_BLENDER_PYTHON=$(CURDIR)/.venv-blender/bin/python $(BIN)/python $$b > out/bench/$$n.txt 2>&1 \
	    || { tail -20 out/bench/$$n.txt; echo "$$b failed"; exit 1; }; tail -1 out/bench/$$n.txt; done

clean:
	rm -rf out dist build $(VENV)
