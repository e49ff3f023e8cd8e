"""The ``arfi`` command line: one module per verb.

Every verb takes ``--scenario FILE`` (default: the embedded scenario) and ``--json FILE`` for
machine-readable results. Options are checked once, by the library functions the verbs call
(``ValueError`` naming the parameter), before anything is written; bad input ends with one line
on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from arfi.cli import (
    calibrate,
    diagnose,
    dicom,
    envelope,
    estimate,
    field,
    phantom,
    predict,
    reproduce,
    scenario,
    simulate,
    sweep,
    validate,
)
from arfi.cli.common import Parser, UsageError

#: The verbs, in the order ``arfi --help`` lists them.
VERBS = (
    scenario,
    phantom,
    field,
    predict,
    envelope,
    simulate,
    dicom,
    calibrate,
    estimate,
    diagnose,
    sweep,
    reproduce,
    validate,
)

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
