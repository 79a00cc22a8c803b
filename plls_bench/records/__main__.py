"""``python -m plls_bench.records``: export runs into the committed records."""
import sys

from plls_bench.records.export import main

if __name__ == "__main__":
    sys.exit(main())
