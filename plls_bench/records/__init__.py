"""Committed run records: what a fresh clone needs of every non-smoke run, kept in git.

Run dirs (``results/runs/``) are git-ignored: they hold checkpoints, replay chunks and logs. A
record keeps what the results collector reads (``config.json``, ``status.json``,
``provenance.json``, ``metrics/``, ``samples/``, ``studies/``, ``filmstrip/``) and the files that
rebuild the run's final policy (PPO: the checkpoint ``checkpoints/latest.json`` names; DBC: the
actor's weights, no replay), each file under :data:`~plls_bench.records.layout.MAX_FILE_BYTES`.
Records live beside the runs dir (``results/records/`` for ``results/runs/``), in the same
``<experiment>/<variant>/seed=<k>`` layout, with the V_s / V_a models they use under
``artifacts/`` and unfinished learner runs under ``partial/`` (:mod:`plls_bench.records.layout`; a file
over the cap travels there in parts). An unfinished run whose checkpoint is over the cap of a
partial record leaves its metrics so far under ``pending/`` (:mod:`plls_bench.records.pending`):
evidence only, never resumed from or judged.

- ``reproduce`` counts a recorded trial as done (``--rerun-recorded`` runs it again);
- a trial that starts with a partial record of its config resumes from it
  (:mod:`plls_bench.records.restore`);
- a V_s / V_a missing from the runs dir is copied from the records instead of trained
  (``repr.store``);
- the collector reads runs and records; a local run wins over a record with the same key and
  config (``report/load.py``); partial records are never read.

``python -m plls_bench.records [--runs results/runs] [--records DIR]`` exports
(:mod:`plls_bench.records.export`); ``reproduce.sh`` does it after a non-smoke profile.

Only the layout is re-exported here: V_s / V_a loading and the learners read the layout and
restore records, while the export reads their checkpoints, so importing this package must not
import the export (it would run back up through the learners).
"""
from plls_bench.records.layout import MAX_FILE_BYTES, records_dir_for

__all__ = ["MAX_FILE_BYTES", "records_dir_for"]
