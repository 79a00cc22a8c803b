# Thin wrapper: every target bootstraps .venv the same way reproduce.sh does.
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup setup-dev lint test test-fast docs smoke bench

setup:
	./reproduce.sh --setup-only

setup-dev:  ## .venv with the dev extra (pytest, mkdocs, ruff)
	./reproduce.sh --setup-only --dev

lint: setup-dev  ## ruff over the whole tree (rules and why: pyproject.toml, [tool.ruff])
	$(PY) -m ruff check .

test: setup-dev  ## the test suite CI runs (2 cores, no GPU)
	$(PY) -m pytest

test-fast: setup-dev  ## the tests not marked slow (minutes instead of the full suite's ~30 min)
	$(PY) -m pytest -m "not slow"

docs: setup-dev  ## the docs site from docs/ and results/ into site/, strict: a broken link or page fails
	$(PY) -m mkdocs build --strict --site-dir site

smoke: setup  ## the whole pipeline at smoke budget
	./reproduce.sh --profile smoke

bench: setup  ## re-measure dry-run rates (bench/throughput.json) and the smoke profile's wall time
	nice -n 10 $(PY) bench/throughput.py
	nice -n 10 $(PY) bench/profile_time.py
