# Thin wrapper: every target bootstraps .venv the same way reproduce.sh does.
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup test smoke bench

setup:
	./reproduce.sh --setup-only

test: setup  ## the test suite CI runs (2 cores, no GPU)
	$(PY) -m pytest

smoke: setup  ## the whole pipeline at smoke budget
	./reproduce.sh --profile smoke

bench: setup  ## re-measure dry-run rates (bench/throughput.json) and the smoke profile's wall time
	nice -n 10 $(PY) bench/throughput.py
	nice -n 10 $(PY) bench/profile_time.py
