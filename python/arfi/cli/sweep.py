"""``arfi sweep``: a Monte-Carlo study on dask.distributed."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from arfi.cli.common import add_common, finish
from arfi.scenario import Scenario


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "sweep",
        help="Monte-Carlo study on dask.distributed: noise x images x methods x seeds",
        description="Run the paper's study (calibrate, estimate, correct) for every combination of ARFI noise "
        "level, number of images (the aberrated one plus diversity images with seeded random known group phases), "
        "estimator and seed, on a dask.distributed cluster: a local one by default, or an existing one with "
        "--scheduler (its workers need arfi installed). Writes sweep.csv (one row per trial: recovered_fraction, gain, "
        "phase_error_rad, ambiguous, ...), summary.csv and sweep.png (recovered fraction against noise and images).",
        epilog="example: arfi sweep --noise-rad 0.01 0.02 0.05 --images 1 2 3 --methods lbfgs --seeds 5 --out sweep",
    )
    add_common(p)
    p.add_argument(
        "--noise-rad",
        dest="noise_levels",
        type=float,
        nargs="+",
        default=[0.02],
        metavar="S",
        help="ARFI noise levels (rad; default 0.02)",
    )
    p.add_argument(
        "--images", type=int, nargs="+", default=[1], metavar="K", help="images per trial (default 1, the paper's)"
    )
    p.add_argument(
        "--methods", nargs="+", default=["lbfgs"], metavar="M", help="nelder-mead, pso, lbfgs (default lbfgs)"
    )
    p.add_argument(
        "--seeds", type=int, default=3, help="trials per combination (seeds --seed, --seed+1, ...; default 3)"
    )
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument(
        "--case", type=int, choices=[16, 1024], default=16, help="16 group or 1024 element aberrations (default 16)"
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="an existing dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)",
    )
    p.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per CPU)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for sweep.csv, summary.csv and sweep.png")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from arfi.analysis.sweep import run_sweep, sweep_json, trials, write_results

    points = trials(args.noise_levels, args.images, args.methods, args.seeds, args.case, args.seed)
    scenario = Scenario.load(args.scenario) if args.scenario else None
    t = time.perf_counter()
    rows = run_sweep(points, scenario, args.scheduler, args.workers)
    summary = write_results(rows, Path(args.out))
    for s in summary:
        print(
            f"sweep: {s.method:>11}, {s.images} image(s), noise {s.noise_rad:g} rad: recovered "
            f"{s.recovered_fraction_mean:.2f} ± {s.recovered_fraction_std:.2f} ({s.trials} trials)"
        )
    print(
        f"sweep: {len(rows)} trials in {time.perf_counter() - t:.0f} s -> {args.out}/sweep.csv, summary.csv, sweep.png"
    )
    finish(args, {**sweep_json(rows, summary), "seconds": time.perf_counter() - t})
    return 0
