"""The clinical chain through a head, run as a user runs it (README, tutorial step 10): a head CT,
``arfi predict``, MR-ARFI images of a patient whose skull the CT gets wrong, ``arfi estimate`` with
the prediction as prior and its transmission (which first fits the prediction's bone-speed mode to
the images on the head with the CT's bone), and the corrected focus through the patient's skull.

The patient: bone 10 % faster than the CT conversion says and the head 1.5 mm off its
registration, driven with the clinic's reference steering (the prediction's, from the CT as
registered: ``arfi simulate --steering-from``), three images (in focus and defocused by ±5 mm) at
0.02 rad noise. Scored exactly at the target by the sum of each element's response through the
real skull (the patient's own prediction's ``skull_responses``) with that steering minus the
phases, as a fraction of the most any phases give there.

Tolerances: the images' 0.02 rad noise moves a per-element estimate by a few hundredths of a
radian around the prior; that costs a few thousandths of the focus, under 0.01, so the estimate
must never fall more than 0.01 below the prediction alone. 0.95 of the optimum is the chain's
required floor; the 220 kHz phantom's predictions reach 0.99.

1 mm CT voxels (clinical CTs have 0.5-1 mm) and 256 elements keep a seed to one CT phantom, one
prediction, three simulated images and one estimate; the default run takes head seed 0 (every
assertion holds per seed: no rate), ``ARFI_FULL_SWEEPS=1`` runs seeds 0-4 (docs/testing.md).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from arfi.analysis.prediction import predict
from arfi.cli import main
from arfi.scenario import Scenario
from arfi.simulation import Simulation

SEEDS = [0, 1, 2, 3, 4] if os.environ.get("ARFI_FULL_SWEEPS") else [0]


def head_scenarios(d: Path, seed: int) -> None:
    """Writes the tutorial's three scenarios for phantom ``seed`` at 220 kHz, 256 elements, the
    target at (10, 0, 140) mm: ``head.toml`` (the CT as read), ``patient.toml`` (the real head) and
    ``model.toml`` (the estimate's model: the head without its skull)."""
    assert (
        main(
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
                "1",
                "--seed",
                str(seed),
            ]
        )
        == 0
    )
    text = (
        (d / "head.toml")
        .read_text()
        .replace("elements = 1024", "elements = 256")
        .replace("frequency_hz = 650000.0", "frequency_hz = 220000.0")
        .replace("position_mm = [0.0, 0.0, 150.0]", "position_mm = [10.0, 0.0, 140.0]")
    )
    (d / "head.toml").write_text(text)
    (d / "patient.toml").write_text(
        text.replace("[ct]\n", "[ct]\nbone_sound_speed_m_s = 3190.0\nsteer_without_bone = true\n").replace(
            "[[1, 0, 0, 0]", "[[1, 0, 0, 1.5]"
        )
    )
    (d / "model.toml").write_text(text.replace("[ct]\n", "[ct]\nwithout_bone = true\n"))


def run_chain(d: Path, seed: int) -> dict[str, float]:
    """The tutorial's commands; returns the fractions of the optimum and the estimate's JSON."""
    head_scenarios(d, seed)
    f = lambda name: str(d / name)  # noqa: E731
    assert main(["predict", "--scenario", f("head.toml"), "--out", f("prior.npy"), "--json", f("prediction.json")]) == 0
    for k, shift in enumerate([None, "5", "-5"]):
        extra = [] if shift is None else ["--focus-shift-mm", "0", "0", shift]
        assert (
            main(
                [
                    "simulate",
                    "--scenario",
                    f("patient.toml"),
                    *extra,
                    "--steering-from",
                    f("prediction.json"),
                    "--noise-rad",
                    "0.02",
                    "--seed",
                    str(k + 1),
                    "--out",
                    f(f"a{k}.nii.gz"),
                ]
            )
            == 0
        )
    assert (
        main(
            [
                "estimate",
                "--scenario",
                f("model.toml"),
                "--groups",
                "256",
                "--image",
                f("a0.nii.gz"),
                "--image",
                f("a1.nii.gz"),
                "--image",
                f("a2.nii.gz"),
                "--prior",
                f("prior.npy"),
                "--prior-std-rad",
                "0.15",
                "--prior-transmission",
                f("prediction.json"),
                "--fit-nuisance",
                "amplitude",
                "--out-phases",
                f("estimate.npy"),
                "--json",
                f("estimate.json"),
            ]
        )
        == 0
    )
    truth = predict(Scenario.load(d / "patient.toml"))
    clinic = np.asarray(json.loads((d / "prediction.json").read_text())["reference_steering_rad"])

    # The clinic drives its reference steering (the CT's, as registered) minus the phases.
    def fraction(phases):
        return float(np.abs(np.sum(truth.skull_responses * np.exp(1j * (clinic - phases)))) / truth.optimal_pa)

    return {
        "uncorrected": fraction(np.zeros(256)),
        "prediction": fraction(np.load(d / "prior.npy")),
        "estimate": fraction(np.load(d / "estimate.npy")),
        **json.loads((d / "estimate.json").read_text()),
    }


