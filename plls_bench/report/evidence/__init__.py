"""The collector's inputs and shared pieces: its types (entry_types.py), runs and records loaded into
trials, return curves, matched arms, statistics, the declared verdict protocol and its settings
(claims.yaml, read by claim_settings.py), verdicts, sweep and variant arms, table formats.

Layer ``report evidence`` of tests/test_imports.py: imports only from itself and the layers below
it (``core`` up to ``pipeline``); no layer below imports it.
"""
