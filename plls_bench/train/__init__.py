"""Policy learning: the ``ppo`` runner on stable-baselines3 (the paper's networks, checkpoints) and the
``dbc`` runner.

Layer ``learners`` of tests/test_imports.py: imports only from itself and the layers below it
(``baselines``, ``core`` up to ``representations``); no layer below imports it.
"""
