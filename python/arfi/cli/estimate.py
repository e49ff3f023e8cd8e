"""``arfi estimate``: hybrid estimation of the phase aberration."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import numpy as np

from arfi.cli.common import (UsageError, add_calibration, add_common, add_method, add_report, calibrated_simulation, finish, load_scenario,
                             npy_path, read_image, read_bone_speed_sensitivity, read_optional_phases, read_transmission, save_npy)
from arfi.estimation import wrap
from arfi import _core
from arfi.scenario import Scenario
from arfi.simulation import Simulation

TARGET_TOLERANCE_MM = 0.5
"""How far the focus may lie from the target a ``--prior-transmission`` was predicted for: a
fraction of the focal spot's width (2.3 mm at 650 kHz), over which each element's wave crosses
the same bone."""

BONE_SPEED_STD_PERCENT = 20.0
"""How far the CT conversion's bone sound speed is taken to be off a priori (percent, one
standard deviation) where the prediction gives its bone-speed mode: the porosity model's dense-
bone speed is a population constant, and individual skulls' speeds scatter by about a tenth
to a fifth around such constants."""


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser("estimate", help="hybrid estimation of the phase aberration",
                       description="Estimate the per-group phase aberration whose simulated MR-ARFI image(s) match the "
                       "measured one(s). Several --image options make a joint fit; each image's sidecar may hold the known "
                       "phases added for it (applied_phases_rad). Subtract the estimate to correct.",
                       epilog="example: arfi estimate --image aberrated.nii.gz --calibration cal.json --groups 16 "
                       "--method lbfgs --json estimate.json")
    add_common(p)
    p.add_argument("--image", required=True, action="append", metavar="M.nii.gz")
    add_calibration(p)
    p.add_argument("--groups", type=int, default=16,
                   help="number of contiguous element groups (default 16); the number of elements (1024) estimates one "
                   "phase per element on the element field basis (lbfgs only): one march per element, through soft tissue and "
                   "water on a grid of 3/8 of the shortest wavelength, at most 3/4 of an MR pixel (images within 1.5 %% of the "
                   "peak of the scenario's grid's at 550-650 kHz)")
    add_method(p, "lbfgs",
               "nelder-mead: the paper's (zero start, <= 8000 evaluations); pso; lbfgs: gradient multi-start (default)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-evaluations", type=int, dest="max_evaluations",
                   help="evaluation limit (defaults: nelder-mead/pso 8000, lbfgs 40000 over all starts, per element 200, "
                   "or 120 when --fit-nuisance fits W or the shift)")
    p.add_argument("--time-limit-s", type=float, dest="time_limit_s")
    p.add_argument("--starts", type=int, help="L-BFGS random starts (default 20)")
    p.add_argument("--fit-amplitude", action="store_true", dest="fit_amplitude",
                   help="fit a free amplitude scale too (absorbs a uniform focal loss)")
    p.add_argument("--fit-nuisance", dest="fit_nuisance", metavar="NAMES",
                   help="per-element estimates: also fit what the images differ in from the model (comma-separated, "
                   "names as arfi diagnose reports them, or 'all'): amplitude, background_phase (per image an offset and "
                   "a ramp), broadening (W), registration_shift (trades with a steering tilt of the phases: prefer "
                   "registering on a calibration image)")
    p.add_argument("--prior", metavar="P", help="predicted aberration (.npy or text, one value per line; per element or per "
                   "group, the sign of phases_rad: subtracting it corrects), e.g. from a CT-based skull simulation; the "
                   "estimate is then the posterior optimum")
    p.add_argument("--prior-std-rad", type=float, dest="prior_std_rad", metavar="S",
                   help="expected error of each predicted phase (rad); required with --prior")
    p.add_argument("--prior-correlation-mm", type=float, dest="prior_correlation_mm", metavar="L",
                   help="the prediction's errors are a smooth field correlated over L mm (per-element estimates then "
                   "correct the prediction by smooth fields only; default: independent errors)")
    p.add_argument("--prior-transmission", dest="prior_transmission", metavar="T",
                   help="each element's predicted transmission through the skull: the JSON of arfi predict (its "
                   "'transmission'), or .npy or text with one value per element. The model then drives each element at its "
                   "transmission relative to the mean, so that a model of the head without its skull weighs the elements "
                   "as the skull does (the skull's overall loss is the image scale's: --fit-nuisance amplitude). The JSON's "
                   "'target_mm' must lie within 0.5 mm of the scenario's focus")
    p.add_argument("--prior-bone-speed-std-percent", type=float, dest="prior_bone_speed_std_percent", metavar="P",
                   help="the CT conversion's bone sound speed may be off by about P percent (default 20 where the "
                   "--prior-transmission JSON of arfi predict holds bone_speed_sensitivity_rad_per_percent; 0: off). "
                   "Before the per-element fit, the images fit that error's mode (the sensitivity times a coefficient, "
                   "P percent a priori) on the head with the CT's bone, driven with the reference steering, the phases "
                   "otherwise the prediction's (one march per image and coefficient tried, about five coefficients); "
                   "the prior then moves along the mode by the fitted coefficient. Needs --prior, a [ct] scenario "
                   "and one phase per element")
    p.add_argument("--out-phases", dest="out_phases", metavar="F.npy",
                   help="write the phases to subtract, those JSON 'recommended' names: the estimate; when an estimate "
                   "with --prior ends in MODEL MISMATCH (the images are not explained), the prediction itself, moved along "
                   "its bone-speed mode when that was fitted; per element without --prior, when the images do not support "
                   "the estimate (they determine too few combinations of phases for its correction to beat none or the "
                   "group fit) or its search did not converge, zeros (uncorrected) or the group fit on its elements")
    p.add_argument("--suggest", metavar="F.npy", help="write the suggested diversity phases for the next acquisition (per "
                   "element: the known per-element phases of the focus shift whose image is expected to raise the "
                   "corrected focus most, about 10 s more; image it with arfi simulate --focus-shift-mm or on the scanner)")
    add_report(p, "PNG figures (images in mm, colour bars in rad, element maps)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    for path, option in ((args.out_phases, "--out-phases"), (args.suggest, "--suggest")):
        if path:
            npy_path(path, option)  # before the estimate, so that neither is written when one is wrong
    t = time.perf_counter()
    prior = read_optional_phases(args.prior, "--prior")
    transmission, predicted_at = read_transmission(args.prior_transmission) if args.prior_transmission else (None, None)
    scenario = load_scenario(args)
    bone_speed = fit_bone_speed(args, scenario, prior, transmission, predicted_at)
    if bone_speed is not None:
        prior = bone_speed.pop("prior")
    sim = calibrated_simulation(args, scenario)
    if transmission is not None:
        check_transmission(args, transmission, predicted_at, sim)
        sim = sim.with_element_amplitudes(transmission / transmission.mean())
    pairs = [read_image(sim, p) for p in args.image]
    e = sim.estimate([p[0] for p in pairs], [p[1] for p in pairs], method=args.method, max_evaluations=args.max_evaluations,
                     time_limit_s=args.time_limit_s, seed=args.seed, starts=args.starts, fit_amplitude=args.fit_amplitude,
                     progress=sys.stderr.isatty(), prior=prior, prior_std_rad=args.prior_std_rad,
                     prior_correlation_mm=args.prior_correlation_mm, fit_nuisance=args.fit_nuisance,
                     suggest=bool(args.suggest))
    total = time.perf_counter() - t
    kind = "element" if len(e.phases_rad) == sim.n_elements else "group"
    print(f"estimate: {len(e.phases_rad)} {kind} phases by {e.method} from {len(pairs)} image(s): cost {e.cost:.4g} "
          f"({e.n_pixels} pixels, noise floor {e.noise_floor:.4f} rad), {e.evaluations} evaluations in {e.seconds:.2f} s ({e.stop})"
          + (f"; with the prior (+-{args.prior_std_rad:g} rad per phase"
             + (f", errors correlated over {args.prior_correlation_mm:g} mm" if args.prior_correlation_mm else "")
             + (f", moved along the bone-speed mode by {bone_speed['percent']:+.1f} %" if bone_speed and bone_speed["prior_moved"] else "")
             + "), ambiguity judged on the posterior" if e.prior_used else "")
          + f"; recommended: {e.recommended}")
    if e.nuisance is not None:
        n = e.nuisance
        offsets = ", ".join(f"{b:+.3f}" for b in n.offset_rad)
        print(f"estimate: fitted {', '.join(n.fitted)}: amplitude scale {n.scale:.3f}, W {n.broadening_width_mm:.2f} mm, "
              f"shift ({n.dx_mm:+.2f}, {n.dy_mm:+.2f}) mm, background offsets {offsets} rad; misfit "
              f"{e.misfit:.2f} x the noise expectation")
    if e.kept_prediction:
        print("estimate: KEPT THE PREDICTION: one acquisition cannot check a per-element correction of a prediction (one "
              "that fits the image better than the truth can leave less focus than the prediction); add an image with "
              f"other known phases, e.g. a defocus (--suggest), and estimate from both. The prediction leaves a misfit of "
              f"{e.misfit:.2f} x the noise expectation on this image"
              + (" (well above 1: the prediction, or the model, misses what the image shows)." if e.misfit > 1.2 else "."))
    if not e.converged:
        print(f"estimate: NOT CONVERGED: the search stopped at its {e.stop} ({e.evaluations} evaluations) before it "
              f"converged: the phases are where it stopped, not a minimum"
              + ("; not recommended (see below)." if e.recommended != "estimate" else
                 " (--max-evaluations or --time-limit-s raise the limit)."))
    if e.underdetermined and not e.kept_prediction:
        s = e.support
        what = (f"the images determine about {s.determined_phases:.0f} combinations of phases, and the correction is "
                f"expected to leave {s.expected_focus:.2f} of the ideal focus against {s.uncorrected_focus:.2f} uncorrected "
                f"and {s.groups_focus:.2f} with the group fit" if s is not None else
                "one acquisition cannot determine a phase per element")
        print(f"estimate: AMBIGUOUS: {len(e.phases_rad)} phases from {len(args.image)} image(s), {e.n_pixels} masked pixels, are "
              f"underdetermined ({what}); add images taken with known diversity phases (--image with a sidecar, "
              f"preferably defocused: --suggest), or a prediction as prior (--prior).")
    elif e.ambiguous:
        where = ("the next acquisition below; " if e.next_acquisition is not None else "") + \
            f"suggested_phases_rad{' -> ' + args.suggest if args.suggest else ' in the JSON'}"
        print(f"estimate: AMBIGUOUS: {len(e.candidate_costs)} clearly different solutions fit within the noise; a "
              f"correction could leave as little as {e.worst_recovery:.2f} of the ideal focus. Acquire one more image "
              f"with the suggested known phases added ({where}).")
    # The library decides what to apply (recommended); the lines say why.
    use_prediction = e.recommended == "prediction"
    if e.recommended in ("uncorrected", "groups"):
        which = ("no correction (zero phases)" if e.recommended == "uncorrected" else
                 "the group fit (group_phases_rad on their elements)")
        print(f"estimate: NOT SUPPORTED: this estimate is NOT to be applied: the images do not support it"
              + (" and its search did not converge" if not e.converged else "")
              + f"; the safer correction is {which}"
              + (f", which is what {args.out_phases} holds" if args.out_phases else "") + ".")
    if use_prediction:
        which = "the prediction (--prior" + (", moved along its bone-speed mode" if bone_speed and bone_speed["prior_moved"] else "") + ")"
        print(f"estimate: MODEL MISMATCH: the best fit leaves {e.misfit:.2f} x the noise expected from the image background; "
              f"the model does not explain the images, so this estimate is NOT to be applied: {which} is "
              f"the safer correction"
              + (f" and is what {args.out_phases} holds" if args.out_phases else "")
              + ". Check the scenario against the images (arfi diagnose), then estimate again.")
    elif e.model_mismatch:
        print(f"estimate: MODEL MISMATCH: the best fit leaves {e.misfit:.2f} x the noise expected from the image background; "
              f"the model does not explain the image (more aberration terms than groups?) and this correction may weaken "
              f"the focus: check it with an image taken with the correction applied (loop 2).")
    if e.next_acquisition is not None:
        nxt = e.next_acquisition
        x, y, z = nxt.focus_shift_mm
        print(f"estimate: next acquisition: the focus shifted by ({x:+g}, {y:+g}, {z:+g}) mm (known phases -> {args.suggest or 'suggested_phases_rad in the JSON'}); "
              f"expected focus after the correction {nxt.expected_focus_now:.2f} of the ideal now, {nxt.expected_focus:.2f} "
              f"with that image (linearised posterior: ranks acquisitions, ignores twins)")
    if args.out_phases:
        save_npy(args.out_phases, e.recommended_phases_rad)
    if args.suggest:
        save_npy(args.suggest, e.suggested_phases_rad)
    if args.report:
        from arfi.report import fit_report

        image, known = pairs[0]
        model = sim.arfi_image(e.phases_rad if known is None else sim.element_phases(e.phases_rad) + sim.element_phases(known))
        flags = [name for name, on in (("KEPT THE PREDICTION", e.kept_prediction), ("AMBIGUOUS", e.ambiguous or e.underdetermined),
                                        ("NOT CONVERGED", not e.converged),
                                        (f"NOT SUPPORTED (recommended: {e.recommended})", e.recommended in ("uncorrected", "groups")),
                                        (f"MODEL MISMATCH (misfit {e.misfit:.2f} x the noise)", e.model_mismatch)) if on]
        fit_report(args.report, sim, "estimate", image, model, {"image": args.image[0], "method": e.method, "cost": e.cost,
                   "ambiguous": e.ambiguous, "model_mismatch": e.model_mismatch, "misfit": e.misfit,
                   "noise_floor_rad": e.noise_floor}, e.phases_rad,
                   warning=("; ".join(flags) + ": see the printed summary before applying this estimate") if flags else None)
    prior_settings = {"prior_std_rad": args.prior_std_rad, "prior_correlation_mm": args.prior_correlation_mm} if e.prior_used else {}
    if bone_speed is not None:
        prior_settings["prior_bone_speed_std_percent"] = bone_speed["std_percent_prior"]
        prior_settings["bone_speed_fit"] = bone_speed
    if transmission is not None:
        prior_settings["prior_transmission"] = args.prior_transmission
    finish(args, {**e.to_dict(), **prior_settings, "images": args.image, "groups": len(e.phases_rad), "seconds_total": total})
    return 0


def check_transmission(args: argparse.Namespace, transmission: np.ndarray, predicted_at: np.ndarray | None,
                       sim: Simulation) -> None:
    """``--prior-transmission`` holds one value per element of ``sim``, predicted at its focus."""
    if len(transmission) != sim.n_elements:
        raise ValueError(f"--prior-transmission: {args.prior_transmission}: has {len(transmission)} values for "
                         f"{sim.n_elements} elements")
    # Each element's transmission is its wave's at the point predicted for; a focus elsewhere
    # (beyond a fraction of the focal spot) crosses the skull elsewhere.
    if predicted_at is not None and np.linalg.norm(predicted_at - sim.focus_mm) > TARGET_TOLERANCE_MM:
        x, y, z = predicted_at
        fx, fy, fz = sim.focus_mm
        raise ValueError(f"--prior-transmission: {args.prior_transmission}: predicted for the target ({x:.1f}, {y:.1f}, "
                         f"{z:.1f}) mm, but the scenario focuses at ({fx:.1f}, {fy:.1f}, {fz:.1f}) mm: predict at "
                         f"the focus (arfi predict --scenario of the same focus, or --target-mm)")


def fit_bone_speed(args: argparse.Namespace, scenario: Scenario, prior: np.ndarray | None,
                   transmission: np.ndarray | None, predicted_at: np.ndarray | None) -> dict[str, Any] | None:
    """The prediction's bone-speed mode fitted to the images on the head with the CT's bone
    (``--prior-bone-speed-std-percent``; by default wherever the prediction's JSON holds its
    sensitivity and the estimate is per element): the fit's numbers and the prior moved along
    the mode (key ``prior``), or None when there is nothing to fit. The model with bone is built
    and dropped here, its memory handed back, before the estimation's own model is built, so that
    the two plans are never held at once."""
    std = args.prior_bone_speed_std_percent
    explicit = std is not None
    if explicit and not (np.isfinite(std) and std >= 0):
        raise UsageError(f"--prior-bone-speed-std-percent: must be a finite number >= 0, got {std:g}")
    if std == 0:
        return None
    if prior is None:
        if explicit:
            raise UsageError("--prior-bone-speed-std-percent: needs --prior (the prediction the mode belongs to)")
        return None
    if args.groups != len(prior):
        if explicit:
            raise UsageError(f"--prior-bone-speed-std-percent: fitted for per-element estimates only (--groups {len(prior)})")
        return None
    sensitivity = read_bone_speed_sensitivity(args.prior_transmission, len(prior), required=explicit)
    if sensitivity is None:
        return None
    if scenario.to_dict().get("ct") is None:
        if explicit:
            raise UsageError("--prior-bone-speed-std-percent: needs a [ct] scenario (the mode is fitted on the head with "
                             "the CT's bone)")
        return None
    if args.prior_std_rad is None:  # checked here too: the fit takes minutes before the estimate would say so
        raise UsageError("--prior-std-rad: required with --prior (the expected error of each predicted phase, rad)")
    t = time.perf_counter()
    skull = calibrated_simulation(args, scenario.with_ct_bone())
    if skull.n_elements != len(prior):
        raise ValueError(f"--prior: {args.prior}: has {len(prior)} values for {skull.n_elements} elements")
    if transmission is not None:
        check_transmission(args, transmission, predicted_at, skull)
    std = std if explicit else BONE_SPEED_STD_PERCENT
    pairs = [read_image(skull, p) for p in args.image]
    fit = skull.fit_mode([p[0] for p in pairs], [p[1] for p in pairs], std * sensitivity)
    del skull, pairs
    _core.release_freed()
    percent, spread = fit.coefficient * std, fit.std * std
    seconds = time.perf_counter() - t
    found = (f"estimate: bone speed from the images on the head with the CT's bone: {percent:+.1f} +- {spread:.1f} % of "
             f"the conversion's (prior +-{std:g} %; image scale {fit.scale:.3f}, misfit {fit.misfit:.2f} over {fit.n_pixels} "
             f"pixels, {len(fit.tried)} coefficients tried, the model with bone built and marched in {seconds:.1f} s)")
    if fit.bracketed:
        print(f"{found}: the prior moves along the prediction's bone-speed mode by that much")
    else:
        print(f"{found}: at the search's end (three times the prior's spread): the prior is NOT moved; check the CT's "
              f"conversion and registration against the images (arfi diagnose)")
    moved = wrap(prior + fit.coefficient * std * sensitivity) if fit.bracketed else prior
    return {"percent": percent, "std_percent": spread, "std_percent_prior": std, "scale": fit.scale, "misfit": fit.misfit,
            "n_pixels": fit.n_pixels, "tried_percent": [c * std for c, _ in fit.tried], "bracketed": fit.bracketed,
            "prior_moved": fit.bracketed, "seconds": seconds, "prior": moved}
