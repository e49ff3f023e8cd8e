"""``arfi reproduce``: the paper's study in simulation."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from arfi.cli.common import UsageError, add_common, add_method, finish


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "reproduce",
        help="re-run the paper's study in simulation (Table 1, Figures 2-10, HTML)",
        description="Re-run the paper's phantom study in simulation with seeded skull-like aberrations: "
        "calibration, one aberrated image per repeat, estimation of 16 group phases, correction. Writes Table 1 "
        "(table.csv, results.json), Figures 2-10 as PNG and report.html to DIR.",
        epilog="example: arfi reproduce --case 16 --repeats 3 --out results",
    )
    add_common(p)
    p.add_argument("--case", type=int, choices=[16, 1024], default=16, help="16 group aberrations or 1024 element ones")
    p.add_argument("--repeats", type=int, default=3, help="aberrations drawn, each estimated and corrected (default 3)")
    p.add_argument(
        "--out", required=True, metavar="DIR", help="folder for table.csv, results.json, the figures and report.html"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="first seed: repeat k draws its aberration and noise from seed + k (default 0)",
    )
    add_method(p, "nelder-mead", "estimator (default: the paper's Nelder-Mead)")
    p.add_argument("--noise-rad", type=float, dest="noise_rad", help="ARFI noise (default: the scenario's, 0.02 rad)")
    p.add_argument(
        "--diversity",
        type=int,
        default=0,
        help="extra images per repeat with random known group phases (phase diversity; default 0, the paper's)",
    )
    p.add_argument(
        "--loop2",
        type=int,
        default=0,
        metavar="N",
        help="the paper's loop 2: N more acquisitions per repeat, each with the current correction applied, fitted "
        "jointly; keeps the correction measured best, or none (default 0: loop 1 only, as in the paper)",
    )
    p.add_argument(
        "--no-ladder",
        dest="ladder",
        action="store_false",
        help="skip the ladder (by default the same seeds also go through loop 2, diversity images, a CT-like "
        "prediction alone and the prediction with MR-ARFI, side by side in the report)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from arfi.analysis.ladder import summary_line
    from arfi.analysis.reproduce import run_study

    if args.scenario:
        raise UsageError("arfi reproduce: runs on the embedded scenario (the paper's phantom); --scenario is not taken")
    s = run_study(
        args.case,
        args.repeats,
        Path(args.out),
        seed=args.seed,
        method=args.method,
        noise_rad=args.noise_rad,
        diversity=args.diversity,
        loop2_iterations=args.loop2,
        ladder=args.ladder,
    )
    print(
        f"reproduce: {s.case}-aberration, {s.repeats} repeats ({s.method}): recovered fraction "
        f"{s.mean_recovered_fraction:.2f} (paper {s.paper.recovered_fraction}), gain {s.mean_gain:+.0%} "
        f"(paper {s.paper.gain:+.0%}), phase error {s.mean_phase_error_rad:.2f} rad (paper "
        f"{s.paper.phase_error_rad}) in {s.seconds:.1f} s -> {args.out}/report.html"
    )
    flagged = s.ambiguous
    if flagged and not (args.diversity or args.loop2):
        print(
            f"reproduce: {flagged} of {len(s.table)} estimates flagged ambiguous (other aberrations fit their image "
            "within the noise: one in-focus image hardly tells phi(u) from -phi(-u)); known diversity images "
            "(--diversity 3) or the paper's loop 2 (--loop2 3) resolve them"
        )
    elif flagged:
        print(
            f"reproduce: {flagged} of {len(s.table)} final estimates still flagged ambiguous: more images would "
            "narrow them"
        )
    if s.ladder:
        print("reproduce: " + summary_line(s.ladder, s.paper.recovered_fraction))
    finish(args, s.to_dict())
    return 0
