"""The ``arfi`` command line (SPEC §5).

Every verb takes ``--scenario FILE`` (default: the embedded scenario) and ``--json FILE`` for
machine-readable results. Bad input ends with one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

import json

from arfi.io import read_arfi_image, read_phases, write_arfi_image, write_json, write_npz
from arfi.scenario import Scenario
from arfi.simulation import Simulation


class UsageError(Exception):
    """Bad command-line input: reported as one line, exit 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse prints usage too)
        raise UsageError(f"{self.prog}: {message}")


def _scenario(args: argparse.Namespace) -> Scenario:
    return Scenario.load(args.scenario) if args.scenario else Scenario.default()


def _phases(path: str | None, name: str) -> np.ndarray | None:
    return None if path is None else read_phases(path, name)


def _finish(args: argparse.Namespace, result: dict[str, Any]) -> None:
    if args.json:
        write_json(args.json, result)


def cmd_scenario(args: argparse.Namespace) -> int:
    sys.stdout.write(_scenario(args).to_toml(chosen_grid=True))
    return 0


def cmd_field(args: argparse.Namespace) -> int:
    if not args.out.endswith(".npz"):
        raise UsageError(f"arfi field: --out must end in .npz, got {args.out}")
    t = time.perf_counter()
    sim = Simulation(_scenario(args))
    f = sim.field(_phases(args.phases, "--phases"), args.z_mm)
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

        field_report(args.report, sim, f, {"out": args.out, **focus, "propagation": sim.propagation_summary()},
                     _phases(args.phases, "--phases"))
    _finish(args, {"out": args.out, "z_mm": f.z_mm, "surface_pressure_pa": f.surface_pressure_pa, **focus,
                   "propagation": sim.propagation, "seconds": time.perf_counter() - t})
    return 0


def image_peak(sim: Simulation, image: np.ndarray) -> tuple[float, list[float]]:
    """Maximum of an ARFI image and its pixel centre (mm, transducer frame)."""
    idx = np.unravel_index(int(np.argmax(image)), image.shape)
    vox = np.zeros(3)
    shape = sim.mr_volume_shape
    axes = [a for a in range(3) if shape[a] != 1]
    for a, i in zip(axes, idx):
        vox[a] = i
    pos = sim.mr_affine_mm @ np.append(vox, 1.0)
    return float(image[idx]), [float(v) for v in pos[:3]]


def cmd_simulate(args: argparse.Namespace) -> int:
    out = args.out
    if not (out.endswith(".nii") or out.endswith(".nii.gz")):
        raise UsageError(f"arfi simulate: --out must end in .nii or .nii.gz, got {out}")
    t = time.perf_counter()
    sim = Simulation(_scenario(args))
    aberration = _phases(args.phases, "--phases")
    known = _phases(args.known_phases, "--known-phases")
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
        from arfi.report import image_report

        image_report(args.report, sim, "simulate", image, {"out": out, "focal_arfi_rad": peak, "noise_rad": noise, "seed": args.seed},
                     total)
    print(
        f"simulate: {image.shape[0]} x {image.shape[1]} MR-ARFI image, focal ARFI phase {peak:.3f} rad at "
        f"({pos[0]:.1f}, {pos[1]:.1f}, {pos[2]:.1f}) mm, noise {noise:g} rad -> {out}"
    )
    _finish(args, {"out": out, "focal_arfi_rad": peak, "focal_position_mm": pos, "noise_rad": noise,
                   "seed": args.seed, "amplitude": sim.amplitude, "seconds": time.perf_counter() - t})
    return 0


def _read_image(sim: Simulation, path: str) -> tuple[np.ndarray, np.ndarray | None]:
    """An MR-ARFI image checked against the scenario's MR geometry, and its known phases."""
    image, affine, side = read_arfi_image(path)
    if image.shape != tuple(n for n in sim.mr_volume_shape if n != 1):
        raise ValueError(f"image: {path}: shape {image.shape} does not match the scenario's MR matrix "
                         f"{tuple(n for n in sim.mr_volume_shape if n != 1)}")
    if not np.allclose(affine[:3], sim.mr_affine_mm[:3], atol=1e-3):
        raise ValueError(f"image: {path}: its affine does not match the scenario's MR geometry "
                         f"(plane, centre_mm, fov_mm, slice_thickness_mm)")
    known = side.get("applied_phases_rad")
    if known is not None:
        try:
            known = np.asarray(known, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"sidecar of {path}: applied_phases_rad must be a list of numbers") from None
        sizes = sorted({sim.n_elements, sim.n_groups} | ({sim.n_default_groups} if sim.n_groups == sim.n_elements else set()))
        if known.ndim != 1 or known.size not in sizes or not np.all(np.isfinite(known)):
            raise ValueError(f"sidecar of {path}: applied_phases_rad must hold {' or '.join(map(str, sizes))} "
                             f"finite values, got shape {known.shape}")
    return image, known


