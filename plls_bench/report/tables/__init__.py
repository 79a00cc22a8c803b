"""Tables beside the claims: the paper's Tables 1-3 (efficiency.py), return comparisons, variants.

Layer ``report tables`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``report figures``); no layer below imports it.
"""
