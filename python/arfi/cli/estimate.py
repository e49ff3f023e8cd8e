"""``arfi estimate``: hybrid estimation of the phase aberration."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import numpy as np

from arfi import _core, prior_modes
from arfi.cli.common import (
    UsageError,
    add_calibration,
    add_common,
    add_method,
    add_report,
    calibrated_simulation,
    estimate_options,
    finish,
    load_scenario,
    npy_path,
    prediction_json,
    read_image,
    read_optional_phases,
    read_transmission,
    save_npy,
)
from arfi.scenario import Scenario

TARGET_TOLERANCE_MM = 0.5
"""How far the focus may lie from the target a ``--prior-transmission`` was predicted for: a
fraction of the focal spot's width (2.3 mm at 650 kHz), over which each element's wave crosses
the same bone."""

#: The option that sets each of the prediction's modes' prior std, and the key of the JSON of
#: arfi predict that holds that mode.
MODE_KEYS = {
    "--prior-bone-speed-std-percent": "bone_speed_sensitivity_rad_per_percent",
    "--prior-pose-std-mm": "pose_sensitivity_rad_per_mm",
    "--prior-pose-std-deg": "pose_sensitivity_rad_per_deg",
}


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
        "--prior-transmission",
        dest="prior_transmission",
        metavar="T",
        help="each element's predicted transmission through the skull: the JSON of arfi predict (its "
        "'transmission'), or .npy or text with one value per element. The model then drives each element at its "
        "transmission relative to the mean, so that a model of the head without its skull weighs the elements as the "
        "skull does (the skull's overall loss is the image scale's: --fit-nuisance amplitude). The JSON's 'target_mm' "
        "must lie within 0.5 mm of the scenario's focus. For a per-element estimate with --prior, the JSON also turns "
        "on the fit of the prediction's bone-speed mode before the estimate (a second model, of the head with its "
        "bone, built and marched; announced when it starts; --prior-bone-speed-std-percent 0 leaves it out)",
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
    if prior is not None:
        outline.check_prior(prior, f"--prior: {args.prior}", args.groups)
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
        fit_nuisance=args.fit_nuisance,
        suggest=bool(args.suggest),
    )
    transmission, predicted_at = read_transmission(args.prior_transmission) if args.prior_transmission else (None, None)
    if transmission is not None:
        check_transmission(args, transmission, predicted_at, outline)
    pairs = [read_image(outline, p, args.groups) for p in args.image]
    modes, source = fit_modes(args, scenario, prior, pairs)
    moved = modes is not None and modes.prior_moved
    if modes is not None and moved:
        prior = modes.prior
        options = options.replace(prior=prior)
    sim = calibrated_simulation(args, scenario, source)
    if transmission is not None:
        sim = sim.with_element_amplitudes(transmission / transmission.mean())
    e = sim.estimate([p[0] for p in pairs], [p[1] for p in pairs], options, progress=sys.stderr.isatty())
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
        from arfi.report import fit_report

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
    if modes is not None:
        prior_settings.update(modes_json(modes))
    if transmission is not None:
        prior_settings["prior_transmission"] = args.prior_transmission
    finish(
        args,
        {**e.to_dict(), **prior_settings, "images": args.image, "groups": len(e.phases_rad), "seconds_total": total},
    )
    return 0


def check_transmission(
    args: argparse.Namespace, transmission: np.ndarray, predicted_at: np.ndarray | None, outline: _core.ScenarioOutline
) -> None:
    """``--prior-transmission`` holds one value per element of the scenario's array, predicted at
    its focus."""
    outline.check_per_element(len(transmission), f"--prior-transmission: {args.prior_transmission}")
    # Each element's transmission is its wave's at the point predicted for; a focus elsewhere
    # (beyond a fraction of the focal spot) crosses the skull elsewhere.
    if predicted_at is not None and np.linalg.norm(predicted_at - np.asarray(outline.focus_mm)) > TARGET_TOLERANCE_MM:
        x, y, z = predicted_at
        fx, fy, fz = outline.focus_mm
        raise ValueError(
            f"--prior-transmission: {args.prior_transmission}: predicted for the target ({x:.1f}, {y:.1f}, {z:.1f}) "
            f"mm, but the scenario focuses at ({fx:.1f}, {fy:.1f}, {fz:.1f}) mm: predict at the focus (arfi predict "
            "--scenario of the same focus, or --target-mm)"
        )


def fit_modes(
    args: argparse.Namespace,
    scenario: Scenario,
    prior: np.ndarray | None,
    pairs: list[tuple[np.ndarray, np.ndarray | None]],
) -> tuple[prior_modes.ModesResult | None, _core.CoreSourceModel | None]:
    """The prediction's error modes (pose, bone speed, ``--prior-modes``) fitted to the images on
    the head with the CT's bone (:mod:`arfi.prior_modes`), by default wherever the prediction's
    JSON holds them and the estimate is per element; the result's ``prior`` is the prediction
    moved by them and ``prior_moved`` whether it is to be used. None when there is nothing to
    fit. The model with bone is built and dropped here, its memory handed back, before the
    estimation's own model is built, so that the two plans are never held at once; its source
    model (the array projected onto the grid, shared by the estimation's model) is returned
    with the result."""
    stds = {
        "--prior-bone-speed-std-percent": args.prior_bone_speed_std_percent,
        "--prior-pose-std-mm": args.prior_pose_std_mm,
        "--prior-pose-std-deg": args.prior_pose_std_deg,
    }
    for option, std in stds.items():
        if std is not None and not (np.isfinite(std) and std >= 0):
            raise UsageError(f"{option}: must be a finite number >= 0, got {std:g}")
    explicit = [o for o, v in stds.items() if v] + (["--prior-modes"] if args.prior_modes else [])
    first = explicit[0] if explicit else None
    if prior is None:
        if first:
            raise UsageError(f"{first}: needs --prior (the prediction the modes belong to)")
        return None, None
    if args.groups != len(prior):
        if first:
            raise UsageError(f"{first}: fitted for per-element estimates only (--groups {len(prior)})")
        return None, None
    path = args.prior_transmission
    prediction = prediction_json(path, "--prior-transmission") if path and path.endswith(".json") else {}
    for option, key in MODE_KEYS.items():
        if stds[option] and key not in prediction:
            raise UsageError(
                f"{option}: needs --prior-transmission with the JSON of arfi predict --json holding '{key}'"
                + (
                    f" ({path} has none: predict again"
                    + (" with --pose-sensitivity)" if key.startswith("pose") else " with the current arfi)")
                    if prediction
                    else ""
                )
            )
    try:
        modes = prior_modes.prediction_modes(
            prediction,
            len(prior),
            pose_std_mm=args.prior_pose_std_mm,
            pose_std_deg=args.prior_pose_std_deg,
            bone_speed_std_percent=(
                prior_modes.BONE_SPEED_STD_PERCENT
                if args.prior_bone_speed_std_percent is None
                else args.prior_bone_speed_std_percent
            ),
        )
    except ValueError as e:
        raise UsageError(f"{option_of(str(e), stds)}: {e}") from None
    if args.prior_modes:
        try:
            modes += prior_modes.read_modes(args.prior_modes, len(prior))
        except (FileNotFoundError, ValueError) as e:
            raise UsageError(f"--prior-modes: {e}") from None
    if not modes:
        return None, None
    if scenario.to_dict().get("ct") is None:
        if first:
            raise UsageError(f"{first}: needs a [ct] scenario (the modes are fitted on the head with the CT's bone)")
        return None, None
    # Said before it runs: the fit builds and marches a second model, through the skull.
    by_default = args.prior_bone_speed_std_percent is None and any(m.name == "bone_speed" for m in modes)
    print(
        f"estimate: fitting the prediction's modes ({', '.join(m.name for m in modes)}) to the images first, on a "
        "model of the head with the CT's bone"
        + (
            " (the bone speed by default where the --prior-transmission JSON holds its sensitivity; "
            "--prior-bone-speed-std-percent 0 skips it)"
            if by_default
            else ""
        ),
        flush=True,
    )
    skull = calibrated_simulation(args, scenario.with_ct_bone())
    result = prior_modes.fit_prior_modes(
        skull, [p[0] for p in pairs], [p[1] for p in pairs], prior, modes, noise_rad=args.noise_rad
    )
    source = skull.source_model()
    del skull
    _core.release_freed()
    at_edge = [m.name for m, edge in zip(result.modes, result.at_bound) if edge]
    print(
        f"estimate: {modes_text(result)}, image scale {result.scale:.3f}, misfit {result.misfit:.2f} "
        f"({result.misfit_at_zero:.2f} with the prediction as it is) over {result.n_pixels} pixels, "
        f"{result.iterations} "
        f"iterations{'' if result.converged else ' (not converged: the iterations ran out or a step failed)'}, the "
        f"model with bone built and marched in {result.seconds:.1f} s; the images' chi-squared falls by "
        f"{result.evidence:.1f} ({result.threshold:.1f} needed to move the prior: the 95 % point of noise alone, as "
        "many degrees of freedom as modes)"
    )
    if at_edge:
        print(
            f"estimate: PRIOR NOT MOVED: {', '.join(at_edge)} at the fit's end (four prior spreads): check the CT's "
            "conversion and registration against the images (arfi diagnose)"
        )
    elif not result.supported:
        print(
            "estimate: PRIOR NOT MOVED: the images do not support it (the modes explain no more of them than as many "
            "free coefficients explain of noise)"
        )
    else:
        print("estimate: prior moved along the modes by the fitted values")
    return result, source


def option_of(message: str, stds: dict[str, float | None]) -> str:
    """The option a malformed mode of the prediction belongs to: the one that asked for it, else
    the file it came from."""
    for option, key in MODE_KEYS.items():
        if stds[option] and message.startswith(key):
            return option
    return "--prior-transmission"


def modes_text(r: prior_modes.ModesResult) -> str:
    """The fitted modes in words: the registration's pose, the bone speed, a user's modes."""
    parts = []
    pose = r.pose()
    if pose is not None:
        tri = lambda v: "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"  # noqa: E731
        std = {m.name: m.std for m in r.modes}
        parts.append(
            f"head shifted {tri(pose['shift_mm'])} +- {tri(pose['shift_std_mm'])} mm and turned "
            f"{tri(pose['turn_deg'])} +- {tri(pose['turn_std_deg'])} deg off the CT's registration (prior "
            f"+-{std['shift_x']:g} mm, +-{std['turn_x']:g} deg)"
        )
    for m, v, s in zip(r.modes, r.values, r.std):
        if pose is not None and m.name in prior_modes.POSE_NAMES:
            continue
        what = "bone speed" if m.name == "bone_speed" else m.name
        tail = " of the conversion's" if m.name == "bone_speed" else ""
        parts.append(f"{what} {v:+.1f} +- {s:.1f} {m.unit}{tail} (prior +-{m.std:g} {m.unit})")
    return "prediction's modes from the images on the head with the CT's bone: " + "; ".join(parts)


def modes_json(r: prior_modes.ModesResult) -> dict[str, Any]:
    """The JSON keys of a modes fit: ``prior_modes_fit`` (every mode, the pose) and, where the
    bone speed was among them, ``bone_speed_fit`` with its percent."""
    d: dict[str, Any] = {"prior_modes_fit": r.to_dict()}
    bone = r.value("bone_speed")
    if bone is not None:
        std_prior = next(m.std for m in r.modes if m.name == "bone_speed")
        d["prior_bone_speed_std_percent"] = std_prior
        d["bone_speed_fit"] = {
            "percent": bone[0],
            "std_percent": bone[1],
            "std_percent_prior": std_prior,
            "scale": r.scale,
            "misfit": r.misfit,
            "n_pixels": r.n_pixels,
            "prior_moved": r.prior_moved,
            "seconds": r.seconds,
        }
    return d
