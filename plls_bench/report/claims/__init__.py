"""The paper-vs-suite claims table: values, comparisons, levels, sweeps, power, costs.

Layer ``report claims`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``report tables``); no layer below imports it.
"""
