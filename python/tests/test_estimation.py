import json
import os
import subprocess
import sys

import numpy as np
import pytest

import arfi
from arfi.cli import main
from arfi.estimation import phase_error


def test_noise_free_single_image_is_recovered(sim, ideal):
    truth = sim.condense(sim.skull_phases(4))
    e = sim.estimate(sim.arfi_image(truth), method="lbfgs")
    # Noise-free and a perfect model: the global minimum is the truth (twin starts find it).
    assert phase_error(e.phases_rad, truth) < 0.01
    assert not e.ambiguous
    corrected = sim.arfi_image(truth - e.phases_rad)
    assert corrected.max() / ideal.max() > 0.99


def test_noisy_single_image_flags_a_bad_answer(sim, ideal):
    # One image at 0.02 rad often cannot decide between an aberration and its twin (phi(u) -> -phi(-u)
    # leaves an in-focus intensity image nearly unchanged); a poor answer must carry the flag.
    truth = sim.condense(sim.skull_phases(2))
    e = sim.estimate(sim.arfi_image(truth, noise_rad=0.02, seed=1))
    rec = sim.arfi_image(truth - e.phases_rad).max() / ideal.max()
    assert rec >= 0.9 or e.ambiguous
    assert e.noise_floor == pytest.approx(0.02, rel=0.1)
    assert e.suggested_phases_rad.shape == (16,)


def test_calibration_recovers_the_scenario_width(sim):
    c = sim.calibrate(sim.arfi_image(noise_rad=0.02, seed=3))
    assert c.broadening_width_mm == pytest.approx(2.7, abs=0.1)
    assert c.amplitude == pytest.approx(sim.amplitude, rel=0.02)
    # Widths beyond the MR field of view are not searched (they blur the image flat): a huge
    # max_width_mm gives the same width, in the time of the field of view's search (it took
    # minutes with 2**64 mm).
    assert sim.calibrate(sim.arfi_image(noise_rad=0.02, seed=3), None, 2**64).broadening_width_mm == pytest.approx(
        c.broadening_width_mm, abs=0.01
    )


