"""``arfi validate``: the propagation on default grids against exact solutions (checks an install)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from arfi.cli.common import finish


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "validate",
        help="check the propagation against exact solutions (water, plates, skull layers, shells, "
        "tilted plates) and stored full-wave results (textured skull caps)",
        description="Run the validation suite: the ITRUSST benchmark's bowl (500 kHz, R 64 mm, aperture "
        "64 mm) in water, through a 6.5 mm cortical plate (BM3), through the flat layered skull (BM4) and through two "
        "caps of cortical bone read from CTs (a shell about the focus, and a BM5-like cap met obliquely), and BM3's "
        "plate read from a CT untilted and turned 10, 20 and 30 degrees about y, each on the grid its scenario chooses "
        "by default, against exact solutions written independently of the propagation; then three-layer skull caps "
        "about the focus read from CTs, their diploe uniform or textured over 1 and 3 mm, against stored full-wave "
        "results (BabelViscoFDTD at 0.5 mm, made once by benches/fullwave/caps_fdtd.py), where no exact solution "
        "exists. Prints the table of focal pressure, focal position, axial profile and focal-plane correlation with "
        "pass/fail (the tilted plates, fluid and solid, against their own, looser tolerances, printed in their rows), "
        "and writes a report with the profiles overlaid. Exit status 1 if a case fails.",
        epilog="example: arfi validate --out validation/",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        help="write DIR/report.html, DIR/validation.md, DIR/validation.json and one PNG per case",
    )
    p.add_argument(
        "--case",
        action="append",
        dest="cases",
        metavar="NAME",
        help="run only this case (repeatable): water, bm3, bm4, bm3_solid, shell, bm5, tilt0, tilt10, tilt20, "
        "tilt30, tilt0_shear1500, tilt10_shear1500, tilt20_shear1500, tilt30_shear1500, cap_uniform, cap_texture1, "
        "cap_texture3, head220",
    )
    p.add_argument("--json", metavar="FILE", help="write machine-readable results to FILE")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from arfi.validation.suite import case_json, check_cases, table, write_report
    from arfi.validation.suite import run as run_suite

    cases = check_cases(args.cases, "--case")
    if args.out is not None and Path(args.out).exists() and not Path(args.out).is_dir():
        raise ValueError(f"--out: {args.out} exists and is not a folder")
    t = time.perf_counter()
    results = run_suite(cases, progress=lambda name: print(f"validate: {name} ...", file=sys.stderr, flush=True))
    print(table(results))
    failed = [r.name for r in results if not r.passed]
    if args.out is not None:
        print(f"validate: report -> {write_report(args.out, results)}")
    print(
        f"validate: {len(results) - len(failed)} of {len(results)} cases pass"
        + (f" ({', '.join(failed)} fail)" if failed else "")
        + f" in {time.perf_counter() - t:.1f} s"
    )
    finish(args, {"cases": [case_json(r) for r in results], "passed": not failed})
    return 1 if failed else 0
