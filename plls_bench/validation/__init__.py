"""The suite's checks of its own engineering choices, each a command writing results/analysis/: bf16
against fp32 (precision.py, precision_runs.py), gymnasium against envpool (backends.py), DBC
against the reference code (dbc_reference_parity.py), where a trained policy's mean action sits
(mean_action.py) and what an untrained policy sends to the env (action_spread.py).

Layer ``analyses`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``learners``); no layer below imports it.
"""
