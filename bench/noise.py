"""The noise test (the paper's Table 3): ``python -m bench.noise --level small|medium|high|all``.

Every requested method on the same cells at L = 1/4 and S = 128, under the paper's noise levels
(:data:`neuspike.conditions.NOISE_LEVELS`): ``small`` = spike fixed-pattern dark current with ISI
spread sigma 10 planes and event shot noise 0.001 Hz, ``medium`` = 50 and 10 Hz, ``high`` = 90 and
100 Hz, each with Algorithm 1's random initial charge. Options, outputs, resuming and exit status
are those of :mod:`bench.sweep`.
"""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

from bench.harness import grid as grids
from bench.sweep import COMMON_EPILOG, add_common_arguments, run_command, spec_from_args

LEVELS = grids.PAPER_NOISE_LEVELS


def levels_of(choice: str) -> tuple[str, ...]:
    """``"all"`` -> the three paper levels; a level name -> itself."""
    return LEVELS if choice == "all" else (choice,)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bench.noise",
        description="The noise test (the paper's Table 3): every registered method at L = 1/4, S = 128 "
        "under the paper's noise levels (small: spike dark-current ISI sigma 10 planes, event shot noise "
        "0.001 Hz; medium: 50, 10 Hz; high: 90, 100 Hz; each with a random initial charge).",
        epilog="examples:\n"
        "  python -m bench.noise                               # all three levels, quick size\n"
        "  python -m bench.noise --level high --methods tfi,events-integrate,fusion-complementary\n"
        "  python -m bench.noise --full --weights ../shared/weights/firenet\n\n" + COMMON_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--level", choices=LEVELS + ("all",), default="all",
                        help="noise level, or all three (default: all)")
    add_common_arguments(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    name = "noise" if args.level == "all" else f"noise-{args.level}"
    default_out = f"runs/{name}" + ("-full" if args.full else "")
    return run_command(lambda a: spec_from_args(a, name, "noise", noises=levels_of(a.level)), args, default_out)


if __name__ == "__main__":
    sys.exit(main())
