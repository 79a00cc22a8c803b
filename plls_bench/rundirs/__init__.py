"""Run directories and what lives beside them: the run-dir contract (run_dir.py), devices, provenance,
the manifest of a copy without .git, content-addressed artifacts, the configs runs are composed
from with Hydra, and the committed records' layout, restore, pending records and checkpoint
snapshots (record_*.py).

Layer ``run dirs`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``config``); no layer below imports it.
"""
