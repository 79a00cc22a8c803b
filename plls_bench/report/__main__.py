"""``python -m plls_bench.report [--runs results/runs | --records-only] [--records DIR] [--out results]
[--only ID ...] [--list]``

Regenerates every table and figure of the paper from run directories (see ``registry.py``).
Exit status: 0 when every id rendered (gaps are reported, not errors), 1 when an id failed to
render (a collector bug: its traceback is logged), 2 for bad arguments (nothing written).
"""
from __future__ import annotations

import argparse
import logging
import shlex
import sys
from pathlib import Path

from plls_bench.report.collect import PAPER_DIR, ReportError, render_all
from plls_bench.report.evidence.returns import DEFAULT_X_AXIS, X_AXES
from plls_bench.report.registry import ENTRIES, builder_name
from plls_bench.rundirs.record_layout import records_dir_for


def print_registry() -> None:
    for entry in ENTRIES:
        presets = ", ".join(entry.experiments)
        print(f"{entry.id:7s} {entry.ref:18s} {entry.kind:6s} {entry.title}\n"
              f"        presets: {presets} (variant default)\n"
              f"        reads:   {entry.reads}\n"
              f"        built by {builder_name(entry)}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plls_bench.report", description=__doc__.split("\n\n")[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="results/runs", help="root of the run directories (read only)")
    parser.add_argument("--records", default=None,
                        help="committed run records read beside the runs (default: 'records' beside --runs)")
    sources = parser.add_mutually_exclusive_group()
    sources.add_argument("--no-records", action="store_true", help="read the runs dir only")
    sources.add_argument("--records-only", action="store_true",
                         help="read the committed records only, not the runs dir: results/ as a fresh clone "
                         "regenerates it")
    parser.add_argument("--out", default="results", help="where tables/, figures/, index.json and README.md go")
    parser.add_argument("--only", nargs="+", metavar="ID", help="regenerate only these ids (see --list)")
    parser.add_argument("--list", action="store_true", help="print the registry and exit")
    parser.add_argument("--x-axis", default=DEFAULT_X_AXIS, choices=X_AXES, help="x axis of the return curves")
    parser.add_argument("--paper", default=str(PAPER_DIR), help="folder of the paper's numbers (*.csv) and the claims' "
                        "decision settings (claims.yaml)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.list:
        print_registry()
        return 0
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    command = shlex.join(["python", "-m", "plls_bench.report", *(sys.argv[1:] if argv is None else argv)])
    if args.records is not None and not args.records_only and not Path(args.records).is_dir():
        # the default beside --runs may be absent (a runs dir of one's own); a folder named must exist
        print(f"plls_bench.report: --records {args.records}: no such directory", file=sys.stderr)
        return 2
    try:
        records = None if args.no_records else (args.records or records_dir_for(args.runs))
        statuses = render_all(None if args.records_only else args.runs, args.out, args.only, args.x_axis, args.paper,
                              progress=not args.no_progress, command=command, records_dir=records)
    except ReportError as err:
        print(f"plls_bench.report: {err}", file=sys.stderr)
        return 2
    for status in statuses.values():
        shown = ", ".join(f"{k}: {v}" for k, v in status.trials.items())
        print(f"{status.id:7s} {status.status:8s} {len(status.gaps):3d} gap(s)  {shown}")
        if status.error:
            print(f"        error: {status.error}")
    print(f"wrote {args.out}/README.md")
    return 1 if any(s.status == "error" for s in statuses.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
