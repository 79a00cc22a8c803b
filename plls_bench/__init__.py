"""plls-bench: reference reproducibility suite for PL-LS (Zhao et al., arXiv 2211.13257)."""

__version__ = "0.1.0"