def test_calibration_is_saved_loaded_and_applied_only_where_it_was_fitted(tmp_path, sim):
    c = sim.calibrate(sim.arfi_image(noise_rad=0.02, seed=4))
    assert (c.scenario, c.frequency_hz) == (sim.scenario.name, sim.frequency_hz)
    path = tmp_path / "cal.json"
    c.save(path)
    # Written whole with the user's umask (shared files, not a temporary file's 0600), keys as
    # `arfi calibrate --json`.
    assert path.stat().st_mode & 0o777 == 0o666 & ~_umask()
    assert list(json.loads(path.read_text())) == list(c.to_dict())
    back = arfi.Calibration.load(str(path))
    # Every value as written (the width through mm and back: within rounding).
    assert back.broadening_width_mm == pytest.approx(c.broadening_width_mm, rel=1e-15)
    assert {**back.to_dict(), "broadening_width_mm": 0} == {**c.to_dict(), "broadening_width_mm": 0}
    np.testing.assert_allclose(sim.calibrated(back).arfi_image(), sim.calibrated(c).arfi_image(), rtol=1e-12)
    # A hand-written calibration (W = 0: no broadening) records no fit and applies anywhere.
    hand = arfi.Calibration(0.0, sim.amplitude)
    assert (hand.cost, hand.n_pixels, hand.noise_rad, hand.scenario) == (None, None, None, None)
    # Its document leaves out what it does not record, as its file does.
    assert hand.to_dict() == {"broadening_width_mm": 0.0, "amplitude": sim.amplitude}
    hand.save(tmp_path / "hand.json")
    assert json.loads((tmp_path / "hand.json").read_text()) == hand.to_dict()
    (tmp_path / "hand.json").unlink()
    assert sim.calibrated(hand).arfi_image().max() > sim.calibrated(c).arfi_image().max()
    # Fitted for another scenario or frequency: refused, naming both.
    for other in (
        arfi.Calibration(2.7, sim.amplitude, scenario="other"),
        arfi.Calibration(2.7, sim.amplitude, frequency_hz=sim.frequency_hz / 2),
    ):
        with pytest.raises(ValueError, match=f'calibration: made for .* not scenario "{sim.scenario.name}"'):
            sim.calibrated(other)
    with pytest.raises(ValueError, match="calibration: must be an arfi.Calibration"):
        sim.calibrated({"broadening_width_mm": 2.7})  # type: ignore[arg-type]
    for bad, match in (
        ({"broadening_width_mm": -1.0, "amplitude": 1.0}, "broadening_width_mm: must be a finite number >= 0"),
        ({"broadening_width_mm": 1.0, "amplitude": 0.0}, "amplitude: must be a finite number > 0"),
        ({"broadening_width_mm": 1.0, "amplitude": 1.0, "frequency_hz": -5.0}, "frequency_hz"),
    ):
        with pytest.raises(ValueError, match=match):
            arfi.Calibration(**bad)
        path.write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=f"{path}: not a calibration file .*{match}"):
            arfi.Calibration.load(path)
    for text in ("[2.7, 1e-6]", "{", '{"amplitude": 1}'):
        path.write_text(text)
        with pytest.raises(ValueError, match="not a calibration file"):
            arfi.Calibration.load(path)
    with pytest.raises(FileNotFoundError, match="absent.json: no such file"):
        arfi.Calibration.load(tmp_path / "absent.json")
    # A save that cannot be made leaves nothing behind.
    with pytest.raises(FileNotFoundError, match="its folder does not exist"):
        c.save(tmp_path / "no" / "cal.json")
    with pytest.raises(ValueError, match="cannot write"):
        c.save(tmp_path)  # a folder
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal.json"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_estimate_rejects_bad_arguments(sim, ideal):
    with pytest.raises(ValueError, match="method"):
        sim.estimate(ideal, method="simplex")
    with pytest.raises(ValueError, match="images\\[0\\]"):
        sim.estimate(np.zeros(5))
    with pytest.raises(ValueError, match="shape"):
        sim.estimate(np.ones((10, 10)))
    with pytest.raises(ValueError, match="no positive pixel"):
        sim.estimate(np.zeros((128, 96)))
    with pytest.raises(ValueError, match="pixel"):
        sim.estimate(np.full((128, 96), np.nan))
    with pytest.raises(ValueError, match="known"):
        sim.estimate([ideal, ideal], known=[None])
    with pytest.raises(ValueError, match="max_evaluations"):
        sim.estimate(ideal, max_evaluations=0)


def test_cli_calibrate_then_estimate(tmp_path, sim):
    truth = sim.condense(sim.skull_phases(5))
    np.save(tmp_path / "ab.npy", truth)
    d = str(tmp_path)
    assert main(["simulate", "--noise-rad", "0.0", "--out", f"{d}/cal.nii.gz"]) == 0
    assert main(["calibrate", "--image", f"{d}/cal.nii.gz", "--json", f"{d}/cal.json"]) == 0
    cal = json.loads((tmp_path / "cal.json").read_text())
    assert cal["broadening_width_mm"] == pytest.approx(2.7, abs=0.02)
    assert main(["simulate", "--phases", f"{d}/ab.npy", "--noise-rad", "0", "--out", f"{d}/ab.nii.gz"]) == 0
    assert (
        main(
            [
                "estimate",
                "--image",
                f"{d}/ab.nii.gz",
                "--calibration",
                f"{d}/cal.json",
                "--groups",
                "16",
                "--method",
                "nelder-mead",
                "--json",
                f"{d}/e.json",
                "--out-phases",
                f"{d}/e.npy",
            ]
        )
        == 0
    )
    e = json.loads((tmp_path / "e.json").read_text())
    for key in ("phases_rad", "cost", "evaluations", "seconds", "ambiguous"):
        assert key in e
    assert len(e["phases_rad"]) == 16 and e["evaluations"] <= 8000
    np.testing.assert_allclose(np.load(tmp_path / "e.npy"), e["phases_rad"])