def _calibrated(args: argparse.Namespace) -> Simulation:
    """The scenario's simulation, with the calibration file applied when given."""
    sim = Simulation(_scenario(args), groups=getattr(args, "groups", None))
    if getattr(args, "calibration", None):
        path = Path(args.calibration)
        if not path.is_file():
            raise FileNotFoundError(f"--calibration: {path}: no such file")
        try:
            cal = json.loads(path.read_text(encoding="utf-8"))
            width, amplitude = float(cal["broadening_width_mm"]), float(cal["amplitude"])
        except (ValueError, KeyError, TypeError) as e:
            raise ValueError(f"--calibration: {path}: not a calibration file ({e})") from None
        if cal.get("scenario") not in (None, sim.scenario.name) or cal.get("frequency_hz") not in (None, sim.scenario.to_dict()["frequency_hz"]):
            raise ValueError(f"--calibration: {path}: made for scenario {cal.get('scenario')!r} at {cal.get('frequency_hz')} Hz, "
                             f"not {sim.scenario.name!r}")
        sim = sim.with_calibration(width, amplitude)
    return sim


def cmd_calibrate(args: argparse.Namespace) -> int:
    t = time.perf_counter()
    sim = Simulation(_scenario(args))
    image, known = _read_image(sim, args.image)
    c = sim.calibrate(image, known, args.max_width_mm)
    if args.report:
        from arfi.report import fit_report

        model = sim.with_calibration(c.broadening_width_mm, c.amplitude).arfi_image(known)
        fit_report(args.report, sim, "calibrate", image, model, {"image": args.image, **c.to_dict()})
    print(f"calibrate: broadening width W = {c.broadening_width_mm:.3f} mm, amplitude {c.amplitude:.4e} rad·m³/N "
          f"({c.n_pixels} pixels, noise {c.noise_rad:.4f} rad)")
    _finish(args, {**c.to_dict(), "scenario": sim.scenario.name, "frequency_hz": sim.scenario.to_dict()["frequency_hz"],
                   "image": args.image, "seconds": time.perf_counter() - t})
    return 0


def cmd_estimate(args: argparse.Namespace) -> int:
    t = time.perf_counter()
    sim = _calibrated(args)
    pairs = [_read_image(sim, p) for p in args.image]
    e = sim.estimate([p[0] for p in pairs], [p[1] for p in pairs], method=args.method, max_evaluations=args.max_evaluations,
                     time_limit_s=args.time_limit_s, seed=args.seed, starts=args.starts, fit_amplitude=args.fit_amplitude,
                     progress=sys.stderr.isatty())
    total = time.perf_counter() - t
    kind = "element" if len(e.phases_rad) == sim.n_elements else "group"
    print(f"estimate: {len(e.phases_rad)} {kind} phases by {e.method} from {len(pairs)} image(s): cost {e.cost:.4g} "
          f"({e.n_pixels} pixels, noise floor {e.noise_floor:.4f} rad), {e.evaluations} evaluations in {e.seconds:.2f} s ({e.stop})")
    if e.underdetermined:
        print(f"estimate: AMBIGUOUS: {len(e.phases_rad)} phases from {e.n_pixels} masked pixels is underdetermined; add images "
              f"taken with known diversity phases (--image with a sidecar), e.g. suggested_phases_rad.")
    elif e.ambiguous:
        print(f"estimate: AMBIGUOUS: {len(e.candidate_costs)} clearly different solutions fit within the noise; a correction "
              f"could leave as little as {e.worst_recovery:.2f} of the ideal focus. Acquire one more image with the "
              f"suggested known phases added (suggested_phases_rad{' -> ' + args.suggest if args.suggest else ' in the JSON'}).")
    if e.model_mismatch:
        print(f"estimate: MODEL MISMATCH: the best fit leaves {e.misfit:.2f} x the noise expected from the image background; "
              f"the model does not explain the image (more aberration terms than groups?) and this correction may weaken "
              f"the focus: check it with an image taken with the correction applied (loop 2).")
    if args.out_phases:
        with_atomic_npy(args.out_phases, e.phases_rad)
    if args.suggest:
        with_atomic_npy(args.suggest, e.suggested_phases_rad)
    if args.report:
        from arfi.report import fit_report

        image, known = pairs[0]
        model = sim.arfi_image(e.phases_rad if known is None else sim.element_phases(e.phases_rad) + sim.element_phases(known))
        fit_report(args.report, sim, "estimate", image, model, {"image": args.image[0], "method": e.method, "cost": e.cost,
                   "ambiguous": e.ambiguous, "misfit": e.misfit, "noise_floor_rad": e.noise_floor}, e.phases_rad)
    _finish(args, {**e.to_dict(), "images": args.image, "groups": len(e.phases_rad), "seconds_total": total})
    return 0


