"""``arfi diagnose``: the model-discrepancy workflow."""

from __future__ import annotations

import argparse
import time
from typing import Any

from arfi.cli.common import (
    UsageError,
    add_calibration,
    add_common,
    add_report,
    calibrated_simulation,
    finish,
    load_scenario,
    read_checked_phases,
    read_image,
)


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "diagnose",
        help="find, name and add the effects the model is missing",
        description="Compare measured MR-ARFI image(s) with the model, fit every candidate effect of the "
        "library (amplitude, broadening, registration_shift, background_phase, slice_offset, broadening_anisotropic, "
        "attenuation, sound_speed, element_dropout, phase_aberration), add the best while its BIC evidence against the "
        "background noise is positive, and repeat until the residual is noise.",
        epilog="example: arfi diagnose --image measured.nii.gz --calibration cal.json --json diagnosis.json "
        "--report diagnosis/",
    )
    add_common(p)
    p.add_argument(
        "--image",
        required=True,
        action="append",
        metavar="M.nii.gz",
        help="measured image (repeat for several; each sidecar's applied_phases_rad are its known phases)",
    )
    add_calibration(p)
    p.add_argument(
        "--aberration",
        metavar="P",
        help="an aberration the model includes (.npy or text, per element or per group, the sign of phases_rad), "
        "e.g. a per-element estimate (arfi estimate --out-phases): it is added to every image's known phases, so what "
        "is named is what else the images differ in (the nuisance to fit with arfi estimate --fit-nuisance)",
    )
    p.add_argument("--threshold", type=float, default=0.0, help="evidence an effect needs (default 0: the plain BIC)")
    p.add_argument("--effects", metavar="A,B", help="comma-separated effects to try (default: the whole library)")
    add_report(p, "per-step PNG figures")
    p.add_argument(
        "--time-limit-s",
        type=float,
        dest="time_limit_s",
        help="stop after this many seconds and report the effects added so far",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from arfi.analysis.diagnose import EFFECTS
    from arfi.reports.diagnose import params_text, write_report

    t = time.perf_counter()
    effects = None
    if args.effects is not None:  # the names are checked by Simulation.diagnose
        effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        if not effects:
            raise UsageError(f"arfi diagnose: --effects: no effect named; known: {', '.join(EFFECTS)}")
    scenario = load_scenario(args)
    outline = scenario.outline()  # the inputs checked before the simulation is built
    aberration = read_checked_phases(outline, args.aberration, "--aberration")
    pairs = [read_image(outline, p) for p in args.image]
    sim = calibrated_simulation(args, scenario)
    images = [p[0] for p in pairs]
    known = [p[1] for p in pairs]
    if aberration is not None:
        added = sim.element_phases(aberration, "--aberration")
        known = [added if k is None else added + sim.element_phases(k) for k in known]
    d = sim.diagnose(images, known, threshold=args.threshold, effects=effects, time_limit_s=args.time_limit_s)
    for k, e in enumerate(d.effects, 1):
        same = f"; explained as well by {', '.join(e.equivalent)}" if e.equivalent else ""
        print(
            f"diagnose: {k}. {e.name} ({params_text(e.params)}): cost {e.cost_before:.4g} -> {e.cost_after:.4g}, "
            f"evidence {e.evidence:.1f}{same}"
        )
    if not d.effects:
        print("diagnose: no effect missing: the residual is consistent with the noise")
    failed = [c for c in [*d.rejected, *(c for e in d.effects for c in e.candidates)] if c.failure]
    for c in {c.name: c for c in failed}.values():
        print(f"diagnose: {c.name} could not be fitted: {c.failure}")
    if d.alternative and d.total_evidence - d.alternative.total_evidence < 10:
        print(
            f"diagnose: the data explain about as well by {', '.join(d.alternative.effects)} (total evidence "
            f"{d.alternative.total_evidence:.1f} against {d.total_evidence:.1f}); images with known diversity phases "
            "tell them apart"
        )
    if d.stop == "time limit":
        print(
            f"diagnose: stopped at the time limit ({args.time_limit_s:g} s) after {len(d.effects)} effect(s); more may "
            "be missing"
        )
    print(
        f"diagnose: residual RMS {d.residual_rms_initial:.4f} -> {d.residual_rms_final:.4f} rad, noise floor "
        f"{d.noise_floor:.4f} rad"
    )
    if args.report:
        print(f"diagnose: report -> {write_report(d, sim, images, args.report)}")
    finish(args, {**d.to_dict(), "images": args.image, "seconds": time.perf_counter() - t})
    return 0
