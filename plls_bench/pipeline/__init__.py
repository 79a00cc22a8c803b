"""What composes and launches runs: the runner registry (runner_registry.py), executing one config
(execute.py), the dry-run plan and its rates, launching, declared sweeps, ablation overrides, the
resolved configs and the records' export (record_export.py).

Layer ``pipeline`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``analyses``); no layer below imports it.
"""
