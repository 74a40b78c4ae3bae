# Two commands: `make demo` and `make test`. Each creates .venv on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
OUT    ?= out/demo

.PHONY: demo test bench clean

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

demo: $(VENV)/.base
	$(VENV)/bin/jaxnav demo --out $(OUT)

test: $(VENV)/.test
	$(PY) -m pytest -q -n 2 --dist loadscope --no-loadscope-reorder

bench: $(BVENV)/.bench
	$(BVENV)/bin/python benchmarks/bench_filters.py

clean:
	rm -rf $(VENV) $(BVENV) out .pytest_cache
