"""``arfi estimate``: hybrid estimation of the phase aberration."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from arfi.analysis import prior_modes
from arfi.analysis.prediction_estimate import estimate_with_prediction
from arfi.cli.common import (
    UsageError,
    add_calibration,
    add_common,
    add_method,
    add_report,
    estimate_options,
    finish,
    load_scenario,
    npy_path,
    prediction_json,
    read_calibration,
    read_image,
    read_optional_phases,
    save_npy,
)
from arfi.io.files import read_phases


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "estimate",
        help="hybrid estimation of the phase aberration",
        description="Estimate the per-group phase aberration whose simulated MR-ARFI image(s) match the "
        "measured one(s). Several --image options make a joint fit; each image's sidecar may hold the known phases "
        "added for it (applied_phases_rad). Subtract the estimate to correct.",
        epilog="example: arfi estimate --image aberrated.nii.gz --calibration cal.json --groups 16 "
        "--method lbfgs --json estimate.json",
    )
    add_common(p)
    p.add_argument(
        "--image",
        required=True,
        action="append",
        metavar="M.nii.gz",
        help="a measured MR-ARFI image (NIfTI, rad, with its JSON sidecar); repeat for a joint fit of several",
    )
    add_calibration(p)
    p.add_argument(
        "--groups",
        type=int,
        default=16,
        help="number of contiguous element groups (default 16); the scenario's number of elements estimates "
        "one phase per element on the element field basis (lbfgs only): one march per element through soft tissue and "
        "water, on a grid of 3/8 of the shortest wavelength and at most 3/4 of an MR pixel (its images agree with "
        "those of the scenario's own grid within 1.5 %% of their peak at 550-650 kHz)",
    )
    add_method(
        p,
        "lbfgs",
        "nelder-mead: the paper's (zero start, <= 8000 evaluations); pso; lbfgs: gradient multi-start (default)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seeds the random starts (lbfgs) and the swarm (pso): the same seed, the same estimate (default 0)",
    )
    p.add_argument(
        "--noise-rad",
        type=float,
        dest="noise_rad",
        metavar="S",
        help="the images' noise standard deviation (rad) where it is known, e.g. the standard deviation of "
        "the difference of two reference acquisitions over sqrt(2); default: each image's floor from its background, "
        "which counts any pixel-scale structure there as noise (through a head at 650 kHz 0.024-0.025 rad for a noise "
        "of 0.02, enough to hide a model mismatch). The misfit, MODEL MISMATCH, PRIOR CONFLICT, the prior's weight and "
        "the fit of the prediction's modes all use it",
    )
    p.add_argument(
        "--max-evaluations",
        type=int,
        dest="max_evaluations",
        help="evaluation limit (defaults: nelder-mead/pso 8000, lbfgs 40000 over all starts, per element 200, "
        "or 120 when --fit-nuisance fits W or the shift)",
    )
    p.add_argument(
        "--time-limit-s",
        type=float,
        dest="time_limit_s",
        metavar="S",
        help="stop the search after S seconds and report the best phases found (default: no limit)",
    )
    p.add_argument("--starts", type=int, help="L-BFGS random starts (default 20)")
    p.add_argument(
        "--fit-amplitude",
        action="store_true",
        dest="fit_amplitude",
        help="fit a free amplitude scale too (absorbs a uniform focal loss)",
    )
    p.add_argument(
        "--fit-nuisance",
        dest="fit_nuisance",
        metavar="NAMES",
        help="per-element estimates: also fit what the images differ in from the model (comma-separated, "
        "names as arfi diagnose reports them, or 'all'): amplitude, background_phase (per image an offset and a ramp), "
        "broadening (W), registration_shift (trades with a steering tilt of the phases: prefer registering on a "
        "calibration image)",
    )
    p.add_argument(
        "--prior",
        metavar="P",
        help="predicted aberration (.npy or text, one value per line; per element or per "
        "group, the sign of phases_rad: subtracting it corrects), e.g. from a CT-based skull simulation; the estimate "
        "is then the posterior optimum",
    )
    p.add_argument(
        "--prior-std-rad",
        type=float,
        dest="prior_std_rad",
        metavar="S",
        help="expected error of each predicted phase (rad); required with --prior",
    )
    p.add_argument(
        "--prior-correlation-mm",
        type=float,
        dest="prior_correlation_mm",
        metavar="L",
        help="the prediction's errors are a smooth field correlated over L mm (per-element estimates then "
        "correct the prediction by smooth fields only; default: independent errors)",
    )
    p.add_argument(
        "--prior-conflict-z",
        type=float,
        metavar="Z",
        help="per element with --prior: the images conflict with the prediction, which is then recommended (a "
        "PRIOR CONFLICT line), when their chi-squared at it lies more than Z standard deviations above what truths "
        "within --prior-std-rad give (default 3)",
    )
    p.add_argument(
        "--prior-transmission",
        dest="prior_transmission",
        metavar="T",
        help="each element's predicted transmission through the skull: the JSON of arfi predict (its "
        "'transmission'), or .npy or text with one value per element. The model then drives each element at its "
        "transmission relative to the mean, so that a model of the head without its skull weighs the elements as the "
        "skull does (the skull's overall loss is the amplitude scale's: --fit-nuisance amplitude). "
        "The JSON's 'target_mm' must lie within 0.5 mm of the scenario's focus. For a per-element estimate with "
        "--prior, the JSON also turns on the fit of the prediction's bone-speed mode before the estimate (a second "
        "model, of the head with its bone, built and marched; announced when it starts; "
        "--prior-bone-speed-std-percent=0 leaves it out)",
    )
    p.add_argument(
        "--prior-bone-speed-std-percent",
        type=float,
        dest="prior_bone_speed_std_percent",
        metavar="P",
        help="the CT conversion's bone sound speed may be off by about P percent (default 20 where the "
        "--prior-transmission JSON of arfi predict holds bone_speed_sensitivity_rad_per_percent; 0: off). Fitted "
        "before the per-element fit on the head with the CT's bone, with the other modes asked for (see "
        "--prior-pose-std-mm); the prior moves along the mode where the images support it",
    )
    p.add_argument(
        "--prior-pose-std-mm",
        type=float,
        dest="prior_pose_std_mm",
        metavar="S",
        help="also fit the registration: the head may lie shifted by about S mm along each axis from where the "
        "CT is registered (e.g. 1.5; needs the --prior-transmission JSON of arfi predict with "
        "pose_sensitivity_rad_per_mm, its default). Before the per-element fit, the images fit the prediction's modes "
        "jointly (the bone speed, these shifts, --prior-pose-std-deg's turns, --prior-modes) on the head with the CT's "
        "bone, driven with the reference steering, the phases otherwise the prediction's (Gauss-Newton: one batch "
        "march of each image and its derivative drives per iteration); the prior then moves along the modes by the "
        "fitted values, printed with their uncertainty, where the images support it (their chi-squared falls by more "
        "than the 95 %% point of noise alone). Off by default: on the head phantom three images do not determine a "
        "1.5-2 mm registration error (docs/head.md), and each mode costs one march per image per iteration. Needs "
        "--prior, a [ct] scenario and one phase per element",
    )
    p.add_argument(
        "--prior-pose-std-deg",
        type=float,
        dest="prior_pose_std_deg",
        metavar="A",
        help="also fit the registration's turns: the head may lie turned by about A degrees about each axis "
        "through the target (e.g. 1.5; needs pose_sensitivity_rad_per_deg in the JSON); see --prior-pose-std-mm",
    )
    p.add_argument(
        "--prior-modes",
        dest="prior_modes",
        metavar="M.npz",
        help="more error modes of the prediction to fit with its own: a NumPy .npz with 'modes' (M x elements, "
        "rad per element for one unit of each mode), 'std' (M prior standard deviations, in those units) and "
        "optionally 'names' and 'units' (M strings each)",
    )
    p.add_argument(
        "--out-phases",
        dest="out_phases",
        metavar="F.npy",
        help="write the phases to subtract, those JSON 'recommended' names: the estimate; when an estimate "
        "with --prior ends in MODEL MISMATCH (the images are not explained) or PRIOR CONFLICT (per element: the images "
        "at the prediction lie far outside what truths within --prior-std-rad give), the prediction itself, moved "
        "along its fitted modes (registration, bone speed) when they were fitted; per element without --prior, when "
        "the images do not support the estimate (they determine too few combinations of phases for its correction to "
        "beat none or the group fit) or its search did not converge, zeros (uncorrected) or the group fit on its "
        "elements",
    )
    p.add_argument(
        "--suggest",
        metavar="F.npy",
        help="write the suggested diversity phases for the next acquisition (per "
        "element: the known per-element phases of the focus shift whose image is expected to raise the corrected focus "
        "most, one linearised posterior per candidate shift; image it with arfi simulate --focus-shift-mm or on the "
        "scanner)",
    )
    add_report(p, "PNG figures (images in mm, colour bars in rad, element maps)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    for path, option in ((args.out_phases, "--out-phases"), (args.suggest, "--suggest")):
        if path:
            npy_path(path, option)  # before the estimate, so that neither is written when one is wrong
    t = time.perf_counter()
    scenario = load_scenario(args)
    # Every input checked against the scenario before any model is built (a build through a
    # head takes tens of seconds and gigabytes).
    outline = scenario.outline()
    prior = read_optional_phases(args.prior, "--prior")
    options = estimate_options(
        method=args.method,
        max_evaluations=args.max_evaluations,
        time_limit_s=args.time_limit_s,
        seed=args.seed,
        starts=args.starts,
        fit_amplitude=args.fit_amplitude,
        noise_rad=args.noise_rad,
        prior=prior,
        prior_std_rad=args.prior_std_rad,
        prior_correlation_mm=args.prior_correlation_mm,
        prior_conflict_z=args.prior_conflict_z,
        fit_nuisance=args.fit_nuisance,
        suggest=bool(args.suggest),
    )
    path = args.prior_transmission
    prediction, transmission = None, None
    if path and path.endswith(".json"):
        prediction = prediction_json(path, "--prior-transmission")
    elif path:
        transmission = read_phases(path, "--prior-transmission")
    user_modes = []
    if args.prior_modes:
        try:
            user_modes = prior_modes.read_modes(args.prior_modes, outline.n_elements)
        except (FileNotFoundError, ValueError) as err:
            raise UsageError(f"--prior-modes: {err}") from None
    calibration = read_calibration(args)
    pairs = [read_image(outline, p, args.groups) for p in args.image]
    r = estimate_with_prediction(
        scenario,
        [p[0] for p in pairs],
        [p[1] for p in pairs],
        options,
        prediction=prediction,
        transmission=transmission,
        calibration=calibration,
        groups=args.groups,
        bone_speed_std_percent=args.prior_bone_speed_std_percent,
        pose_std_mm=args.prior_pose_std_mm,
        pose_std_deg=args.prior_pose_std_deg,
        modes=user_modes,
        log=lambda line: print(f"estimate: {line}", flush=True),
        progress=sys.stderr.isatty(),
        names={
            "prediction": (
                f"--prior-transmission: {path}"
                if prediction is not None
                else "--prior-transmission with the JSON of arfi predict"
            ),
            "transmission": f"--prior-transmission: {path}",
            "calibration": f"--calibration: {args.calibration}",
            "images": "--image",
            "known": "applied_phases_rad of --image",
            "pose_sensitivity": "arfi predict --pose-sensitivity",
            "groups": "--groups",
            "bone_speed_std_percent": "--prior-bone-speed-std-percent",
            "pose_std_mm": "--prior-pose-std-mm",
            "pose_std_deg": "--prior-pose-std-deg",
            "modes": "--prior-modes",
            "prior": f"--prior: {args.prior}" if args.prior else "--prior",
        },
    )
    e, sim, moved = r.estimate, r.simulation, r.prior_moved
    total = time.perf_counter() - t
    kind = "element" if len(e.phases_rad) == sim.n_elements else "group"
    print(
        f"estimate: {len(e.phases_rad)} {kind} phases by {e.method} from {len(pairs)} image(s): cost {e.cost:.4g} "
        f"({e.n_pixels} pixels, noise {'given ' if args.noise_rad is not None else 'floor '}{e.noise_floor:.4f} rad), "
        f"{e.evaluations} evaluations in {e.seconds:.2f} s ({e.stop})"
        + (
            f"; with the prior (+-{args.prior_std_rad:g} rad per phase"
            + (f", errors correlated over {args.prior_correlation_mm:g} mm" if args.prior_correlation_mm else "")
            + "), ambiguity judged on the posterior"
            if e.prior_used
            else ""
        )
        + f"; recommended: {e.recommended}"
    )
    if e.nuisance is not None:
        n = e.nuisance
        # Fitted though not asked for: the library's refit of a smooth prior's mismatched estimate.
        refit = "amplitude" in n.fitted and not (options.fit_amplitude or "amplitude" in options.fit_nuisance)
        offsets = ", ".join(f"{b:+.3f}" for b in n.offset_rad)
        print(
            f"estimate: fitted {', '.join(n.fitted)}: amplitude scale {n.scale:.3f}, W {n.broadening_width_mm:.2f} mm, "
            f"shift ({n.dx_mm:+.2f}, {n.dy_mm:+.2f}) mm, background offsets {offsets} rad; misfit {e.misfit:.2f} x the "
            "noise expectation"
            + (
                " (the amplitude was not asked for: with the scale held at 1 the model could not explain the images, "
                "as the prediction's element-level error, which smooth corrections leave, lowers them)"
                if refit
                else ""
            )
        )
    if e.kept_prediction:
        print(
            "estimate: KEPT THE PREDICTION: one acquisition cannot check a per-element correction of a prediction "
            "(one that fits the image better than the truth can leave less focus than the prediction); add an image "
            "with other known phases, e.g. a defocus (--suggest), and estimate from both. The prediction leaves a "
            f"misfit of {e.misfit:.2f} x the noise expectation on this image"
            + (" (well above 1: the prediction, or the model, misses what the image shows)." if e.misfit > 1.2 else ".")
        )
    if not e.converged:
        print(
            f"estimate: NOT CONVERGED: the search stopped at its {e.stop} ({e.evaluations} evaluations) before it "
            "converged: the phases are where it stopped, not a minimum"
            + (
                "; not recommended (see below)."
                if e.recommended != "estimate"
                else " (--max-evaluations or --time-limit-s raise the limit)."
            )
        )
    if e.underdetermined and not e.kept_prediction:
        s = e.support
        what = (
            f"the images determine about {s.determined_phases:.0f} combinations of phases, and the correction is "
            f"expected to leave {s.expected_focus:.2f} of the ideal focus against {s.uncorrected_focus:.2f} "
            "uncorrected "
            f"and {s.groups_focus:.2f} with the group fit"
            if s is not None
            else "one acquisition cannot determine a phase per element"
        )
        print(
            f"estimate: AMBIGUOUS: {len(e.phases_rad)} phases from {len(args.image)} image(s), {e.n_pixels} masked "
            f"pixels, are underdetermined ({what}); add images taken with known diversity phases (--image with a "
            "sidecar, preferably defocused: --suggest), or a prediction as prior (--prior)."
        )
    elif e.ambiguous:
        where = (
            "the next acquisition below; " if e.next_acquisition is not None else ""
        ) + f"suggested_phases_rad{' -> ' + args.suggest if args.suggest else ' in the JSON'}"
        print(
            f"estimate: AMBIGUOUS: {len(e.candidate_costs)} clearly different solutions fit within the noise; a "
            f"correction could leave as little as {e.worst_recovery:.2f} of the ideal focus. Acquire one more image "
            f"with the suggested known phases added ({where})."
        )
    # The library decides what to apply (recommended); the lines say why.
    use_prediction = e.recommended == "prediction"
    if e.recommended in ("uncorrected", "groups"):
        which = (
            "no correction (zero phases)"
            if e.recommended == "uncorrected"
            else "the group fit (group_phases_rad on their elements)"
        )
        print(
            "estimate: NOT SUPPORTED: this estimate is NOT to be applied: the images do not support it"
            + (" and its search did not converge" if not e.converged else "")
            + f"; the safer correction is {which}"
            + (f", which is what {args.out_phases} holds" if args.out_phases else "")
            + "."
        )
    c = e.prior_check
    conflict = c is not None and c.conflict
    noise = (
        "the given noise (--noise-rad)"
        if args.noise_rad is not None
        else "the noise expected from the image background"
    )
    if use_prediction:
        which = "the prediction (--prior" + (", moved along its fitted modes" if moved else "") + ")"
        if e.model_mismatch or c is None:
            why = f"MODEL MISMATCH: the best fit leaves {e.misfit:.2f} x {noise}; the model does not explain the images"
        else:
            why = (
                f"PRIOR CONFLICT: at the prediction the images leave chi-squared {c.chi2_prediction:.0f}, {c.z:.1f} "
                f"std above the {c.null_mean:.0f} that images of truths within the prior's {args.prior_std_rad:g} rad "
                f"would leave ({c.excess_per_pixel:.2f} x the noise per pixel more): the model cannot form these "
                "images about the prediction, or the prediction errs by more than its std, and the fit (misfit "
                f"{e.misfit:.2f}) absorbs that in its phases"
            )
        print(
            f"estimate: {why}, so this estimate is NOT to be applied: {which} is the safer correction"
            + (f" and is what {args.out_phases} holds" if args.out_phases else "")
            + ". Check the scenario against the images (arfi diagnose), then estimate again."
        )
    elif e.model_mismatch:
        print(
            f"estimate: MODEL MISMATCH: the best fit leaves {e.misfit:.2f} x {noise}; the model does not explain the "
            "image (more aberration terms than groups?) and this correction may weaken the focus: check it with an "
            "image taken with the correction applied (loop 2)."
        )
    if e.next_acquisition is not None:
        nxt = e.next_acquisition
        x, y, z = nxt.focus_shift_mm
        print(
            f"estimate: next acquisition: the focus shifted by ({x:+g}, {y:+g}, {z:+g}) mm (known phases -> "
            f"{args.suggest or 'suggested_phases_rad in the JSON'}); expected focus after the correction "
            f"{nxt.expected_focus_now:.2f} of the ideal now, {nxt.expected_focus:.2f} with that image (linearised "
            "posterior: ranks acquisitions, ignores twins)"
        )
    if args.out_phases:
        save_npy(args.out_phases, e.recommended_phases_rad)
    if args.suggest:
        save_npy(args.suggest, e.suggested_phases_rad)
    if args.report:
        from arfi.reports.html import fit_report

        image, known = pairs[0]
        model = sim.arfi_image(
            e.phases_rad if known is None else sim.element_phases(e.phases_rad) + sim.element_phases(known)
        )
        flags = [
            name
            for name, on in (
                ("KEPT THE PREDICTION", e.kept_prediction),
                ("AMBIGUOUS", e.ambiguous or e.underdetermined),
                ("NOT CONVERGED", not e.converged),
                (f"NOT SUPPORTED (recommended: {e.recommended})", e.recommended in ("uncorrected", "groups")),
                (f"MODEL MISMATCH (misfit {e.misfit:.2f} x the noise)", e.model_mismatch),
                ("PRIOR CONFLICT (recommended: prediction)", conflict),
            )
            if on
        ]
        page = fit_report(
            args.report,
            sim,
            "estimate",
            image,
            model,
            {
                "image": args.image[0],
                "method": e.method,
                "cost": e.cost,
                "ambiguous": e.ambiguous,
                "model_mismatch": e.model_mismatch,
                "misfit": e.misfit,
                "noise_floor_rad": e.noise_floor,
            },
            e.phases_rad,
            warning=("; ".join(flags) + ": see the printed summary before applying this estimate") if flags else None,
        )
        print(f"estimate: report -> {page}")
    prior_settings = (
        {"prior_std_rad": args.prior_std_rad, "prior_correlation_mm": args.prior_correlation_mm} if e.prior_used else {}
    )
    if path:
        prior_settings["prior_transmission"] = path
    finish(
        args,
        {**r.to_dict(), **prior_settings, "images": args.image, "groups": len(e.phases_rad), "seconds_total": total},
    )
    return 0
