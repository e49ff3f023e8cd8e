"""``arfi field``: the complex pressure on a plane and along the beam axis."""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from arfi.cli.common import add_common, add_report, finish, load_scenario, read_optional_phases
from arfi.io import npz_path, write_npz
from arfi.simulation import Simulation


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser("field", help="complex pressure on a plane and the beam axis (.npz)",
                       description="Simulate the beam (HAS) and write the complex pressure amplitude (Pa) on the "
                       "plane z = Z and along the beam axis.",
                       epilog="example: arfi field --z-mm 85 --out focus.npz")
    add_common(p)
    p.add_argument("--phases", metavar="P", help="phases (rad) added to the steering: .npy or text, one per element or group")
    p.add_argument("--correction", metavar="P", help="an estimate's or a prediction's phases_rad (.npy or text), "
                   "subtracted from the steering: the corrected beam (with --phases: both)")
    p.add_argument("--z-mm", type=float, dest="z_mm", help="plane z in mm (default: the focus)")
    p.add_argument("--out", required=True, metavar="F.npz")
    add_report(p, "PNG figures (|p| in MPa on the plane in mm, the axis profile, and the beam on the x-z section "
                  "through the plane's peak over the sound speed: one more march)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    npz_path(args.out)  # before the simulation
    t = time.perf_counter()
    sim = Simulation(load_scenario(args))
    phases = read_optional_phases(args.phases, "--phases")
    correction = read_optional_phases(args.correction, "--correction")
    if correction is not None:
        added = sim.element_phases(phases, "--phases") if phases is not None else np.zeros(sim.n_elements)
        phases = added - sim.element_phases(correction, "--correction")
    f = sim.field(phases, args.z_mm)
    write_npz(
        args.out,
        {
            "pressure": f.pressure,
            "x_mm": f.x_mm,
            "y_mm": f.y_mm,
            "z_mm": np.float64(f.z_mm),
            "axis_pressure": f.axis_pressure,
            "axis_z_mm": f.axis_z_mm,
            "surface_pressure_pa": np.float64(f.surface_pressure_pa),
        },
    )
    focus = f.focus()
    print(
        f"field: plane z = {f.z_mm:.2f} mm, peak {focus['plane_peak_pa'] / 1e6:.3f} MPa at "
        f"({focus['plane_peak_x_mm']:.2f}, {focus['plane_peak_y_mm']:.2f}) mm; axis peak "
        f"{focus['axis_peak_pa'] / 1e6:.3f} MPa at z = {focus['axis_peak_z_mm']:.2f} mm -> {args.out}\n"
        f"field: {sim.propagation_summary()}"
    )
    if args.report:
        from arfi.report import field_report

        field_report(args.report, sim, f, {"out": args.out, **focus, "propagation": sim.propagation_summary()}, phases)
    finish(args, {"out": args.out, "z_mm": f.z_mm, "surface_pressure_pa": f.surface_pressure_pa, **focus,
                   "propagation": sim.propagation, "seconds": time.perf_counter() - t})
    return 0
