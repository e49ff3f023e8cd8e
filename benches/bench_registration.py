#!/usr/bin/env python3
"""What the MR-ARFI images correct of a CT prediction whose registration and bone speed are off:
the chain through a head phantom with the prediction's pose and bone-speed modes fitted to the
images (``arfi estimate --prior-pose-std-mm 1.5 --prior-pose-std-deg 1.5``), against the
bone-speed mode alone (the default).

A head phantom (``arfi phantom --array hemisphere --thickness-mm 4 12``), ``--elements`` of the
hemisphere steered to ``--target-mm``; the patient's bone ``--bone-percent`` faster than the CT
conversion says and the head shifted by ``--shift-mm`` and turned by ``--turn-deg`` (about x, y, z
through the target) off the CT's registration. Three images (in focus, defocused by +-5 mm) at
0.02 rad noise, taken with the prediction's reference steering; the estimate per element with the
prediction as prior (+-0.3 rad, its transmission, ``--fit-nuisance amplitude``). Printed per case:
the focal pressure at the target through the patient's skull as a fraction of the most any phases
give (``Prediction.pressure_with``) for no correction, the prediction, the estimate with the bone
speed alone and with the pose too; the fitted pose against the truth in units of its standard
deviation. At 220 kHz and 1 mm voxels a case takes about a minute.

Usage::

    python benches/bench_registration.py --seed 5 [--shift-mm 1.5 0 0] [--turn-deg 0 0 0] [--bone-percent 10]
        [--frequency-hz 220000] [--target-mm 12 -6 138] [--elements 256] [--voxel-mm 1] [--json FILE]
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

AS_READ = "patient_to_transducer_mm = [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 170], [0, 0, 0, 1]]"
AS_READ_MATRIX = np.array([[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 170], [0, 0, 0, 1.0]])


def rotation(turn_deg: np.ndarray) -> np.ndarray:
    """The turn about x, then y, then z (degrees, right-handed) as a matrix."""
    r = np.eye(3)
    for axis, deg in enumerate(turn_deg):
        a = np.radians(deg)
        c, s = np.cos(a), np.sin(a)
        i, j = (axis + 1) % 3, (axis + 2) % 3
        m = np.eye(3)
        m[i, i] = m[j, j] = c
        m[i, j], m[j, i] = -s, s
        r = m @ r
    return r


def scenarios(d: Path, a: argparse.Namespace) -> None:
    """``head.toml`` (the CT as read), ``patient.toml`` (the head off its registration, its bone
    faster) and ``model.toml`` (the estimate's model: the head without its skull)."""
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
                str(a.voxel_mm),
                "--seed",
                str(a.seed),
            ]
        )
        == 0
    )
    t = np.asarray(a.target_mm, dtype=float)
    text = (
        (d / "head.toml")
        .read_text()
        .replace("elements = 1024", f"elements = {a.elements}")
        .replace("frequency_hz = 650000.0", f"frequency_hz = {a.frequency_hz}")
        .replace("position_mm = [0.0, 0.0, 150.0]", f"position_mm = [{t[0]}, {t[1]}, {t[2]}]")
    )
    assert AS_READ in text, "the phantom's registration changed: update AS_READ"
    r = rotation(np.asarray(a.turn_deg, dtype=float))
    off = np.eye(4)
    off[:3, :3] = r
    off[:3, 3] = t - r @ t + np.asarray(a.shift_mm, dtype=float)
    rows = ", ".join("[" + ", ".join(f"{v:.12g}" for v in row) + "]" for row in off @ AS_READ_MATRIX)
    (d / "head.toml").write_text(text)
    (d / "patient.toml").write_text(
        text.replace(AS_READ, f"patient_to_transducer_mm = [{rows}]").replace(
            "[ct]\n", f"[ct]\nbone_sound_speed_m_s = {2900.0 * (1 + a.bone_percent / 100)}\nsteer_without_bone = true\n"
        )
    )
    (d / "model.toml").write_text(text.replace("[ct]\n", "[ct]\nwithout_bone = true\n"))


