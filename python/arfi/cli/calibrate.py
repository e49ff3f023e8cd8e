"""``arfi calibrate``: the broadening width and amplitude from a no-aberration image."""

from __future__ import annotations

import argparse
import time
from typing import Any

from arfi.cli.common import add_common, add_report, finish, load_scenario, read_image
from arfi.simulation import Simulation


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "calibrate",
        help="fit the broadening width and amplitude to a no-aberration image",
        description="Fit the Gaussian broadening width W and the force-to-phase amplitude (paper Eq. 2) "
        "to an MR-ARFI image taken with no aberration (known phases from its sidecar are honoured).",
        epilog="example: arfi calibrate --image calibration.nii.gz --json cal.json",
    )
    add_common(p)
    p.add_argument(
        "--image",
        required=True,
        metavar="C.nii.gz",
        help="the MR-ARFI image of the uncorrected focus in a medium without aberration (NIfTI, rad)",
    )
    p.add_argument(
        "--max-width-mm", type=float, default=10.0, dest="max_width_mm", help="largest W searched (default 10)"
    )
    add_report(p, "PNG figures (images in mm, colour bars in rad)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    t = time.perf_counter()
    scenario = load_scenario(args)
    image, known = read_image(scenario.outline(), args.image)  # before the simulation is built
    sim = Simulation(scenario)
    c = sim.calibrate(image, known, args.max_width_mm)
    if args.report:
        from arfi.reports.html import fit_report

        model = sim.calibrated(c).arfi_image(known)
        page = fit_report(args.report, sim, "calibrate", image, model, {"image": args.image, **c.to_dict()})
        print(f"calibrate: report -> {page}")
    print(
        f"calibrate: broadening width W = {c.broadening_width_mm:.3f} mm, amplitude {c.amplitude:.4e} rad·m³/N "
        f"({c.n_pixels} pixels, noise {c.noise_rad:.4f} rad)"
    )
    finish(
        args,
        {**c.to_dict(), "image": args.image, "seconds": time.perf_counter() - t},
    )
    return 0
