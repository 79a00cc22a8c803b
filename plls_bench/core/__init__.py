"""Leaf utilities, importing nothing of the suite: atomic files (atomic_files.py), the stable hash of
configs and artifacts, seeding, progress bars (progress_bars.py), SIGTERM as an exception, glibc's
freed-memory setting (malloc_retain.py) and the typed metric rows every trainer writes and the
collector reads (metric_rows.py).

Layer ``core`` of tests/test_imports.py, the lowest: imports nothing of the suite.
"""
