"""The ``arfi`` command line: one module per verb.

Every verb takes ``--scenario FILE`` (default: the embedded scenario) and ``--json FILE`` for
machine-readable results. Bad input ends with one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from typing import Callable, Sequence

import numpy as np

from arfi.cli import calibrate, diagnose, dicom, estimate, field, reproduce, scenario, simulate, sweep
from arfi.cli.common import Parser, UsageError

#: The verbs, in the order ``arfi --help`` lists them.
VERBS = (scenario, field, simulate, dicom, calibrate, estimate, diagnose, sweep, reproduce)

__all__ = ["UsageError", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="arfi",
        description="Hybrid simulation–MR-ARFI phase aberration correction for focused ultrasound.",
    )
    sub = parser.add_subparsers(dest="verb", metavar="VERB", parser_class=Parser)
    sub.required = True
    for verb in VERBS:
        verb.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: returns the exit status (0 ok, 2 bad input)."""
    try:
        args = build_parser().parse_args(argv)
        if getattr(args, "seed", 0) is not None and not 0 <= getattr(args, "seed", 0) < 2**64:
            raise UsageError("--seed: must be an integer in [0, 2**64)")
        for name in ("max_width_mm", "time_limit_s"):
            v = getattr(args, name, None)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise UsageError(f"--{name.replace('_', '-')}: must be a finite number > 0, got {v}")
        if getattr(args, "repeats", 1) is not None and not 1 <= getattr(args, "repeats", 1) <= 100:
            raise UsageError(f"--repeats: must be between 1 and 100, got {args.repeats}")
        if not 0 <= getattr(args, "diversity", 0) <= 32:
            raise UsageError(f"--diversity: must be between 0 and 32, got {args.diversity}")
        if not 0 <= getattr(args, "loop2", 0) <= 20:
            raise UsageError(f"--loop2: must be between 0 and 20, got {args.loop2}")
        for name in ("max_evaluations", "starts"):
            v = getattr(args, name, None)
            if v is not None and v <= 0:
                raise UsageError(f"--{name.replace('_', '-')}: must be > 0, got {v}")
        if getattr(args, "noise_rad", None) is not None and not (np.isfinite(args.noise_rad) and args.noise_rad >= 0):
            raise UsageError(f"--noise-rad: must be a finite number >= 0, got {args.noise_rad}")
        run: Callable[[argparse.Namespace], int] = args.run
        return run(args)
    except (UsageError, ValueError, FileNotFoundError, IsADirectoryError, PermissionError) as e:
        print(f"arfi: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("arfi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