def world_images(d: Path, clinic: np.ndarray) -> list[str]:
    """The patient's three MR-ARFI images (in focus, defocused by +-5 mm; 0.02 rad noise) as the
    clinic takes them: every element driven with the clinic's reference steering ``clinic`` (the
    prediction's, through the head as the CT registers it, without bone), the defocus's known
    phases computed by the clinic's model. The patient's own scenario would steer through the
    head where it really lies: a drive no clinic knows, which corrects part of the registration
    error before any estimate (arfi simulate --phases adds the difference, unrecorded)."""
    patient, model = Simulation(Scenario.load(d / "patient.toml")), Simulation(Scenario.load(d / "model.toml"))
    np.save(d / "steering.npy", clinic - patient.steering_phases_rad)
    args = []
    for k, dz in enumerate([0.0, 5.0, -5.0]):
        np.save(d / f"known{k}.npy", model.focus_shift_phases((0.0, 0.0, dz)))
        assert (
            arfi_main(
                [
                    "simulate",
                    "--scenario",
                    str(d / "patient.toml"),
                    "--phases",
                    str(d / "steering.npy"),
                    "--known-phases",
                    str(d / f"known{k}.npy"),
                    "--noise-rad",
                    "0.02",
                    "--seed",
                    str(k + 1),
                    "--out",
                    str(d / f"a{k}.nii.gz"),
                ]
            )
            == 0
        )
        args += ["--image", str(d / f"a{k}.nii.gz")]
    return args


def focus_fraction(responses: np.ndarray, clinic: np.ndarray, phases: np.ndarray) -> float:
    """The focal pressure through the patient's skull (``responses``: each element's at the target)
    when the clinic drives its reference steering minus ``phases``, over the most any phases give."""
    return float(np.abs(np.sum(responses * np.exp(1j * (clinic - phases)))) / np.sum(np.abs(responses)))


