"""``python -m plls_bench.film RUN_DIR``: film a run's policy (:mod:`plls_bench.film`)."""
import sys

from plls_bench.film import main

if __name__ == "__main__":
    sys.exit(main())