@pytest.mark.parametrize("seed", SEEDS)
def test_the_chain_through_a_head_corrects_as_documented(tmp_path, capsys, seed):
    r = run_chain(tmp_path, seed)
    line = (
        f"seed {seed}: uncorrected {r['uncorrected']:.3f}, prediction {r['prediction']:.3f}, estimate "
        f"{r['estimate']:.3f} of the optimum; misfit {r['misfit']:.2f}, scale {r['nuisance']['scale']:.3f}; bone speed "
        f"{r['bone_speed_fit']['percent']:+.1f} +- {r['bone_speed_fit']['std_percent']:.1f} %"
    )
    out = capsys.readouterr().out
    print(line)
    # The images were fitted on the brain around the target, at their own scale: the skull's loss
    # is in the images already (both are calibrated at their own ideal focus), so the fitted
    # scale is about 1 (a model showing bone's force as displacement fitted the skull ring at a
    # scale of about 100).
    assert 0.7 < r["nuisance"]["scale"] < 1.4, line
    assert not r["model_mismatch"] and r["recommended"] == "estimate", line
    assert r["estimate"] >= 0.95 and r["estimate"] >= r["prediction"] - 0.01, line
    # The images find the patient's bone 10 % faster than the conversion (the prediction's JSON
    # gives its bone-speed mode, so the estimate fits it first on the head with the CT's bone):
    # within three of the fit's own standard deviations (over seeds 0-4 the fit lands within 1.3).
    bone = r["bone_speed_fit"]
    assert abs(bone["percent"] - 10.0) < 3.0 * bone["std_percent"], line
    # `simulate` reports the focus at the target, not a hotter place in the skull or scalp.
    for reported in [ln for ln in out.splitlines() if ln.startswith("simulate:")]:
        x, y, _ = (float(v) for v in reported.split(" at (")[1].split(")")[0].split(","))
        assert np.hypot(x - 10.0, y) <= 8.0, reported


def test_images_through_a_head_leave_the_bone_out(tmp_path, capsys):
    # The patient's in-focus image: bone pixels are NaN in the NIfTI, the focal maximum lies at the
    # target, and the brain around it is imaged. The model of the head without its skull leaves out
    # the same pixels as the head it was read from (bone is bone to the scanner whatever the
    # model's acoustics).
    head_scenarios(tmp_path, 1)
    image = tmp_path / "a.nii.gz"
    assert (
        main(["simulate", "--scenario", str(tmp_path / "patient.toml"), "--noise-rad", "0", "--out", str(image)]) == 0
    )
    data = np.squeeze(np.asarray(nib.load(str(image)).get_fdata()))
    patient = Simulation(Scenario.load(tmp_path / "patient.toml"))
    dark = ~patient.imaged
    assert dark.sum() > 100 and np.all(np.isnan(data[dark])) and np.all(np.isfinite(data[~dark]))
    as_read, model = (Simulation(Scenario.load(tmp_path / name)) for name in ("head.toml", "model.toml"))
    assert np.array_equal(model.imaged, as_read.imaged) and not as_read.imaged.all()
    value, (i, j) = patient.focal_arfi(data)
    x, y = (patient.mr_affine_mm @ np.array([i, j, 0, 1.0]))[:2]
    assert value == pytest.approx(0.6, abs=1e-6) and np.hypot(x - 10.0, y) < 4.0, (value, x, y)
    assert "focal ARFI phase 0.600 rad" in capsys.readouterr().out


def test_field_through_a_head_reports_the_focus_at_the_target(tmp_path, capsys):
    # The patient's field: the focal peak is the lobe at the target (within a pixel diagonal of
    # the 0.97 mm grid and a wavelength, 7 mm, along the axis at 220 kHz), and any hotter place is
    # named by what it is, never brain: the skull, the scalp or the water in front of the head.
    head_scenarios(tmp_path, 1)
    js = tmp_path / "f.json"
    assert (
        main(
            ["field", "--scenario", str(tmp_path / "patient.toml"), "--out", str(tmp_path / "f.npz"), "--json", str(js)]
        )
        == 0
    )
    out = capsys.readouterr().out
    r = json.loads(js.read_text())
    assert r["plane_peak_to_axis_mm"] < 1.5 and abs(r["axis_peak_z_mm"] - 140.0) < 7.0, r
    # In 3-D: within a wavelength of the target, in the brain, and not hotter than the axis and plane
    # samples allow (the refined peak is at most a few % above them).
    assert r["peak_to_target_mm"] < 7.0 and r["focal_tissue"] == "brain", r
    assert (
        max(r["plane_peak_pa"], r["axis_peak_pa"])
        <= r["focal_peak_pa"]
        < 1.1 * max(r["plane_peak_pa"], r["axis_peak_pa"])
    )
    hottest = [ln for ln in out.splitlines() if "hottest on the" in ln]
    for line in hottest:
        assert line.split("hottest on the ")[1].split(":")[1].split(",")[0].strip() in {"skull", "scalp", "water"}, line
    for key in ("plane", "axis"):
        assert (r[f"{key}_hottest_pa"] is None) == (f"{key}_hottest_tissue" not in r)
    # Each tissue's hottest place over the grid: the skull's and the scalp's are named, and the
    # brain's is a sample of the focal lobe (the peak, refined between samples, a few % above it as above).
    assert {"skull", "scalp", "brain"} <= set(r["hottest"]), r["hottest"]
    assert (
        r["hottest"]["brain"]["pressure_pa"]
        <= r["focal_peak_pa"] * (1 + 1e-6)
        < 1.1 * r["hottest"]["brain"]["pressure_pa"]
    )
    data = np.load(tmp_path / "f.npz")
    assert np.allclose(data["axis_x_mm"], data["axis_z_mm"] * 10.0 / 140.0)
