# Two commands do all the set-up on a fresh machine:
#   make demo   -> creates .venv if missing, installs the project, runs the main job
#   make test   -> same set-up, then the default (fast) test suite
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
OUT    ?= results
# test processes for `make test` (pytest-xdist; one per core by default, 0 to run in-process)
TEST_WORKERS ?= auto

.PHONY: demo test test-slow test-all bench lint docs cf-check clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dem,test,docs]'
	touch $(STAMP)

demo: $(STAMP)
	$(PY) scripts/demo.py --out $(OUT)

test: $(STAMP)
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile

test-slow: $(STAMP)
	$(PY) -m pytest -m slow

test-all: $(STAMP)
	$(PY) -m pytest -m ''

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy

# the documentation site, warnings as errors, into site/ (tests/test_docs.py builds it too)
docs: $(STAMP)
	$(PY) -m mkdocs build --strict

# CF-1.11 check of the netCDF files we write: installs the optional extra 'cf' (the IOOS
# compliance-checker, offline: it ships the standard-name table, cf-units bundles UDUNITS-2, so
# no `apt-get install libudunits2-0` is needed), then runs only tests/test_cf_conventions.py
# with the checker required. `make test` runs that file too, skipping the checker's part.
cf-check: $(STAMP)
	$(PY) -m pip install --quiet -e '.[cf]'
	CF_CHECK_REQUIRED=1 $(PY) -m pytest tests/test_cf_conventions.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
