"""Comparison methods no maintained library provides (DBC), importable as ``baselines``."""