def run(a: argparse.Namespace) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(a.keep or tmp)
        d.mkdir(parents=True, exist_ok=True)
        f = lambda name: str(d / name)  # noqa: E731
        scenarios(d, a)
        t0 = time.perf_counter()
        assert (
            arfi_main(
                [
                    "predict",
                    "--scenario",
                    f("head.toml"),
                    "--out",
                    f("prior.npy"),
                    "--json",
                    f("prediction.json"),
                    "--no-focal-metrics",
                    *(["--pose-sensitivity"] if a.pose else []),
                ]
            )
            == 0
        )
        predict_s = time.perf_counter() - t0
        clinic = np.asarray(json.loads((d / "prediction.json").read_text())["reference_steering_rad"])
        images = world_images(d, clinic)
        common = [
            "estimate",
            "--scenario",
            f("model.toml"),
            "--groups",
            str(a.elements),
            *images,
            "--prior",
            f("prior.npy"),
            "--prior-std-rad",
            str(a.prior_std_rad),
            "--prior-transmission",
            f("prediction.json"),
            "--fit-nuisance",
            "amplitude",
        ]
        t0 = time.perf_counter()
        assert arfi_main([*common, "--out-phases", f("bone.npy"), "--json", f("bone.json")]) == 0
        estimate_s = time.perf_counter() - t0
        if a.pose:
            assert (
                arfi_main(
                    [
                        *common,
                        "--prior-pose-std-mm",
                        "1.5",
                        "--prior-pose-std-deg",
                        "1.5",
                        "--out-phases",
                        f("pose.npy"),
                        "--json",
                        f("pose.json"),
                    ]
                )
                == 0
            )
        truth = predict(Scenario.load(d / "patient.toml"))
        fraction = lambda phases: focus_fraction(truth.skull_responses, clinic, phases)  # noqa: E731
        bone = json.loads((d / "bone.json").read_text())
        bone_result = {
            "bone_speed_only": fraction(np.load(d / "bone.npy")),
            "bone_speed_only_estimate": fraction(np.asarray(bone["phases_rad"])),
            "bone_recommended": bone["recommended"],
            "bone_evidence": bone["prior_modes_fit"]["evidence_chi2"],
            "bone_prior_check": bone.get("prior_check"),
            "bone_supported": bone["prior_modes_fit"]["supported"],
            "bone_speed_percent": bone.get("bone_speed_fit", {}).get("percent"),
        }
        common_result = {
            "seed": a.seed,
            "frequency_hz": a.frequency_hz,
            "target_mm": a.target_mm,
            "shift_mm": a.shift_mm,
            "turn_deg": a.turn_deg,
            "bone_percent": a.bone_percent,
            "uncorrected": fraction(np.zeros(a.elements)),
            "prediction": fraction(np.load(d / "prior.npy")),
            **bone_result,
            "predict_s": predict_s,
            "estimate_s": estimate_s,
            "date": _dt.date.today().isoformat(),
        }
        if not a.pose:
            return common_result
        pose = json.loads((d / "pose.json").read_text())
        fitted = pose["prior_modes_fit"]["pose"]
        z = [
            (v - s) / e
            for v, s, e in zip(
                fitted["shift_mm"] + fitted["turn_deg"],
                list(a.shift_mm) + list(a.turn_deg),
                fitted["shift_std_mm"] + fitted["turn_std_deg"],
            )
        ]
        return {
            **common_result,
            "seed": a.seed,
            "frequency_hz": a.frequency_hz,
            "target_mm": a.target_mm,
            "shift_mm": a.shift_mm,
            "turn_deg": a.turn_deg,
            "bone_percent": a.bone_percent,
            "uncorrected": fraction(np.zeros(a.elements)),
            "estimate": fraction(np.load(d / "pose.npy")),
            "recommended": pose["recommended"],
            "flags": {k: pose[k] for k in ("ambiguous", "model_mismatch") if k in pose},
            "fitted_pose": fitted,
            "pose_error_in_std": z,
            "supported": pose["prior_modes_fit"]["supported"],
            "evidence_chi2": pose["prior_modes_fit"]["evidence_chi2"],
        }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("--shift-mm", type=float, nargs=3, default=[1.5, 0.0, 0.0])
    p.add_argument("--turn-deg", type=float, nargs=3, default=[0.0, 0.0, 0.0])
    p.add_argument("--bone-percent", type=float, default=10.0)
    p.add_argument("--frequency-hz", type=float, default=220000.0)
    p.add_argument("--target-mm", type=float, nargs=3, default=[12.0, -6.0, 138.0])
    p.add_argument("--elements", type=int, default=256)
    p.add_argument("--voxel-mm", type=float, default=1.0)
    p.add_argument("--prior-std-rad", type=float, default=0.3)
    p.add_argument(
        "--no-pose", dest="pose", action="store_false", help="the bone speed's fit alone (the default estimate)"
    )
    p.add_argument("--keep", metavar="DIR", help="write the case's files (CT, prediction, images, estimates) to DIR")
    p.add_argument("--json", help="append the result as one JSON line")
    a = p.parse_args()
    r = run(a)
    check = r["bone_prior_check"]
    head = (
        f"seed {r['seed']} at {a.frequency_hz / 1e3:g} kHz, shift {a.shift_mm} mm, turn {a.turn_deg} deg, bone "
        f"{a.bone_percent:+g} %: uncorrected {r['uncorrected']:.3f}, prediction {r['prediction']:.3f}, bone speed "
        f"alone {r['bone_speed_only']:.3f} ({r['bone_recommended']}; its estimate {r['bone_speed_only_estimate']:.3f}, "
        f"the modes' chi-squared fall {r['bone_evidence']:.1f}; the images at the prediction "
        + (
            "not checked"
            if check is None
            else f"{check['z']:+.1f} std from the prior's null, conflict {check['conflict']}"
        )
        + ")"
    )
    if not a.pose:
        print(
            f"{head}; bone {r['bone_speed_percent']}; predict {r['predict_s']:.1f} s, estimate {r['estimate_s']:.1f} s"
        )
    else:
        print(
            f"{head}, pose and bone speed {r['estimate']:.3f} ({r['recommended']}; supported {r['supported']}, "
            f"chi-squared falls by {r['evidence_chi2']:.1f}); fitted pose off the truth by "
            f"{', '.join(f'{v:+.1f}' for v in r['pose_error_in_std'])} std; bone {r['bone_speed_percent']}; predict "
            f"{r['predict_s']:.1f} s, estimate {r['estimate_s']:.1f} s"
        )
    if a.json:
        with open(a.json, "a", encoding="utf-8") as fh:
            fh.write(json.dumps(r) + "\n")


if __name__ == "__main__":
    main()
