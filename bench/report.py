"""Figures, tables and a PDF from a results folder alone: ``python -m bench.report RESULTS_DIR``.

The command of :mod:`bench.reporting.build` (what it reads and writes is described there); nothing heavy is
imported before the arguments are parsed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence


# ----------------------------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench.report",
        description="Rebuild every figure, table and report.pdf of a results folder from its files alone "
        "(results.csv and/or timing.csv, config.json, metadata.json, images/). Nothing is simulated and no "
        "method runs.",
        epilog="examples:\n  python -m bench.report runs/light\n  python -m bench.report runs/timing --out /tmp/t",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("results_dir", help="a folder written by bench.sweep, bench.noise or bench.timing")
    parser.add_argument("--out", help="write figures/, tables/ and report.pdf here (default: RESULTS_DIR)")
    parser.add_argument("--spread", choices=("std", "minmax"), default="std",
                        help="band around the axis figures' lines: mean ± 1 std over scenes and seeds (default), "
                        "or min..max")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from bench.reporting.build import build_report

    try:
        pdf = build_report(Path(args.results_dir), Path(args.out) if args.out else None, spread=args.spread)
    except (FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"report: {pdf}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
