"""``arfi simulate``: a simulated MR-ARFI image (NIfTI with a JSON sidecar)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from arfi.cli.common import (
    UsageError,
    add_common,
    add_report,
    finish,
    image_peak,
    load_scenario,
    prediction_json,
    read_checked_phases,
)
from arfi.io.files import arfi_image_path, write_arfi_image
from arfi.simulation import Simulation


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "simulate",
        help="simulated MR-ARFI image (NIfTI)",
        description="Simulate an MR-ARFI phase image (rad) for phases added to the steering and "
        "write it as NIfTI with a JSON sidecar.",
        epilog="example: arfi simulate --phases aberration.npy --noise-rad 0.02 --seed 1 --out aberrated.nii.gz",
    )
    add_common(p)
    p.add_argument(
        "--phases", metavar="P", help="unknown aberration (rad) added to the steering (not recorded in the sidecar)"
    )
    p.add_argument(
        "--known-phases",
        metavar="P",
        dest="known_phases",
        help="known diversity phases (rad) added to the steering and recorded as applied_phases_rad in the sidecar",
    )
    p.add_argument(
        "--focus-shift-mm",
        type=float,
        nargs=3,
        dest="focus_shift_mm",
        metavar=("DX", "DY", "DZ"),
        help="known diversity phases that move the focus by (DX, DY, DZ) mm, e.g. 0 0 5 for a defocused image "
        "(more informative than random group phases for per-element estimates); added to --known-phases and recorded "
        "with them, per element, as applied_phases_rad",
    )
    p.add_argument(
        "--steering-from",
        dest="steering_from",
        metavar="PREDICTION.json",
        help="drive the elements with the reference steering of arfi predict's JSON (reference_steering_rad) "
        "instead of the scenario's own steering (not recorded in the sidecar): a patient whose head lies off the CT's "
        "registration, or whose bone the CT gets wrong, is driven as the clinic computes it from the CT, not from "
        "where the head really is. The JSON's target_mm must lie within 0.5 mm of the focus",
    )
    p.add_argument(
        "--noise-rad",
        type=float,
        dest="noise_rad",
        help="Gaussian noise sigma (rad; default: the scenario's noise_rad)",
    )
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument(
        "--out",
        required=True,
        metavar="M.nii.gz",
        help="the simulated MR-ARFI image (.nii or .nii.gz) and its JSON sidecar beside it",
    )
    add_report(p, "PNG figures (images in mm, colour bars in rad, element maps)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = args.out
    arfi_image_path(out)  # before the simulation
    t = time.perf_counter()
    steering_json = read_steering(args.steering_from) if args.steering_from else None  # before the simulation
    scenario = load_scenario(args)
    outline = scenario.outline()  # the inputs checked before the simulation is built
    aberration = read_checked_phases(outline, args.phases, "--phases")
    known = read_checked_phases(outline, args.known_phases, "--known-phases")
    sim = Simulation(scenario)
    if args.focus_shift_mm is not None:
        shift = sim.focus_shift_phases(args.focus_shift_mm, "--focus-shift-mm")
        known = shift if known is None else sim.element_phases(known, "--known-phases") + shift
    if steering_json is not None:
        steering = clinic_steering(args.steering_from, steering_json, sim)
        aberration = steering if aberration is None else sim.element_phases(aberration, "--phases") + steering
    total = None
    for p in (aberration, known):
        if p is not None:
            full = sim.element_phases(p, "--phases" if p is aberration else "--known-phases")
            total = full if total is None else total + full
    noise = sim.noise_rad if args.noise_rad is None else args.noise_rad
    image = sim.arfi_image(total, noise, args.seed)
    sidecar: dict[str, Any] = {"arfi_simulated": {"scenario": sim.scenario.name, "noise_rad": noise, "seed": args.seed}}
    if known is not None:
        sidecar["applied_phases_rad"] = known
    write_arfi_image(out, image, sim.mr_affine_mm, sim.mr_volume_shape, sidecar)
    peak, pos = image_peak(sim, image)
    if args.report:
        from arfi.reports.html import image_report

        page = image_report(
            args.report,
            sim,
            "simulate",
            image,
            {"out": out, "focal_arfi_rad": peak, "noise_rad": noise, "seed": args.seed},
            total,
        )
        print(f"simulate: report -> {page}")
    print(
        f"simulate: {image.shape[0]} x {image.shape[1]} MR-ARFI image, focal ARFI phase {peak:.3f} rad at "
        f"({pos[0]:.1f}, {pos[1]:.1f}, {pos[2]:.1f}) mm, noise {noise:g} rad -> {out}"
    )
    finish(
        args,
        {
            "out": out,
            "focal_arfi_rad": peak,
            "focal_position_mm": pos,
            "noise_rad": noise,
            "seed": args.seed,
            "amplitude": sim.amplitude,
            "seconds": time.perf_counter() - t,
        },
    )
    return 0


def read_steering(path: str) -> tuple[np.ndarray, np.ndarray]:
    """The reference steering (rad) and target (mm) of the prediction JSON at ``path``
    (``--steering-from``), checked to be finite numbers."""
    p = Path(path)
    d = prediction_json(path, "--steering-from")
    try:
        steering = np.asarray(d["reference_steering_rad"], dtype=np.float64)
        target = np.asarray(d["target_mm"], dtype=np.float64)
    except (ValueError, KeyError, TypeError) as e:
        raise UsageError(
            f"--steering-from: {p}: not the JSON of arfi predict (no 'reference_steering_rad' and 'target_mm': {e})"
        ) from None
    if (
        steering.ndim != 1
        or not np.all(np.isfinite(steering))
        or target.shape != (3,)
        or not np.all(np.isfinite(target))
    ):
        raise UsageError(f"--steering-from: {p}: 'reference_steering_rad' and 'target_mm' must be finite numbers")
    return steering, target


def clinic_steering(path: str, steering_json: tuple[np.ndarray, np.ndarray], sim: Simulation) -> np.ndarray:
    """The phases that turn ``sim``'s own steering into the reference steering of the prediction
    JSON at ``path`` (``--steering-from``), per element."""
    steering, target = steering_json
    if steering.shape != (sim.n_elements,):
        raise UsageError(f"--steering-from: {path}: 'reference_steering_rad' must hold {sim.n_elements} values")
    if not np.linalg.norm(target - sim.focus_mm) <= 0.5:
        raise UsageError(
            f"--steering-from: {path}: predicted for {target.tolist()} mm, but the scenario focuses at "
            f"{np.round(sim.focus_mm, 1).tolist()} mm"
        )
    return steering - sim.steering_phases_rad
