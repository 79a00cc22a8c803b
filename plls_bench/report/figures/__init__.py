"""Every figure the collector draws, and their plumbing (plot.py).

Layer ``report figures`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``report evidence``); no layer below imports it.
"""
