#!/usr/bin/env python3
"""The chain through a head with two estimate models: how much the MR-ARFI images add to the CT
prediction, and what the bone-speed mode does, for a patient whose skull the CT gets wrong.

A head phantom (``arfi phantom --array hemisphere --thickness-mm 4 12``), 256 elements steered to
(10, 0, 140) mm. The patient's bone is faster than the CT conversion says and the head is off
its registration: ``mild`` (10 %, 1.5 mm along x: the tutorial's) or ``harsh`` (25 %, 3 mm along
x and 4 degrees about y through the target). Three images (in focus, defocused by +-5 mm) at
0.02 rad noise, taken with the prediction's reference steering. Estimates, each with a prior of
``--prior-std-rad`` correlated over 30 mm and a fitted amplitude scale:

* ``without-bone`` (the README's and the tutorial's): the head with its bone read as soft tissue,
  the elements weighted by the prediction's transmission, the prediction as the prior;
* ``with-bone``: the head as the CT reads it, driven with the reference steering; the estimate is
  the residual on top of the prediction (prior zero), the correction the prediction plus it.

Each without and with the prediction's bone-speed mode (``--mode-percent`` times
``bone_speed_sensitivity_rad_per_percent``) free in the per-element fit; and ``fitted`` (what
``arfi estimate`` does by default with a prediction that gives the mode): the mode's coefficient
fitted to the images first on the head with the CT's bone, the phases the prediction's
(``Simulation.fit_mode``), then the ``without-bone`` estimate around the prediction moved along it. Printed: the focal
pressure at the target through
the patient's skull as a fraction of the most any phases give (``Prediction.pressure_with``) for
no correction, the prediction, the prediction moved along the mode alone, and each estimate,
with its posterior cost and misfit. At 650 kHz and 0.5 mm voxels a run takes about 15 minutes
(the basis through bone, 256 element marches on the simulation's grid, about 4.5 of them) and
9 GB; ``--frequency-hz 220000 --voxel-mm 2`` half a minute.

Usage::

    python benches/bench_chain_models.py [--seed 1] [--case harsh] [--frequency-hz 650000] [--voxel-mm 0.5]
        [--prior-std-rad 0.15] [--mode-percent 20] [--models fitted without-bone with-bone] [--json FILE]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from arfi.analysis.prediction import predict
from arfi.cli import main as arfi_main
from arfi.scenario import Scenario
from arfi.simulation import Simulation

TARGET_MM = np.array([10.0, 0.0, 140.0])
ELEMENTS = 256
CASES = {"mild": (1.10, 1.5, 0.0), "harsh": (1.25, 3.0, 4.0)}  # bone speed factor, shift (mm), rotation (deg)
AS_READ = "patient_to_transducer_mm = [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 170], [0, 0, 0, 1]]"


def scenarios(d: Path, seed: int, case: str, frequency_hz: float, voxel_mm: float) -> dict[str, Path]:
    """The head as read, the patient (its bone and registration off) and the two models."""
    assert (
        arfi_main(
            [
                "phantom",
                "--out",
                str(d / "head_ct.nii.gz"),
                "--scenario-out",
                str(d / "head.toml"),
                "--array",
                "hemisphere",
                "--thickness-mm",
                "4",
                "12",
                "--voxel-mm",
                str(voxel_mm),
                "--seed",
                str(seed),
            ]
        )
        == 0
    )
    text = (
        (d / "head.toml")
        .read_text()
        .replace("elements = 1024", f"elements = {ELEMENTS}")
        .replace("frequency_hz = 650000.0", f"frequency_hz = {frequency_hz}")
        .replace("position_mm = [0.0, 0.0, 150.0]", f"position_mm = [{TARGET_MM[0]}, {TARGET_MM[1]}, {TARGET_MM[2]}]")
    )
    assert AS_READ in text, "the phantom's registration changed: update AS_READ"
    factor, shift_mm, degrees = CASES[case]
    a = np.radians(degrees)
    rotation = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    off = np.eye(4)
    off[:3, :3] = rotation
    off[:3, 3] = TARGET_MM - rotation @ TARGET_MM + np.array([shift_mm, 0.0, 0.0])
    as_read = np.array([[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 170], [0, 0, 0, 1.0]])
    rows = ", ".join("[" + ", ".join(f"{v:.12g}" for v in row) + "]" for row in off @ as_read)
    paths = {name: d / f"{name}.toml" for name in ("head", "patient", "without-bone", "with-bone")}
    paths["head"].write_text(text)
    paths["patient"].write_text(
        text.replace(AS_READ, f"patient_to_transducer_mm = [{rows}]").replace(
            "[ct]\n", f"[ct]\nbone_sound_speed_m_s = {2900.0 * factor}\nsteer_without_bone = true\n"
        )
    )
    paths["without-bone"].write_text(text.replace("[ct]\n", "[ct]\nwithout_bone = true\n"))
    paths["with-bone"].write_text(text.replace("[ct]\n", "[ct]\nsteer_without_bone = true\n"))
    return paths


def run(
    seed: int, case: str, frequency_hz: float, voxel_mm: float, std: float, mode_percent: float, models: list[str]
) -> dict[str, object]:
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        paths = scenarios(Path(folder), seed, case, frequency_hz, voxel_mm)
        prediction = predict(Scenario.load(paths["head"]), bone_speed_sensitivity=True)
        prior, mode = prediction.phases_rad, mode_percent * prediction.bone_speed_sensitivity_rad_per_percent
        patient = Simulation(Scenario.load(paths["patient"]))
        known = [None] + [patient.focus_shift_phases((0.0, 0.0, dz)) for dz in (5.0, -5.0)]
        images = [patient.arfi_image(k, 0.02, i + 1) for i, k in enumerate(known)]
        del patient
        truth = predict(Scenario.load(paths["patient"]))
        fraction = lambda phases: float(truth.pressure_with(phases) / truth.optimal_pa)  # noqa: E731
        r: dict[str, object] = {
            "date": _dt.date.today().isoformat(),
            "seed": seed,
            "case": case,
            "frequency_hz": frequency_hz,
            "voxel_mm": voxel_mm,
            "prior_std_rad": std,
            "mode_percent": mode_percent,
            "uncorrected": fraction(np.zeros(ELEMENTS)),
            "prediction": fraction(prior),
            "along_the_mode": {f"{c:+.1f}": fraction(prior + c * mode) for c in (-1.0, -0.5, 0.5, 1.0, 1.5)},
        }
        for name in models:
            if name == "fitted":
                # The CLI's default: the mode's coefficient from the images on the head with the CT's
                # bone, then the estimate without bone around the prediction moved along it.
                skull = Simulation(Scenario.load(paths["head"]).with_ct_bone(), groups=ELEMENTS)
                fit = skull.fit_mode(images, known, mode)
                del skull
                t = prediction.transmission
                model = Simulation(Scenario.load(paths["without-bone"]), groups=ELEMENTS).with_element_amplitudes(
                    t / t.mean()
                )
                moved = prior + fit.coefficient * mode
                e = model.estimate(
                    images, known, prior=moved, prior_std_rad=std, prior_correlation_mm=30.0, fit_nuisance="amplitude"
                )
                r[name] = {
                    "bone_speed_percent": fit.coefficient * mode_percent,
                    "std_percent": fit.std * mode_percent,
                    "moved": fraction(moved),
                    "fraction": fraction(e.phases_rad),
                    "posterior_cost": e.posterior_cost,
                    "misfit": e.misfit,
                    "model_mismatch": e.model_mismatch,
                }
                print(
                    f"  fitted: bone speed {r[name]['bone_speed_percent']:+.1f} +- {r[name]['std_percent']:.1f} %, the "
                    f"prediction moved {r[name]['moved']:.3f}, the estimate around it {r[name]['fraction']:.3f} of the "
                    f"optimum, misfit {e.misfit:.2f} ({time.perf_counter() - t0:.0f} s)",
                    flush=True,
                )
                continue
            if name == "without-bone":
                t = prediction.transmission
                model = Simulation(Scenario.load(paths[name]), groups=ELEMENTS).with_element_amplitudes(t / t.mean())
                mean, add = prior, np.zeros(ELEMENTS)
            else:
                model, mean, add = Simulation(Scenario.load(paths[name]), groups=ELEMENTS), np.zeros(ELEMENTS), prior
            for modes in (None, mode[None, :]):
                e = model.estimate(
                    images,
                    known,
                    prior=mean,
                    prior_std_rad=std,
                    prior_correlation_mm=30.0,
                    fit_nuisance="amplitude",
                    prior_modes=modes,
                )
                key = f"{name}{'' if modes is None else ', mode'}"
                r[key] = {
                    "fraction": fraction(add + e.phases_rad),
                    "posterior_cost": e.posterior_cost,
                    "misfit": e.misfit,
                    "scale": e.nuisance.scale if e.nuisance else None,
                    "model_mismatch": e.model_mismatch,
                }
                print(
                    f"  {key}: {r[key]['fraction']:.3f} of the optimum, posterior cost {e.posterior_cost:.1f}, misfit "
                    f"{e.misfit:.2f} ({time.perf_counter() - t0:.0f} s)",
                    flush=True,
                )
        r["seconds"] = time.perf_counter() - t0
        return r


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--case", choices=sorted(CASES), default="harsh")
    p.add_argument("--frequency-hz", type=float, default=650000.0)
    p.add_argument("--voxel-mm", type=float, default=0.5)
    p.add_argument("--prior-std-rad", type=float, default=0.15)
    p.add_argument("--mode-percent", type=float, default=20.0)
    p.add_argument(
        "--models",
        nargs="+",
        choices=["fitted", "without-bone", "with-bone"],
        default=["fitted", "without-bone", "with-bone"],
    )
    p.add_argument("--json", type=Path)
    a = p.parse_args()
    r = run(a.seed, a.case, a.frequency_hz, a.voxel_mm, a.prior_std_rad, a.mode_percent, a.models)
    along = ", ".join(f"{k}: {v:.3f}" for k, v in r["along_the_mode"].items())  # type: ignore[union-attr]
    print(
        f"seed {a.seed} {a.case}: uncorrected {r['uncorrected']:.3f}, prediction {r['prediction']:.3f}; the prediction "
        f"moved along the mode by (x {a.mode_percent:g} %) {along}"
    )
    if a.json:
        a.json.write_text(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
