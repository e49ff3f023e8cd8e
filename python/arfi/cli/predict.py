"""``arfi predict``: the CT-based prediction of each element's aberration, the prior of ``arfi estimate``."""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from arfi.analysis.focal import metrics_text
from arfi.analysis.prediction import compared_section, drive_labels, focal_metrics, predict, predict_targets
from arfi.cli.common import UsageError, add_common, add_report, finish, load_scenario, npy_path, save_npy
from arfi.io.files import read_targets
from arfi.progress import callback


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "predict",
        help="per-element aberration of the CT's skull at the focus (.npy, the prior of arfi estimate)",
        description="Predict what the skull of the scenario's CT ([ct]) does to each element's wave at the focus, by "
        "reciprocity: one march from the focus back to the array through the head, and one through the same head with "
        "its bone read as soft tissue (the reference the estimation's model assumes). Writes the predicted phase per "
        "element (rad) in the sign of arfi estimate's phases_rad: subtracting it from the reference steering corrects, "
        "and it is the --prior of arfi estimate. --json adds each element's transmission and the focal pressures "
        "(reference, uncorrected, straight-ray CT steering, corrected, and the most any phases give), and the focal "
        "metrics in 3-D of the uncorrected, straight-ray and corrected beams (see --focal-metrics).",
        epilog="example: arfi predict --scenario head.toml --out prior.npy --json prediction.json",
    )
    add_common(p)
    p.add_argument("--out", required=True, metavar="P.npy", help="predicted phases (rad), one per element")
    p.add_argument(
        "--target-mm",
        type=float,
        nargs=3,
        dest="target_mm",
        metavar=("X", "Y", "Z"),
        help="point to predict for, transducer frame (default: the focus)",
    )
    p.add_argument(
        "--targets",
        metavar="FILE.csv",
        help="predict for every point of a CSV file (a header naming x_mm, y_mm, z_mm, transducer frame; one row "
        "per target) from one plan of each head: the plans are built once, each further target costs its marches. "
        "--out then holds one row of phases per target (targets x elements), the --json a list under targets, each "
        "entry the keys of a single prediction; a target outside the grid or the CT is refused by its index (from 0, "
        "header not counted) and position before anything is built. Not with --target-mm or --report",
    )
    p.add_argument(
        "--bone-speed-sensitivity",
        action=argparse.BooleanOptionalAction,
        default=None,
        dest="bone_speed_sensitivity",
        help="also give how the predicted phases move per percent of the CT conversion's bone sound speed "
        "(rad/%%, per element, in the --json as bone_speed_sensitivity_rad_per_percent): the mode arfi "
        "estimate fits to the images on the head with the CT's bone before its per-element fit. One more "
        "simulation of the skull (about half the prediction's time). Default: on with the porosity conversion "
        '("aubry2003", the default), which has the constant, whether or not --json is given (what is printed does '
        "not depend on the files asked for); --no-bone-speed-sensitivity skips it",
    )
    p.add_argument(
        "--pose-sensitivity",
        action=argparse.BooleanOptionalAction,
        default=False,
        dest="pose_sensitivity",
        help="also give how the predicted phases move per mm that the head lies shifted along x, y, z and per "
        "degree that it lies turned about x, y, z through the target, off where the CT is registered (rad per mm or "
        "degree, per element, in the --json as pose_sensitivity_rad_per_mm and pose_sensitivity_rad_per_deg, rows x, "
        "y, z): the registration modes arfi estimate fits to the images with the bone speed before its per-element "
        "fit. The moved head is the registered one seen by the array moved the other way: six more transposed marches "
        "through the skull, side by side, no plan, about two thirds more time than the prediction alone. For a "
        "hemisphere or a bowl of elements (a planar array's elements lie in the source plane, a single bowl has one "
        "element). Off by default: on the head phantom three images do not determine a 1.5-2 mm registration error "
        "from these modes",
    )
    p.add_argument(
        "--focal-metrics",
        action=argparse.BooleanOptionalAction,
        default=None,
        dest="focal_metrics",
        help="also march the uncorrected, straight-ray CT steering and corrected beams through the skull "
        "and give each one's focal metrics in 3-D around the target: the focal peak and its distance from the target, "
        "the -6 dB extents and volume, I_SPPA and MI in the tissue it lies in (printed, and in the --json as "
        "focal_metrics with the keys of arfi field's JSON). Three marches of the skull's simulation to the focal box, "
        "kept until they are done (with --report, the report's own march gives them). Default: on; "
        "--no-focal-metrics skips them",
    )
    add_report(
        p,
        "PNG figures (the beam through the skull on the x-z section through the target, uncorrected, with straight-ray "
        "CT steering and corrected, over the sound speed; element maps of the predicted phase and transmission; one "
        "batch march of the three beams through the prediction's own simulation of the skull, kept for the report, "
        "which also gives their focal metrics)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    npy_path(args.out, "--out")  # before the simulation
    targets = None
    if args.targets is not None:
        if args.target_mm is not None or args.report:
            raise UsageError(f"--targets: not with {'--target-mm' if args.target_mm is not None else '--report'}")
        try:
            targets = read_targets(args.targets)
        except (ValueError, OSError) as e:
            raise UsageError(f"--targets: {e}") from None
    scenario = load_scenario(args)
    if scenario.to_dict().get("ct") is None:
        raise UsageError(
            "--scenario: a prediction needs a CT of the head ([ct] in the scenario); arfi phantom writes a synthetic "
            "one"
        )
    # The defaults do not depend on whether a file is asked for: the same command prints the same.
    sensitivity = args.bone_speed_sensitivity
    if sensitivity is None:  # where the conversion has the constant the sensitivity is taken along
        sensitivity = scenario.to_dict()["ct"].get("conversion", "aubry2003") == "aubry2003"
    metrics_wanted = True if args.focal_metrics is None else args.focal_metrics
    if targets is not None:
        return run_targets(args, scenario, targets, sensitivity, metrics_wanted)
    t = time.perf_counter()
    # The focal metrics and the report march the beams through the skull: the prediction keeps the
    # skull's simulation for them.
    p = predict(
        scenario,
        args.target_mm,
        bone_speed_sensitivity=sensitivity,
        keep_simulation=bool(args.report) or metrics_wanted,
        pose_sensitivity=args.pose_sensitivity,
    )
    seconds = time.perf_counter() - t
    # One batch march of the three drives draws the report's section and gives their focal
    # metrics; without a report, the metrics alone march each drive only to its focal box.
    section, metrics = compared_section(p) if args.report else (None, focal_metrics(p) if metrics_wanted else None)
    metrics = metrics if metrics_wanted else None
    metrics_seconds = time.perf_counter() - t - seconds
    save_npy(args.out, p.phases_rad)
    x, y, z = p.target_mm
    labels = drive_labels(scenario)
    steering = (
        f"{p.ray_steering_pa / 1e6:.3f} MPa with straight-ray CT steering"
        if labels["ray_steering"] == "straight-ray CT steering"
        else "the same with the scenario's straight-ray steering (it leaves the bone out: [ct] steer_without_bone)"
    )
    print(
        f"predict: {len(p.phases_rad)} elements at ({x:.1f}, {y:.1f}, {z:.1f}) mm: phases span "
        f"{p.phases_rad.max() - p.phases_rad.min():.2f} rad, transmission {p.transmission.mean():.2f} mean -> "
        f"{args.out}\npredict: focal |p| {p.uncorrected_pa / 1e6:.3f} MPa uncorrected, {steering}, "
        f"{p.corrected_pa / 1e6:.3f} MPa corrected (the most any phases give: "
        f"{p.optimal_pa / 1e6:.3f} MPa; {p.reference_pa / 1e6:.3f} MPa without the skull, "
        f"{p.reference_pa / p.reference_optimal_pa:.2f} of what that head allows) in {seconds:.1f} s"
    )
    if p.bone_speed_sensitivity_rad_per_percent is not None:
        g = p.bone_speed_sensitivity_rad_per_percent
        print(
            f"predict: bone speed sensitivity {np.sqrt(np.mean(g**2)):.3f} rad RMS per percent of bone sound speed "
            f"({np.abs(g).max():.3f} at most)"
        )
    if p.pose_sensitivity_rad_per_mm is not None and p.pose_sensitivity_rad_per_deg is not None:
        rms = lambda rows: ", ".join(f"{np.sqrt(np.mean(r**2)):.3f}" for r in rows)  # noqa: E731
        print(
            "predict: registration sensitivity, rad RMS per mm of the head's shift along x, y, z: "
            f"{rms(p.pose_sensitivity_rad_per_mm)}; per degree of its turn about x, y, z through the target: "
            f"{rms(p.pose_sensitivity_rad_per_deg)}"
        )
    for name, m in (metrics or {}).items():
        print(f"predict: {labels[name]}: {metrics_text(m)}")
    result = p.to_dict()
    if metrics is not None:
        result["focal_metrics"] = {name: m.to_dict() for name, m in metrics.items()}
        result["focal_metrics_seconds"] = metrics_seconds
    if args.report:
        from arfi.reports.html import predict_report

        page = predict_report(
            args.report,
            p,
            {
                "out": args.out,
                "target_mm": p.target_mm,
                "elements": len(p.phases_rad),
                "seconds": seconds,
                **{f"focal |p| {k} (Pa)": v for k, v in result["focal_pressure_pa"].items()},
                **{f"{labels[k]}: focal metrics": metrics_text(m) for k, m in (metrics or {}).items()},
            },
            section,
            labels,
        )
        print(f"predict: report -> {page}")
    finish(args, {"out": args.out, **result, "seconds": seconds})
    return 0


def run_targets(
    args: argparse.Namespace, scenario: Any, targets: list[tuple[float, float, float]], sensitivity: bool, metrics: bool
) -> int:
    """``arfi predict --targets``: every target's prediction from one plan of each head, a row of
    phases per target, a line per target."""
    try:
        t = time.perf_counter()
        predictions = predict_targets(
            scenario,
            targets,
            bone_speed_sensitivity=sensitivity,
            keep_simulation=metrics,
            pose_sensitivity=args.pose_sensitivity,
            progress=callback(True, "predict: transposed marches", "marches"),
        )
        seconds = time.perf_counter() - t
    except ValueError as e:
        # The core names its parameter targets; the user gave them as --targets.
        text = str(e)
        raise UsageError(f"--targets: {text.split(': ', 1)[1]}" if text.startswith("targets:") else text) from None
    found = [focal_metrics(p) for p in predictions] if metrics else None
    metrics_seconds = time.perf_counter() - t - seconds
    save_npy(args.out, np.stack([p.phases_rad for p in predictions]))
    labels = drive_labels(scenario)
    print(
        f"predict: {len(predictions)} targets, {len(predictions[0].phases_rad)} elements, one plan of each head, in "
        f"{seconds:.1f} s -> {args.out} (a row of phases per target); focal |p| (MPa) uncorrected, "
        f"{labels['ray_steering']}, corrected, the most any phases give; mean transmission:"
    )
    entries = []
    for k, p in enumerate(predictions):
        x, y, z = p.target_mm
        print(
            f"predict: target {k} ({x:.1f}, {y:.1f}, {z:.1f}) mm: {p.uncorrected_pa / 1e6:.3f}, "
            f"{p.ray_steering_pa / 1e6:.3f}, {p.corrected_pa / 1e6:.3f}, {p.optimal_pa / 1e6:.3f}; "
            f"{p.transmission.mean():.2f}"
        )
        entry = p.to_dict()
        if found is not None:
            print(f"predict: target {k}: corrected: {metrics_text(found[k]['corrected'])}")
            entry["focal_metrics"] = {name: m.to_dict() for name, m in found[k].items()}
        entries.append(entry)
    result: dict[str, Any] = {"out": args.out, "targets": entries, "seconds": seconds}
    if found is not None:
        result["focal_metrics_seconds"] = metrics_seconds
    finish(args, result)
    return 0
