# tma: make table | make test | make lint | make bench | make help | make clean
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# Every family's default experiment (conf/experiment/*_table.yaml); `make table EXPERIMENT=<name>`
# builds one.
EXPERIMENTS := $(sort $(basename $(notdir $(wildcard conf/experiment/*_table.yaml))))
EXPERIMENT ?= $(EXPERIMENTS)
ARGS ?=

.PHONY: help table test lint bench options clean venv

help:  ## list the targets
	@grep -E '^[a-z]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-7s %s\n", $$1, $$2}'

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

venv: $(STAMP)  ## create .venv from pyproject.toml

# pipeline.table runs the three stages in one process (one start-up, one worker pool); they
# still meet only through the files under data/
table: $(STAMP)  ## simulate -> estimate -> aggregate every default experiment into tables/
	@set -e; for exp in $(EXPERIMENT); do \
	  echo "== $$exp"; \
	  $(PY) -m pipeline.table experiment=$$exp $(ARGS); \
	done

# one pytest worker per core (at most 4: each builds its module fixtures); TEST_JOBS=0 runs in
# this process, e.g. for a debugger
TEST_JOBS ?= auto --maxprocesses=4
test: $(STAMP)  ## run the test suite (pytest, one worker per core)
	$(PY) -m pytest -q -n $(TEST_JOBS) $(ARGS)

lint: $(STAMP)  ## ruff
	$(VENV)/bin/ruff check tma pipeline tests bench examples

bench: $(STAMP)  ## benchmarks of every family (ratios against named baselines, stage times)
	$(PY) bench/bench.py $(ARGS)

options: $(STAMP)  ## every scenario, estimator, ingest, parallel option: key, default, range, meaning (ARGS=lm)
	$(PY) -m tma.options $(ARGS)

clean:  ## remove generated data, tables, Hydra outputs and caches (keeps .venv)
	rm -rf data tables outputs multirun .pytest_cache .ruff_cache .hypothesis
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