def cmd_diagnose(args: argparse.Namespace) -> int:
    from arfi.diagnose import EFFECTS, _params

    t = time.perf_counter()
    effects = None
    if args.effects:
        effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        unknown = [e for e in effects if e not in EFFECTS]
        if unknown or not effects:
            raise UsageError(f"arfi diagnose: --effects: unknown effect(s) {', '.join(unknown) or '(none given)'}; "
                             f"known: {', '.join(EFFECTS)}")
    sim = _calibrated(args)
    pairs = [_read_image(sim, p) for p in args.image]
    images = [p[0] for p in pairs]
    d = sim.diagnose(images, [p[1] for p in pairs], threshold=args.threshold, effects=effects, time_limit_s=args.time_limit_s)
    for k, e in enumerate(d.effects, 1):
        same = f"; explained as well by {', '.join(e['equivalent'])}" if e["equivalent"] else ""
        print(f"diagnose: {k}. {e['name']} ({_params(e['params'])}): cost {e['cost_before']:.4g} -> {e['cost_after']:.4g}, "
              f"evidence {e['evidence']:.1f}{same}")
    if not d.effects:
        print("diagnose: no effect missing: the residual is consistent with the noise")
    failed = [c for c in d.rejected + [c for e in d.effects for c in e["candidates"]] if c["failure"]]
    for c in {c["name"]: c for c in failed}.values():
        print(f"diagnose: {c['name']} could not be fitted: {c['failure']}")
    if d.alternative and d.total_evidence - d.alternative["total_evidence"] < 10:
        print(f"diagnose: the data explain about as well by {', '.join(d.alternative['effects'])} (total evidence "
              f"{d.alternative['total_evidence']:.1f} against {d.total_evidence:.1f}); images with known diversity phases tell them apart")
    if d.stop == "time limit":
        print(f"diagnose: stopped at the time limit ({args.time_limit_s:g} s) after {len(d.effects)} effect(s); more may be missing")
    print(f"diagnose: residual RMS {d.residual_rms_initial:.4f} -> {d.residual_rms_final:.4f} rad, noise floor {d.noise_floor:.4f} rad")
    if args.report:
        print(f"diagnose: report -> {d.report(sim, images, args.report)}")
    _finish(args, {**d.to_dict(), "images": args.image, "seconds": time.perf_counter() - t})
    return 0


def with_atomic_npy(path: str, array: np.ndarray) -> None:
    """Writes a .npy file atomically."""
    from arfi.io import atomic_path

    if not path.endswith(".npy"):
        raise UsageError(f"{path}: phase vectors are written as .npy")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, array)


def cmd_reproduce(args: argparse.Namespace) -> int:
    from arfi.reproduce import run_study

    if args.scenario:
        raise UsageError("arfi reproduce: runs on the embedded scenario (the paper's phantom); --scenario is not taken")
    s = run_study(args.case, args.repeats, Path(args.out), seed=args.seed, method=args.method, noise_rad=args.noise_rad,
                  diversity=args.diversity, loop2_iterations=args.loop2)
    print(f"reproduce: {s['case']}-aberration, {s['repeats']} repeats ({s['method']}): recovered fraction "
          f"{s['mean_recovered_fraction']:.2f} (paper {s['paper']['recovered_fraction']}), gain {s['mean_gain']:+.0%} "
          f"(paper {s['paper']['gain']:+.0%}), phase error {s['mean_phase_error_rad']:.2f} rad "
          f"(paper {s['paper']['phase_error_rad']}) in {s['seconds']:.1f} s -> {args.out}/report.html")
    flagged = sum(bool(r["ambiguous"]) for r in s["table"])
    if flagged and not (args.diversity or args.loop2):
        print(f"reproduce: {flagged} of {len(s['table'])} estimates flagged ambiguous (other aberrations fit their image within "
              f"the noise: one in-focus image hardly tells phi(u) from -phi(-u)); known diversity images (--diversity 3) or the paper's loop 2 (--loop2 3) resolve them")
    elif flagged:
        print(f"reproduce: {flagged} of {len(s['table'])} final estimates still flagged ambiguous: more images would narrow them")
    _finish(args, s)
    return 0


