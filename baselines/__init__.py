"""Comparison methods no maintained library provides (DBC), importable as ``baselines``.

Layer ``baselines`` of tests/test_imports.py, the bottom one: imports only from itself (torch and
numpy aside), nothing of ``plls_bench``; what the suite wants of it, such as the conv trunks' layout
and precision, it passes in (``DBCAgent(..., conv_stack=...)``).
"""
