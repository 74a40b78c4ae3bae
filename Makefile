# Two commands: `make demo` and `make test`. Each creates .venv on first use.
# `make docs` builds the API documentation (strict) into site/, in its own .venv-docs.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
OUT    ?= out/demo

.PHONY: demo test lint bench docs clean

$(VENV)/.base:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e .
	touch $@

$(VENV)/.test: $(VENV)/.base pyproject.toml
	$(PY) -m pip install --quiet -e '.[test]'
	touch $@

# The peers live in their own environment so that their pins never move the test environment.
BVENV := .venv-bench
$(BVENV)/.bench: pyproject.toml
	$(PYTHON) -m venv $(BVENV)
	$(BVENV)/bin/python -m pip install --quiet --upgrade pip
	$(BVENV)/bin/python -m pip install --quiet -e '.[bench]'
	touch $@

# The documentation tools live in their own environment too (jaxnav itself is installed there:
# the command reference is generated from its argparse parsers).
DVENV := .venv-docs
$(DVENV)/.docs: pyproject.toml
	$(PYTHON) -m venv $(DVENV)
	$(DVENV)/bin/python -m pip install --quiet --upgrade pip
	$(DVENV)/bin/python -m pip install --quiet -e '.[docs]'
	touch $@

demo: $(VENV)/.base
	$(VENV)/bin/jaxnav demo --out $(OUT)

# A worker that crashes ends the run (--max-worker-restart=0): after a restart xdist hung with both
# workers idle until CI's 90 minutes ran out.
test: $(VENV)/.test
	$(PY) -m pytest -q -n 2 --dist loadscope --no-loadscope-reorder --max-worker-restart=0

# ruff, configured in pyproject.toml: the linter's rules and the formatter's check.
lint: $(VENV)/.test
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

bench: $(BVENV)/.bench
	$(BVENV)/bin/python benchmarks/bench_filters.py

docs: $(DVENV)/.docs
	NO_MKDOCS_2_WARNING=1 $(DVENV)/bin/mkdocs build --strict --site-dir site

clean:
	rm -rf $(VENV) $(BVENV) $(DVENV) site .cache/mkdocs-jupyter out .pytest_cache
