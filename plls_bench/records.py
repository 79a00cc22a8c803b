"""Committed run records: what a fresh clone needs of every non-smoke run, kept in git.

Run dirs (``results/runs/``) are git-ignored: they hold checkpoints, replay chunks and logs. A
record keeps what the results collector reads (``config.json``, ``status.json``,
``provenance.json``, ``metrics/``, ``samples/``, ``studies/``, ``filmstrip/``) and the files that
rebuild the run's final policy (PPO: the checkpoint ``checkpoints/latest.json`` names; DBC: the
actor's weights, no replay), each file under :data:`~plls_bench.rundirs.record_layout.MAX_FILE_BYTES`.
Records live beside the runs dir (``results/records/`` for ``results/runs/``), in the same
``<experiment>/<variant>/seed=<k>`` layout, with the V_s / V_a models they use under
``artifacts/`` and unfinished learner runs under ``partial/`` (:mod:`plls_bench.rundirs.record_layout`; a file
over the cap travels there in parts). An unfinished run whose checkpoint is over the cap of a
partial record leaves its metrics so far under ``pending/`` (:mod:`plls_bench.rundirs.record_pending`):
evidence only, never resumed from or judged.

- ``reproduce`` counts a recorded trial as done (``--rerun-recorded`` runs it again);
- a trial that starts with a partial record of its config resumes from it
  (:mod:`plls_bench.rundirs.record_restore`);
- a V_s / V_a missing from the runs dir is copied from the records instead of trained
  (``repr.store``);
- the collector reads runs and records; a local run wins over a record with the same key and
  config (``report/evidence/load.py``); partial records are never read.

``python -m plls_bench.records [--runs results/runs] [--records DIR]`` exports
(:mod:`plls_bench.pipeline.record_export`); ``reproduce.sh`` does it after a non-smoke profile.

This module is the command (``python -m plls_bench.records``); the records' layout, restore,
pending records and snapshots are ``plls_bench/rundirs/record_*.py``.
"""
import sys

from plls_bench.pipeline.record_export import main

if __name__ == "__main__":
    sys.exit(main())
