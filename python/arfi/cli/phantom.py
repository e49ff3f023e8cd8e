"""``arfi phantom``: a synthetic head CT (NIfTI, Hounsfield units) and a scenario that places it."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from arfi.cli.common import finish
from arfi.io.files import atomic_write_text


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "phantom",
        help="synthetic head CT (NIfTI, HU) and a scenario placing it",
        description="Write a seeded, skull-like head CT in Hounsfield units: scalp, an outer and an inner "
        "cortical table with the diploë between, thickness varying smoothly over the head, brain inside, air outside, "
        "CT noise. With --scenario-out, also write a scenario whose [ct] section places the head with the crown facing "
        "the array and a point 20 mm above the brain's centre at the focus (conversion aubry2003; water around the "
        "head).",
        epilog="example: arfi phantom --out head_ct.nii.gz --scenario-out head.toml && "
        "arfi field --scenario head.toml --out through_skull.npz",
    )
    p.add_argument("--out", required=True, metavar="CT.nii.gz", help="the CT volume (.nii or .nii.gz)")
    p.add_argument("--seed", type=int, default=0, help="draws the skull's thickness and bone values (default 0)")
    p.add_argument(
        "--voxel-mm", type=float, default=0.5, dest="voxel_mm", help="isotropic voxel size, mm (default 0.5)"
    )
    p.add_argument(
        "--thickness-mm",
        type=float,
        nargs=2,
        default=(4.0, 9.0),
        dest="thickness_mm",
        metavar=("MIN", "MAX"),
        help="the skull's thinnest and thickest, mm (default 4 9)",
    )
    p.add_argument(
        "--noise-hu", type=float, default=20.0, dest="noise_hu", help="CT noise standard deviation, HU (default 20)"
    )
    p.add_argument(
        "--scenario-out",
        metavar="FILE.toml",
        dest="scenario_out",
        help="also write a scenario with this CT in [ct] (default transducer and focus)",
    )
    p.add_argument(
        "--array",
        choices=["planar", "hemisphere"],
        default="planar",
        help="the transducer the scenario uses: the paper's planar array at 550 kHz with the focus 85 mm "
        "from it (default), or a 1024-element hemisphere of radius 150 mm out to 60 degrees at 650 kHz focused at its "
        "centre (0, 0, 150) mm",
    )
    p.add_argument("--json", metavar="FILE", help="write machine-readable results to FILE")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from arfi.io.phantom import array_focus_mm, head_phantom, placement, scenario_for
    from arfi.scenario import Scenario

    t = time.perf_counter()
    out = Path(args.out)
    if not out.name.endswith((".nii", ".nii.gz")):
        raise ValueError(f"--out: {out}: a CT must be written as .nii or .nii.gz")
    if args.scenario_out is not None and not args.scenario_out.endswith(".toml"):
        raise ValueError(f"--scenario-out: {args.scenario_out}: a scenario must be written as .toml")
    head = head_phantom(args.seed, args.voxel_mm, tuple(args.thickness_mm), args.noise_hu)
    transform = placement(focus_mm=array_focus_mm(args.array))
    scenario_text = None
    if args.scenario_out is not None:
        rel = os.path.relpath(out.resolve(), Path(args.scenario_out).resolve().parent)
        scenario_text = scenario_for(rel, args.seed, args.array)
    head.save(out)
    if scenario_text is not None:
        Scenario.from_toml(
            scenario_text, Path(args.scenario_out).resolve().parent
        )  # checks the placement against the CT
        atomic_write_text(Path(args.scenario_out), scenario_text)
    lo, hi, _ = head.thickness_mm
    print(
        f"phantom: head CT {head.hu.shape[0]} x {head.hu.shape[1]} x {head.hu.shape[2]} voxels of {args.voxel_mm:g} "
        f"mm, skull {lo:.1f}-{hi:.1f} mm thick (a smooth random thickness within the asked "
        f"{args.thickness_mm[0]:g}-{args.thickness_mm[1]:g} mm, drawn by seed {args.seed}) -> {out}"
        + (f"\nphantom: scenario -> {args.scenario_out}" if args.scenario_out else "")
    )
    finish(
        args,
        {
            "out": str(out),
            "shape": list(head.hu.shape),
            "voxel_mm": args.voxel_mm,
            "seed": args.seed,
            "skull_thickness_mm": [lo, hi],
            "scenario": args.scenario_out,
            "patient_to_transducer_mm": transform.tolist(),
            "seconds": time.perf_counter() - t,
        },
    )
    return 0
