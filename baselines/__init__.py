"""Comparison methods no maintained library provides (DBC), importable as ``baselines``.

Layer ``baselines`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``representations``); no layer below imports it.
"""
