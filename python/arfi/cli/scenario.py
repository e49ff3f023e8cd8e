"""``arfi scenario``: print a scenario as complete TOML, with the grid it resolves to."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from arfi.cli.common import add_common, load_scenario


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "scenario",
        help="print a scenario as TOML with every default written out",
        description="Print the scenario (default: the embedded one) as complete TOML, with the [grid] "
        "it resolves to (spacing, step, lateral size, last plane, absorbing layer, reflections, interface model). "
        "Delete [grid] keys after editing the frequency, transducer or focus to have them chosen again.",
        epilog="example: arfi scenario --default > phantom.toml",
    )
    add_common(p)
    p.add_argument("--default", action="store_true", help="print the embedded default scenario")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    sys.stdout.write(load_scenario(args).to_toml(chosen_grid=True))
    return 0
