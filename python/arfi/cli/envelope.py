"""``arfi envelope``: where in the head the array can focus, how strongly, at what cost to the skull."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from arfi.cli.common import UsageError, add_common, finish, load_scenario
from arfi.io.files import read_targets
from arfi.progress import Progress


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "envelope",
        help="treatment envelope: the corrected focus over a grid of targets in the brain, and the skull's cost",
        description="Over a grid of targets in the brain of the scenario's CT ([ct]), predict each target's "
        "correction (as arfi predict, one plan of each head for many targets) and give its focal pressure with the "
        "corrected phases, uncorrected and with straight-ray CT steering, the ratio of the corrected focus to the "
        "focus in water (every element in phase), the distance of the corrected beam's focal peak from the target, "
        "and the hottest place in the skull (I_SPPA per MPa² of focal pressure: how hot the skull runs for a given "
        "focus, whatever the drive). Targets in the skull, the scalp or the coupling medium are counted, not "
        "evaluated. Writes to --out: envelope.csv (a row per target), a NIfTI volume per quantity on the CT's voxels "
        "and affine (to open over the CT in 3D Slicer), envelope.png (three orthogonal slices over the CT) and "
        "scenario.toml; prints a one-line summary. Run again with the same --out to resume: targets already in "
        "envelope.csv are skipped. Tasks of many targets (each builds its plans once) run in this process, or on "
        "dask.distributed with --workers or --scheduler.",
        epilog="example: arfi envelope --scenario head.toml --box-mm -20 20 -20 20 130 170 --spacing-mm 10 "
        "--out envelope",
    )
    add_common(p)
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--box-mm",
        type=float,
        nargs=6,
        dest="box_mm",
        metavar=("X0", "X1", "Y0", "Y1", "Z0", "Z1"),
        help="a box of targets (mm, transducer frame), --spacing-mm apart along each axis from its lowest corner",
    )
    where.add_argument(
        "--targets",
        metavar="FILE.csv",
        help="targets from a CSV file (a header naming x_mm, y_mm, z_mm, transducer frame; one row per target)",
    )
    p.add_argument(
        "--spacing-mm",
        type=float,
        dest="spacing_mm",
        help="the box's spacing (required with --box-mm); with --targets, the side of the cube each target fills in "
        "the volumes (default: the median distance between neighbouring targets)",
    )
    p.add_argument(
        "--reachable-mpa",
        type=float,
        dest="reachable_mpa",
        help="the summary counts a target reachable when its corrected focus reaches this pressure (MPa, at the "
        "scenario's drive); default: half the highest corrected focus of the envelope (-6 dB of its best target)",
    )
    p.add_argument(
        "--task-size",
        type=int,
        dest="task_size",
        help="targets per task, each task building the plans once (default: the targets shared evenly among the "
        "workers, at most 25 a task: a stopped run keeps every finished task)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        help="local dask.distributed worker processes sharing this machine's cores (default 1: no dask, this "
        "process); each holds one plan of the head at a time",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="an existing dask scheduler, e.g. tcp://10.0.0.5:8786, whose workers have arfi and can read the "
        "scenario's CT at the same path",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="folder for envelope.csv, the volumes and envelope.png")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from arfi.analysis.envelope import (
        box_targets,
        cell_size_mm,
        on_ct_voxels,
        plot,
        run_envelope,
        summary_line,
        write_volumes,
    )

    if args.box_mm is not None:
        if args.spacing_mm is None:
            raise UsageError("--spacing-mm: required with --box-mm")
        targets = box_targets(args.box_mm, args.spacing_mm)
    else:
        try:
            targets = np.array(read_targets(args.targets), dtype=np.float64)
        except (ValueError, OSError) as e:
            raise UsageError(f"--targets: {e}") from None
        if args.spacing_mm is not None and not (np.isfinite(args.spacing_mm) and args.spacing_mm > 0):
            raise UsageError(f"--spacing-mm: must be a positive number, got {args.spacing_mm}")
    if args.reachable_mpa is not None and not (np.isfinite(args.reachable_mpa) and args.reachable_mpa > 0):
        raise UsageError(f"--reachable-mpa: must be a positive number, got {args.reachable_mpa}")
    scenario = load_scenario(args)
    if scenario.to_dict().get("ct") is None:
        raise UsageError("--scenario: an envelope needs a CT of the head ([ct]); arfi phantom writes a synthetic one")
    out = Path(args.out)
    t = time.perf_counter()
    bar: Progress | None = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if bar is None:
            bar = Progress("envelope: targets", total, "targets")
        bar.update(done)

    try:
        points, counts = run_envelope(
            scenario, targets, out, args.task_size, args.scheduler, args.workers, progress=progress
        )
    except ValueError as e:
        # The core and the library name their parameters; the user gave them as options.
        text = str(e)
        options = {
            "targets:": "--targets" if args.targets else "--box-mm",
            "out:": "--out",
            "task_size:": "--task-size",
            "workers:": "--workers",
            "scheduler:": "--scheduler",
        }
        name = next((n for n in options if text.startswith(n)), None)
        raise UsageError(text if name is None else f"{options[name]}:{text[len(name) :]}") from None
    seconds = time.perf_counter() - t
    cell = args.spacing_mm if args.spacing_mm is not None else cell_size_mm(targets)
    files = ["envelope.csv", "scenario.toml"]
    if points:
        on_ct = on_ct_voxels(scenario, points, cell)
        files += write_volumes(on_ct, out)
        plot(scenario, points, on_ct, out / "envelope.png")
        files.append("envelope.png")
    threshold = None if args.reachable_mpa is None else args.reachable_mpa * 1e6
    line = summary_line(points, counts, threshold)
    print(line)
    print(f"envelope: {len(points)} targets in {seconds:.0f} s -> {out}/ ({', '.join(files)})")
    finish(
        args,
        {
            "targets": [p.to_row() for p in points],
            "tissues": counts,
            "summary": line,
            "files": files,
            "seconds": seconds,
        },
    )
    return 0
