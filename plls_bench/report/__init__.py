"""The results collector: ``python -m plls_bench.report`` turns run directories into every table
and figure of the paper, plus confidence intervals and a "paper vs suite" verdict table.

Public entry points: :func:`render_all` (render every registry id from a runs dir, returning each
id's status) and :data:`ENTRIES` / :data:`BY_ID` (the registry).

Layer ``report`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``report claims``); no layer below imports it.
"""
from plls_bench.report.collect import ReportError, render_all
from plls_bench.report.evidence.entry_types import IdStatus
from plls_bench.report.registry import BY_ID, ENTRIES

__all__ = ["BY_ID", "ENTRIES", "IdStatus", "ReportError", "render_all"]