def cmd_dicom(args: argparse.Namespace) -> int:
    from arfi.dicom import read_dicom_arfi, read_transform

    out = args.out
    if not (out.endswith(".nii") or out.endswith(".nii.gz")):
        raise UsageError(f"arfi dicom: --out must end in .nii or .nii.gz, got {out}")
    transform = None if args.transform is None else read_transform(args.transform)
    measured = read_dicom_arfi(args.plus, args.minus, transform, args.phase_units)
    sidecar: dict[str, Any] = {"arfi_dicom": {"plus": measured.sources[0], "minus": measured.sources[1], "echo_time_ms": measured.echo_time_ms,
                                              "mr": measured.mr}}
    if args.known_phases:
        sidecar["applied_phases_rad"] = read_phases(args.known_phases, "--known-phases")
    if args.scenario:  # the image must fit the scenario it will be used with
        sim = Simulation(_scenario(args))
        if tuple(measured.volume_shape) != tuple(sim.mr_volume_shape) or not np.allclose(measured.affine_mm[:3], sim.mr_affine_mm[:3], atol=1e-3):
            m = measured.mr
            raise ValueError(f"--scenario: {args.scenario}: its MR geometry does not match the DICOM image (plane {m['plane']}, "
                             f"center_mm {np.round(m['center_mm'], 3).tolist()}, fov_mm {np.round(m['fov_mm'], 3).tolist()}, "
                             f"matrix {m['matrix']}); run without --scenario to print the matching [mr] section")
    write_arfi_image(out, measured.image_rad, measured.affine_mm, measured.volume_shape, sidecar)
    m, peak = measured.mr, float(np.max(np.abs(measured.image_rad)))
    print(f"dicom: {m['matrix'][0]} x {m['matrix'][1]} MR-ARFI image on the {m['plane']} plane, |Δφ| up to {peak:.3f} rad -> {out}")
    if not args.scenario:
        print(f"dicom: the scenario's MR geometry for this image:\n{measured.mr_toml()}", end="")
    _finish(args, {"out": out, "mr": m, "echo_time_ms": measured.echo_time_ms, "plus": measured.sources[0], "minus": measured.sources[1],
                   "max_abs_arfi_rad": peak})
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from arfi.sweep import run_sweep, trials, write_results

    points = trials(args.noise_levels, args.images, args.methods, args.seeds, args.case, args.seed)
    scenario = Scenario.load(args.scenario) if args.scenario else None
    t = time.perf_counter()
    rows = run_sweep(points, scenario, args.scheduler, args.workers)
    result = write_results(rows, Path(args.out))
    for s in result["summary"]:
        print(f"sweep: {s['method']:>11}, {s['images']} image(s), noise {s['noise_rad']:g} rad: recovered "
              f"{s['recovered_fraction_mean']:.2f} ± {s['recovered_fraction_std']:.2f} ({s['trials']} trials)")
    print(f"sweep: {len(rows)} trials in {time.perf_counter() - t:.0f} s -> {args.out}/sweep.csv, summary.csv, sweep.png")
    _finish(args, {**result, "seconds": time.perf_counter() - t})
    return 0


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", metavar="FILE", help="scenario TOML (default: the embedded phantom experiment)")
    p.add_argument("--json", metavar="FILE", help="write machine-readable results to FILE")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="arfi",
        description="Hybrid simulation–MR-ARFI phase aberration correction for focused ultrasound.",
    )
    sub = parser.add_subparsers(dest="verb", metavar="VERB", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("scenario", help="print a scenario as TOML with every default written out",
                       description="Print the scenario (default: the embedded one) as complete TOML, with the [grid] "
                                   "it resolves to (spacing, step, lateral size, last plane, absorbing layer, "
                                   "reflections, interface model). Delete [grid] keys after editing the frequency, "
                                   "transducer or focus to have them chosen again.",
                       epilog="example: arfi scenario --default > phantom.toml")
    _add_common(p)
    p.add_argument("--default", action="store_true", help="print the embedded default scenario")
    p.set_defaults(run=cmd_scenario)

    p = sub.add_parser("field", help="complex pressure on a plane and the beam axis (.npz)",
                       description="Simulate the beam (HAS) and write the complex pressure amplitude (Pa) on the "
                       "plane z = Z and along the beam axis.",
                       epilog="example: arfi field --z-mm 85 --out focus.npz")
    _add_common(p)
    p.add_argument("--phases", metavar="P", help="phases (rad) added to the steering: .npy or text, one per element or group")
    p.add_argument("--z-mm", type=float, dest="z_mm", help="plane z in mm (default: the focus)")
    p.add_argument("--out", required=True, metavar="F.npz")
    p.add_argument("--report", metavar="DIR", help="write PNG figures (|p| in MPa on the plane in mm, the axis profile) and report.html to DIR")
    p.set_defaults(run=cmd_field)

    p = sub.add_parser("simulate", help="simulated MR-ARFI image (NIfTI)",
                       description="Simulate an MR-ARFI phase image (rad) for phases added to the steering and "
                       "write it as NIfTI with a JSON sidecar.",
                       epilog="example: arfi simulate --phases aberration.npy --noise-rad 0.02 --seed 1 --out aberrated.nii.gz")
    _add_common(p)
    p.add_argument("--phases", metavar="P", help="unknown aberration (rad) added to the steering (not recorded in the sidecar)")
    p.add_argument("--known-phases", metavar="P", dest="known_phases",
                   help="known diversity phases (rad) added to the steering and recorded as applied_phases_rad in the sidecar")
    p.add_argument("--noise-rad", type=float, dest="noise_rad", help="Gaussian noise sigma (rad; default: the scenario's noise_rad)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument("--out", required=True, metavar="M.nii.gz")
    p.add_argument("--report", metavar="DIR", help="write PNG figures (images in mm, colour bars in rad, element maps) and report.html to DIR")
    p.set_defaults(run=cmd_simulate)

    p = sub.add_parser("dicom", help="MR-ARFI image (NIfTI) from the scanner's two phase series (DICOM)",
                       description="Read the phase images acquired with opposite motion-encoding polarity (phi+, phi-), "
                       "form the displacement phase 0.5*wrap(phi+ - phi-), carry the scanner geometry into the transducer "
                       "frame with a rigid transform, and write it as arfi's MR-ARFI NIfTI (phase in rad, affine in the transducer frame, mm) and the matching scenario [mr] "
                       "section. With --scenario, the image must match that scenario's MR geometry.",
                       epilog="example: arfi dicom --plus series_plus/ --minus series_minus/ --transform patient_to_transducer.txt "
                       "--out measured.nii.gz")
    _add_common(p)
    p.add_argument("--plus", required=True, metavar="PATH", help="phase image with positive encoding: a DICOM file, or a directory of one")
    p.add_argument("--minus", required=True, metavar="PATH", help="phase image with negative encoding")
    p.add_argument("--transform", metavar="T", help="4x4 rigid transform patient (DICOM LPS, mm) -> transducer frame (mm): .npy, "
                   "text (4 rows), or JSON {\"patient_to_transducer_mm\": [[...]]} (default: identity)")
    p.add_argument("--phase-units", dest="phase_units", choices=["auto", "rad", "mrad", "siemens"], default="auto",
                   help="stored phase after the DICOM rescale: rad, mrad (GE) or siemens (-4096..4094 = -pi..pi); "
                   "auto picks by Manufacturer (default)")
    p.add_argument("--known-phases", dest="known_phases", metavar="P",
                   help="phases (rad) added to the steering for this acquisition, stored in the sidecar (applied_phases_rad)")
    p.add_argument("--out", required=True, metavar="M.nii.gz")
    p.set_defaults(run=cmd_dicom)

    p = sub.add_parser("calibrate", help="fit the broadening width and amplitude to a no-aberration image",
                       description="Fit the Gaussian broadening width W and the force-to-phase amplitude (paper Eq. 2) "
                       "to an MR-ARFI image taken with no aberration (known phases from its sidecar are honoured).",
                       epilog="example: arfi calibrate --image calibration.nii.gz --json cal.json")
    _add_common(p)
    p.add_argument("--image", required=True, metavar="C.nii.gz")
    p.add_argument("--max-width-mm", type=float, default=10.0, dest="max_width_mm", help="largest W searched (default 10)")
    p.add_argument("--report", metavar="DIR", help="write PNG figures (images in mm, colour bars in rad) and report.html to DIR")
    p.set_defaults(run=cmd_calibrate)

    p = sub.add_parser("estimate", help="hybrid estimation of the phase aberration",
                       description="Estimate the per-group phase aberration whose simulated MR-ARFI image(s) match the "
                       "measured one(s). Several --image options make a joint fit; each image's sidecar may hold the known "
                       "phases added for it (applied_phases_rad). Subtract the estimate to correct.",
                       epilog="example: arfi estimate --image aberrated.nii.gz --calibration cal.json --groups 16 "
                       "--method lbfgs --json estimate.json")
    _add_common(p)
    p.add_argument("--image", required=True, action="append", metavar="M.nii.gz")
    p.add_argument("--calibration", metavar="CAL.json", help="output of arfi calibrate (default: the scenario's W and amplitude)")
    p.add_argument("--groups", type=int, default=16,
                   help="number of contiguous element groups (default 16); the number of elements (1024) estimates one "
                   "phase per element on the element field basis (lbfgs only, about a minute of marching)")
    p.add_argument("--method", choices=["nelder-mead", "pso", "lbfgs"], default="lbfgs",
                   help="nelder-mead: the paper's (zero start, <= 8000 evaluations); pso; lbfgs: gradient multi-start (default)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-evaluations", type=int, dest="max_evaluations",
                   help="evaluation limit (defaults: nelder-mead/pso 8000, lbfgs 40000 over all starts, per element 500)")
    p.add_argument("--time-limit-s", type=float, dest="time_limit_s")
    p.add_argument("--starts", type=int, help="L-BFGS random starts (default 20)")
    p.add_argument("--fit-amplitude", action="store_true", dest="fit_amplitude",
                   help="fit a free amplitude scale too (absorbs a uniform focal loss)")
    p.add_argument("--out-phases", dest="out_phases", metavar="F.npy", help="write the estimated group phases")
    p.add_argument("--suggest", metavar="F.npy", help="write the suggested diversity phases for the next acquisition")
    p.add_argument("--report", metavar="DIR", help="write PNG figures (images in mm, colour bars in rad, element maps) and report.html to DIR")
    p.set_defaults(run=cmd_estimate)

    p = sub.add_parser("diagnose", help="find, name and add the effects the model is missing",
                       description="Compare measured MR-ARFI image(s) with the model, fit every candidate effect of the "
                       "library (amplitude, broadening, registration_shift, background_phase, slice_offset, "
                       "broadening_anisotropic, attenuation, sound_speed, element_dropout, phase_aberration), add the best "
                       "while its BIC evidence against the background noise is positive, and repeat until the residual is noise.",
                       epilog="example: arfi diagnose --image measured.nii.gz --calibration cal.json --json diagnosis.json "
                       "--report diagnosis/")
    _add_common(p)
    p.add_argument("--image", required=True, action="append", metavar="M.nii.gz",
                   help="measured image (repeat for several; each sidecar's applied_phases_rad are its known phases)")
    p.add_argument("--calibration", metavar="CAL.json", help="output of arfi calibrate (default: the scenario's W and amplitude)")
    p.add_argument("--threshold", type=float, default=0.0, help="evidence an effect needs (default 0: the plain BIC)")
    p.add_argument("--effects", metavar="A,B", help="comma-separated effects to try (default: the whole library)")
    p.add_argument("--report", metavar="DIR", help="write per-step PNG figures and report.html to DIR")
    p.add_argument("--time-limit-s", type=float, dest="time_limit_s",
                   help="stop after this many seconds and report the effects added so far")
    p.set_defaults(run=cmd_diagnose)

    p = sub.add_parser("sweep", help="Monte-Carlo study on dask.distributed: noise x images x methods x seeds",
                       description="Run the paper's study (calibrate, estimate, correct) for every combination of ARFI noise "
                       "level, number of images (the aberrated one plus diversity images with seeded random known group "
                       "phases), estimator and seed, on a dask.distributed cluster: a local one by default, or an existing "
                       "one with --scheduler (its workers need arfi installed). Writes sweep.csv (one row per trial: "
                       "recovered_fraction, gain, phase_error_rad, ambiguous, ...), summary.csv and sweep.png (recovered "
                       "fraction against noise and images).",
                       epilog="example: arfi sweep --noise-rad 0.01 0.02 0.05 --images 1 2 3 --methods lbfgs --seeds 5 --out sweep")
    _add_common(p)
    p.add_argument("--noise-rad", dest="noise_levels", type=float, nargs="+", default=[0.02], metavar="S",
                   help="ARFI noise levels (rad; default 0.02)")
    p.add_argument("--images", type=int, nargs="+", default=[1], metavar="K", help="images per trial (default 1, the paper's)")
    p.add_argument("--methods", nargs="+", default=["lbfgs"], metavar="M", help="nelder-mead, pso, lbfgs (default lbfgs)")
    p.add_argument("--seeds", type=int, default=3, help="trials per combination (seeds --seed, --seed+1, ...; default 3)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--case", type=int, choices=[16, 1024], default=16, help="16 group or 1024 element aberrations (default 16)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="an existing dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    p.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per CPU)")
    p.add_argument("--out", required=True, metavar="DIR")
    p.set_defaults(run=cmd_sweep)

    p = sub.add_parser("reproduce", help="re-run the paper's study in simulation (Table 1, Figures 2-10, HTML)",
                       description="Re-run the paper's phantom study in simulation with seeded skull-like aberrations: "
                       "calibration, one aberrated image per repeat, estimation of 16 group phases, correction. Writes "
                       "Table 1 (table.csv, results.json), Figures 2-10 as PNG and report.html to DIR.",
                       epilog="example: arfi reproduce --case 16 --repeats 3 --out results")
    _add_common(p)
    p.add_argument("--case", type=int, choices=[16, 1024], default=16, help="16 group aberrations or 1024 element ones")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--method", choices=["nelder-mead", "pso", "lbfgs"], default="nelder-mead",
                   help="estimator (default: the paper's Nelder-Mead)")
    p.add_argument("--noise-rad", type=float, dest="noise_rad", help="ARFI noise (default: the scenario's, 0.02 rad)")
    p.add_argument("--diversity", type=int, default=0,
                   help="extra images per repeat with random known group phases (phase diversity; default 0, the paper's)")
    p.add_argument("--loop2", type=int, default=0, metavar="N",
                   help="the paper's loop 2: N more acquisitions per repeat, each with the current correction applied, fitted "
                   "jointly; keeps the correction measured best, or none (default 0: loop 1 only, as in the paper)")
    p.set_defaults(run=cmd_reproduce)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: returns the exit status (0 ok, 2 bad input)."""
    try:
        args = build_parser().parse_args(argv)
        if getattr(args, "seed", 0) is not None and not 0 <= getattr(args, "seed", 0) < 2**64:
            raise UsageError("--seed: must be an integer in [0, 2**64)")
        for name in ("max_width_mm", "time_limit_s"):
            v = getattr(args, name, None)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise UsageError(f"--{name.replace('_', '-')}: must be a finite number > 0, got {v}")
        if getattr(args, "repeats", 1) is not None and not 1 <= getattr(args, "repeats", 1) <= 100:
            raise UsageError(f"--repeats: must be between 1 and 100, got {args.repeats}")
        if not 0 <= getattr(args, "diversity", 0) <= 32:
            raise UsageError(f"--diversity: must be between 0 and 32, got {args.diversity}")
        if not 0 <= getattr(args, "loop2", 0) <= 20:
            raise UsageError(f"--loop2: must be between 0 and 20, got {args.loop2}")
        for name in ("max_evaluations", "starts"):
            v = getattr(args, name, None)
            if v is not None and v <= 0:
                raise UsageError(f"--{name.replace('_', '-')}: must be > 0, got {v}")
        if getattr(args, "noise_rad", None) is not None and not (np.isfinite(args.noise_rad) and args.noise_rad >= 0):
            raise UsageError(f"--noise-rad: must be a finite number >= 0, got {args.noise_rad}")
        run: Callable[[argparse.Namespace], int] = args.run
        return run(args)
    except (UsageError, ValueError, FileNotFoundError, IsADirectoryError, PermissionError) as e:
        print(f"arfi: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("arfi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