def test_cli_estimate_reads_known_phases_from_the_sidecar(tmp_path, sim):
    truth = sim.condense(sim.skull_phases(6))
    d = str(tmp_path)
    np.save(tmp_path / "ab.npy", truth)
    rng = np.random.default_rng(0)
    for k in range(3):
        np.save(tmp_path / f"d{k}.npy", rng.uniform(-np.pi, np.pi, 16))
        assert (
            main(
                [
                    "simulate",
                    "--phases",
                    f"{d}/ab.npy",
                    "--known-phases",
                    f"{d}/d{k}.npy",
                    "--noise-rad",
                    "0",
                    "--out",
                    f"{d}/m{k}.nii.gz",
                ]
            )
            == 0
        )
    args = ["estimate", "--json", f"{d}/e.json"] + sum([["--image", f"{d}/m{k}.nii.gz"] for k in range(3)], [])
    assert main(args) == 0
    e = json.loads((tmp_path / "e.json").read_text())
    assert phase_error(e["phases_rad"], truth) < 0.01


@pytest.mark.parametrize(
    "setup, args, match",
    [
        ("none", ["estimate", "--image", "{d}/absent.nii.gz"], "absent.nii.gz"),
        ("small", ["estimate", "--image", "{d}/small.nii.gz"], "shape"),
        ("nan", ["estimate", "--image", "{d}/nan.nii.gz"], "NaN"),
        ("zero", ["estimate", "--image", "{d}/zero.nii.gz"], "no positive pixel"),
        ("shifted", ["estimate", "--image", "{d}/shifted.nii.gz"], "affine"),
        ("badside", ["estimate", "--image", "{d}/badside.nii.gz"], "applied_phases_rad"),
        (
            "badcal",
            ["estimate", "--image", "{d}/good.nii.gz", "--calibration", "{d}/cal.json"],
            "--calibration: {d}/cal.json: made for scenario",
        ),
        ("none", ["estimate", "--image", "{d}/x.nii.gz", "--method", "simplex"], "invalid choice"),
        (
            "good",
            ["calibrate", "--image", "{d}/good.nii.gz", "--max-width-mm", "-1"],
            "max_width_mm: must be a finite number > 0",
        ),
    ],
)
def test_bad_estimation_input_is_one_line_exit_2(tmp_path, sim, ideal, setup, args, match):
    import nibabel as nib

    if setup != "none":
        good = ideal
        aff = sim.mr_affine_mm
        data = {
            "small": np.ones((10, 10, 1)),
            "nan": np.full((128, 96, 1), np.nan),
            "zero": np.zeros((128, 96, 1)),
            "shifted": good[:, :, None],
            "badside": good[:, :, None],
            "good": good[:, :, None],
            "badcal": good[:, :, None],
        }[setup]
        affine = aff.copy()
        if setup == "shifted":
            affine[0, 3] += 5.0
        name = "good" if setup == "badcal" else setup
        nib.save(nib.Nifti1Image(data.astype(np.float32), affine), str(tmp_path / f"{name}.nii.gz"))
        if setup == "badside":
            (tmp_path / "badside.json").write_text(json.dumps({"applied_phases_rad": [1.0, 2.0]}))
        if setup == "badcal":
            (tmp_path / "cal.json").write_text(
                json.dumps({"broadening_width_mm": 2.7, "amplitude": 1e-7, "scenario": "other"})
            )
    r = subprocess.run(
        [sys.executable, "-m", "arfi", *[a.format(d=tmp_path) for a in args]],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and match.format(d=tmp_path) in lines[0], r.stderr
