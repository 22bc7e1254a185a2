# `make test`, `make demo` and `make docs` each create .venv when missing and install what they need.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-test
# bpy gets its own environment (it pins NumPy < 2; JAX needs NumPy 2). Its wheels exist for one
# Python version per Blender release (3.11 for Blender 4.x-5.0); where none fits, the Blender
# export test skips and says why.
BPY_VENV  := .venv-bpy
BPY_PYTHON ?= $(PYTHON)
BPY_STAMP := $(BPY_VENV)/.installed

.PHONY: test demo docs lint format bench clean interop

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e '.[test,interop]'
	touch $(STAMP)

$(BPY_STAMP):
	$(BPY_PYTHON) -m venv $(BPY_VENV)
	$(BPY_VENV)/bin/python -m pip install --quiet 'bpy>=4.2' && touch $(BPY_STAMP) || \
		echo "make: bpy is not installable for $$($(BPY_PYTHON) --version); the Blender export test will skip" >&2

# Mitsuba 3, MaterialX, usd-core (the interop extra) and bpy for the export tests.
interop: $(STAMP) $(BPY_STAMP)

# The whole pipeline on the simulated rig; the report lands in gonio-demo/index.html.
demo: $(STAMP)
	$(VENV)/bin/gonio demo --force $(DEMO_ARGS)

test: $(STAMP) $(BPY_STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/ruff format --check src tests benchmarks
	$(VENV)/bin/pytest -n 2 --dist loadgroup

# The documentation site (docs/, mkdocs.yml) into site/; open site/index.html.
docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/ruff format --check src tests benchmarks

format: $(STAMP)
	$(VENV)/bin/ruff check --fix src tests benchmarks
	$(VENV)/bin/ruff format src tests benchmarks

bench: $(STAMP)
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) $(BPY_VENV) gonio-demo site .pytest_cache build src/*.egg-info
