"""``arfi predict``: the CT-based prediction of each element's aberration, the prior of ``arfi estimate``."""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from arfi.cli.common import UsageError, add_common, add_report, finish, load_scenario, npy_path, save_npy
from arfi.prediction import predict


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "predict", help="per-element aberration of the CT's skull at the focus (.npy, the prior of arfi estimate)",
        description="Predict what the skull of the scenario's CT ([ct]) does to each element's wave at the focus, by "
        "reciprocity: one march from the focus back to the array through the head, and one through the same head with "
        "its bone read as soft tissue (the reference the estimation's model assumes). Writes the predicted phase per "
        "element (rad) in the sign of arfi estimate's phases_rad: subtracting it from the reference steering corrects, "
        "and it is the --prior of arfi estimate. --json adds each element's transmission and the focal pressures "
        "(reference, uncorrected, straight-ray CT steering, corrected, and the most any phases give).",
        epilog="example: arfi predict --scenario head.toml --out prior.npy --json prediction.json")
    add_common(p)
    p.add_argument("--out", required=True, metavar="P.npy", help="predicted phases (rad), one per element")
    p.add_argument("--target-mm", type=float, nargs=3, dest="target_mm", metavar=("X", "Y", "Z"),
                   help="point to predict for, transducer frame (default: the focus)")
    p.add_argument("--bone-speed-sensitivity", action=argparse.BooleanOptionalAction, default=None,
                   dest="bone_speed_sensitivity",
                   help="also give how the predicted phases move per percent of the CT conversion's bone sound speed "
                        "(rad/%%, per element, in the --json as bone_speed_sensitivity_rad_per_percent): the mode arfi "
                        "estimate fits to the images on the head with the CT's bone before its per-element fit. One more "
                        "simulation of the skull (about half the prediction's time). Default: on with --json and the "
                        "porosity conversion (\"aubry2003\", the default), which has the constant; --no-bone-speed-sensitivity "
                        "skips it")
    add_report(p, "PNG figures (the beam through the skull on the x-z section through the target, uncorrected, "
                  "with straight-ray CT steering and corrected, over the sound speed; element maps of the predicted "
                  "phase and transmission; two more marches of the prediction's own simulation of the skull, kept for the report)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    npy_path(args.out, "--out")  # before the simulation
    scenario = load_scenario(args)
    if scenario.to_dict().get("ct") is None:
        raise UsageError("--scenario: a prediction needs a CT of the head ([ct] in the scenario); "
                         "arfi phantom writes a synthetic one")
    sensitivity = args.bone_speed_sensitivity
    if sensitivity is None:  # by default for the JSON (what arfi estimate reads), where the conversion has the constant
        sensitivity = args.json is not None and scenario.to_dict()["ct"].get("conversion", "aubry2003") == "aubry2003"
    t = time.perf_counter()
    # The report draws the beam through the skull: the prediction keeps the skull's simulation for it.
    p = predict(scenario, args.target_mm, bone_speed_sensitivity=sensitivity,
                keep_simulation=bool(args.report))
    seconds = time.perf_counter() - t
    save_npy(args.out, p.phases_rad)
    x, y, z = p.target_mm
    print(
        f"predict: {len(p.phases_rad)} elements at ({x:.1f}, {y:.1f}, {z:.1f}) mm: phases span "
        f"{p.phases_rad.max() - p.phases_rad.min():.2f} rad, transmission {p.transmission.mean():.2f} mean -> {args.out}\n"
        f"predict: focal |p| {p.uncorrected_pa / 1e6:.3f} MPa uncorrected, {p.ray_steering_pa / 1e6:.3f} MPa with straight-ray "
        f"CT steering, {p.corrected_pa / 1e6:.3f} MPa corrected (the most any phases give: {p.optimal_pa / 1e6:.3f} MPa; "
        f"{p.reference_pa / 1e6:.3f} MPa without the skull, {p.reference_pa / p.reference_optimal_pa:.2f} of what that head "
        f"allows) in {seconds:.1f} s"
    )
    if p.bone_speed_sensitivity_rad_per_percent is not None:
        g = p.bone_speed_sensitivity_rad_per_percent
        print(f"predict: bone speed sensitivity {np.sqrt(np.mean(g**2)):.3f} rad RMS per percent of bone sound speed "
              f"({np.abs(g).max():.3f} at most)")
    result = p.to_dict()
    if args.report:
        from arfi.report import predict_report

        predict_report(args.report, p, {"out": args.out, "target_mm": p.target_mm, "elements": len(p.phases_rad),
                                        "seconds": seconds,
                                        **{f"focal |p| {k} (Pa)": v for k, v in result["focal_pressure_pa"].items()}})
    finish(args, {"out": args.out, **result, "seconds": seconds})
    return 0
