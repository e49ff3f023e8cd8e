"""``arfi predict`` and ``Simulation.predict``: the CT-based prediction of each element's aberration."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from arfi.analysis.prediction import DRIVE_LABELS, compared_drives, compared_section, focal_metrics, predict
from arfi.cli import main
from arfi.scenario import Scenario
from arfi.simulation import Simulation

#: The focal metrics' keys, as arfi field's JSON names them.
FOCAL_KEYS = {
    "target_mm",
    "focal_peak_mm",
    "focal_peak_pa",
    "peak_to_target_mm",
    "fwhm_6db_mm",
    "fwhm_6db_across_mm",
    "fwhm_3db_mm",
    "focal_volume_6db_mm3",
    "isppa_w_cm2",
    "mechanical_index",
    "focal_tissue",
}


@pytest.fixture(scope="module")
def head(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The head phantom (2 mm voxels) in the hemisphere, at 220 kHz with 256 elements to keep the
    tests short; the scenario file is ``head.toml`` in the returned folder."""
    d = tmp_path_factory.mktemp("head")
    assert (
        main(
            [
                "phantom",
                "--out",
                str(d / "head.nii.gz"),
                "--scenario-out",
                str(d / "head.toml"),
                "--voxel-mm",
                "2",
                "--array",
                "hemisphere",
            ]
        )
        == 0
    )
    text = (d / "head.toml").read_text()
    (d / "head.toml").write_text(
        text.replace("frequency_hz = 650000.0", "frequency_hz = 220000.0").replace("elements = 1024", "elements = 256")
    )
    return d


def test_cli_predict_writes_the_prior_and_the_focal_pressures(head, tmp_path, capsys):
    out, js = tmp_path / "prior.npy", tmp_path / "prediction.json"
    assert main(["predict", "--scenario", str(head / "head.toml"), "--out", str(out), "--json", str(js)]) == 0
    printed = capsys.readouterr().out
    assert "predict: 256 elements" in printed
    # Asking for a file changes no printed line (the sensitivity and the focal metrics are computed
    # either way; only the times differ).
    assert main(["predict", "--scenario", str(head / "head.toml"), "--out", str(tmp_path / "again.npy")]) == 0
    again = capsys.readouterr().out

    def untimed(text: str) -> list[str]:
        return [re.sub(r" in [0-9.]+ s$", "", line).replace("again.npy", "prior.npy") for line in text.splitlines()]

    assert untimed(again) == untimed(printed) and "bone speed sensitivity" in again and "focus in 3-D" in again
    phases = np.load(out)
    result = json.loads(js.read_text())
    assert phases.shape == (256,) and np.allclose(phases, result["phases_rad"])
    assert np.all(np.abs(phases) <= np.pi + 1e-12)
    p = result["focal_pressure_pa"]
    # The skull aberrates and attenuates; the predicted phases bring back the best focus the skull
    # allows (the model's own optimum, sum |h|, to within 10 %), better than straight rays.
    assert p["uncorrected"] < p["corrected"] <= p["optimal"] * (1 + 1e-9) < p["reference"]
    assert p["corrected"] >= 0.9 * p["optimal"] and p["corrected"] >= p["ray_steering"], p
    # Straight rays through the head without bone nearly focus it (about 0.99 at 220 kHz; 0.95 asserted).
    assert 0.95 * p["reference_optimal"] <= p["reference"] <= p["reference_optimal"] * (1 + 1e-9), p
    t = np.array(result["transmission"])
    assert t.shape == (256,) and 0.02 < t.mean() < 1.0
    # The focal metrics of each drive compared (on by default with --json), in arfi field's keys.
    metrics = result["focal_metrics"]
    assert set(metrics) == {"uncorrected", "ray_steering", "corrected"}
    for name, m in metrics.items():
        assert set(m) == FOCAL_KEYS and m["target_mm"] == result["target_mm"], name
        # Two computations that share nothing but the plan: the peak of the forward march's box
        # (sub-voxel) and the transposed march's |p| at the target (to the rounding of the
        # single-precision projection). The peak is the local maximum, so at least the target's
        # |p| (1e-4: the trilinear interpolation at the target against the peak's parabola); the
        # peak lies within 1 mm of the target, across a -6 dB lobe 5 mm wide and 15 mm long, so
        # the target keeps at least 95 % of it.
        assert p[name] * (1 - 1e-4) <= m["focal_peak_pa"] <= p[name] / 0.95, (name, m, p)
        assert m["peak_to_target_mm"] < 1.0 and m["focal_tissue"] == "brain", (name, m)
        # I_SPPA and MI by hand at the peak, in brain (1546 m/s, 1040 kg/m3) at 220 kHz.
        assert m["mechanical_index"] == pytest.approx(m["focal_peak_pa"] / 1e6 / np.sqrt(0.22), rel=1e-12)
        assert m["isppa_w_cm2"] == pytest.approx(m["focal_peak_pa"] ** 2 / (2 * 1040.0 * 1546.0) * 1e-4, rel=1e-12)
    # The corrected beam peaks highest, and at the target: within 0.5 mm (a quarter of a voxel). The
    # hemisphere centred on its target puts every drive's peak within about 0.2 mm of it at 220 kHz,
    # so which of them lies nearest is a matter of hundredths of a millimetre, not asserted.
    assert metrics["corrected"]["peak_to_target_mm"] < 0.5
    assert metrics["corrected"]["focal_peak_pa"] >= max(m["focal_peak_pa"] for m in metrics.values())
    for name in ["uncorrected", "straight-ray CT steering", "corrected"]:
        assert f"predict: {name}: focus in 3-D: " in printed
    assert (
        main(
            [
                "predict",
                "--scenario",
                str(head / "head.toml"),
                "--out",
                str(out),
                "--json",
                str(js),
                "--no-focal-metrics",
                "--no-bone-speed-sensitivity",
            ]
        )
        == 0
    )
    assert "focal_metrics" not in json.loads(js.read_text()) and "focus in 3-D" not in capsys.readouterr().out


def test_predicted_phases_applied_by_the_forward_march_give_the_predicted_focus(head):
    # The prediction sums reciprocal responses; the forward march of the whole array with the
    # correction added must give the same focal pressure (to 1e-4: single-precision Rayleigh sums).
    scenario = Scenario.load(head / "head.toml")
    p, sim = predict(scenario, keep_simulation=True), Simulation(scenario)
    f = sim.field(p.correction_rad(sim.steering_phases_rad), p.target_mm[2])
    i, j = np.argmin(np.abs(f.x_mm - p.target_mm[0])), np.argmin(np.abs(f.y_mm - p.target_mm[1]))
    assert abs(abs(f.pressure[j, i]) - p.corrected_pa) < 1e-4 * p.corrected_pa
    # The kept simulation is the skull's: the same march as a fresh one, to the bit.
    kept = p.simulation.field(p.correction_rad(sim.steering_phases_rad), p.target_mm[2])
    assert np.array_equal(kept.pressure, f.pressure)
    # Its scenario is the one it was built from: the head's, with the ARFI amplitude given (a
    # prediction makes no ideal image to calibrate it from).
    built_from = p.simulation.scenario.to_dict()
    assert built_from["arfi"]["amplitude_rad_m3_per_n"] == 1.0 and built_from["ct"] == scenario.to_dict()["ct"]
    assert predict(scenario).simulation is None
    with pytest.raises(ValueError, match="target_mm"):
        predict(scenario, [0.0, 1.0])
    # A target between grid points is predicted where it is (the fields interpolated there), and
    # its own correction focuses there about as well as the focus's does at the focus. The
    # correction is relative to the reference steered toward the target itself: relative to the
    # focus's steering it leaves about 0.987 of the target's optimum, relative to the target's own
    # about 0.999, so the tolerance 0.995 tells the two apart.
    off = predict(scenario, [0.3, -0.2, 150.4])
    assert off.target_mm == (0.3, -0.2, 150.4)
    assert off.corrected_pa >= 0.97 * p.corrected_pa
    assert off.corrected_pa >= 0.995 * off.optimal_pa, (off.corrected_pa, off.optimal_pa)


def test_cli_predict_refuses_a_scenario_without_ct_and_a_bad_out(tmp_path, capsys):
    out = tmp_path / "prior.npy"
    assert main(["predict", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "[ct]" in err, err
    assert main(["predict", "--out", str(tmp_path / "prior.txt")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--out" in err, err
    assert not out.exists() and not (tmp_path / "prior.txt").exists()


def test_section_through_the_target_gives_the_predicted_focal_pressures(head):
    # The x-z section is a forward march recorded row by row; at the target it must give the focal
    # pressures the prediction sums from reciprocal responses (to 1e-4: single-precision Rayleigh
    # sums), for several drives marched in one batch.
    scenario = Scenario.load(head / "head.toml")
    p, sim = predict(scenario), Simulation(scenario)
    drives = [p.reference_steering_rad - sim.steering_phases_rad, p.correction_rad(sim.steering_phases_rad)]
    s = sim.section(drives, y_mm=p.target_mm[1])
    assert s.pressure.shape == (2, s.z_mm.size, s.x_mm.size) == (2,) + s.sound_speed_m_s.shape
    n, i = np.argmin(np.abs(s.z_mm - p.target_mm[2])), np.argmin(np.abs(s.x_mm - p.target_mm[0]))
    for k, expected in enumerate([p.uncorrected_pa, p.corrected_pa]):
        assert abs(abs(s.pressure[k, n, i]) - expected) < 1e-4 * expected
    # the skull's bone is on the section, faster than any soft tissue
    assert s.sound_speed_m_s.max() > 2000.0 and s.sound_speed_m_s.min() >= 1400.0
    with pytest.raises(ValueError, match="y_mm"):
        sim.section(y_mm=1e4)


def test_a_scenario_steered_without_bone_is_not_said_to_have_ct_steering(head, tmp_path, capsys):
    # Its straight-ray steering leaves the bone out: the same drive as "uncorrected", and named so
    # (not a second "CT steering" line with the same numbers).
    text = (head / "head.toml").read_text().replace("[ct]\n", "[ct]\nsteer_without_bone = true\n")
    (tmp_path / "head.nii.gz").symlink_to(head / "head.nii.gz")
    (tmp_path / "patient.toml").write_text(text)
    args = ["predict", "--scenario", str(tmp_path / "patient.toml"), "--out", str(tmp_path / "p.npy")]
    assert main([*args, "--no-bone-speed-sensitivity", "--focal-metrics"]) == 0
    out = capsys.readouterr().out
    assert "the same with the scenario's straight-ray steering (it leaves the bone out" in out, out
    assert "straight-ray CT steering" not in out, out
    assert "predict: straight-ray steering without bone (the uncorrected drive): focus in 3-D" in out, out


def test_a_patient_steered_without_bone_is_driven_as_the_prediction_assumes(head, tmp_path, capsys):
    # [ct] steer_without_bone: the bone stays, the steering is the prediction's reference, so the
    # scenario's own field is the uncorrected focus and --correction with the prior the corrected one.
    text = (head / "head.toml").read_text().replace("[ct]\n", "[ct]\nsteer_without_bone = true\n")
    (tmp_path / "head.nii.gz").symlink_to(head / "head.nii.gz")
    (tmp_path / "patient.toml").write_text(text)
    scenario = Scenario.load(tmp_path / "patient.toml")
    sim, p = Simulation(scenario), predict(scenario)
    # (the same steering as the head's prediction; the focal pressures below are the patient's own
    # prediction's, since a HAS plan depends slightly, 0.2 % here, on the beam it is built for)
    assert np.array_equal(sim.steering_phases_rad, predict(Scenario.load(head / "head.toml")).reference_steering_rad)
    assert np.array_equal(sim.steering_phases_rad, p.reference_steering_rad)
    np.save(tmp_path / "prior.npy", p.phases_rad)
    prior = str(tmp_path / "prior.npy")
    # the correction with the same phases added cancels: the uncorrected focus again
    for extra, expected in [
        ([], p.uncorrected_pa),
        (["--correction", prior], p.corrected_pa),
        (["--correction", prior, "--phases", prior], p.uncorrected_pa),
    ]:
        assert (
            main(
                [
                    "field",
                    "--scenario",
                    str(tmp_path / "patient.toml"),
                    "--out",
                    str(tmp_path / "f.npz"),
                    "--z-mm",
                    str(p.target_mm[2]),
                    *extra,
                ]
            )
            == 0
        )
        f = np.load(tmp_path / "f.npz")
        i, j = np.argmin(np.abs(f["x_mm"] - p.target_mm[0])), np.argmin(np.abs(f["y_mm"] - p.target_mm[1]))
        assert abs(abs(f["pressure"][j, i]) - expected) < 1e-4 * expected, extra
    assert (
        main(
            [
                "field",
                "--scenario",
                str(tmp_path / "patient.toml"),
                "--out",
                str(tmp_path / "f.npz"),
                "--correction",
                str(tmp_path / "missing.npy"),
            ]
        )
        == 2
    )
    assert "--correction" in capsys.readouterr().err


def test_cli_predict_report_draws_the_beams_and_the_element_maps(head, tmp_path, capsys):
    report, js = tmp_path / "report", tmp_path / "p.json"
    assert (
        main(
            [
                "predict",
                "--scenario",
                str(head / "head.toml"),
                "--out",
                str(tmp_path / "prior.npy"),
                "--report",
                str(report),
                "--json",
                str(js),
                "--no-bone-speed-sensitivity",
            ]
        )
        == 0
    )
    for name in ["predict_section.png", "predict_elements.png", "report.html"]:
        assert (report / name).stat().st_size > 10_000, name
    out = capsys.readouterr().out
    assert out.splitlines()[-1] == f"predict: report -> {report / 'report.html'}"
    assert "MPa with straight-ray CT steering" in out
    # The report's march gives the focal metrics too: in the JSON and on the page, each drive's.
    metrics = json.loads(js.read_text())["focal_metrics"]
    assert set(metrics) == {"uncorrected", "ray_steering", "corrected"} and all(
        set(m) == FOCAL_KEYS for m in metrics.values()
    )
    page = (report / "report.html").read_text()
    assert all(f"{label}: focal metrics" in page for label in ["uncorrected", "straight-ray CT steering", "corrected"])
    assert (report / "predict_section.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The report and the focal metrics march the kept skull's simulation; without one the drives
    # they march say how to get it.
    p = predict(Scenario.load(head / "head.toml"))
    assert p.simulation is None
    with pytest.raises(ValueError, match="keep_simulation=True"):
        compared_drives(p)


def test_one_march_draws_the_section_and_gives_each_drives_focal_metrics(head):
    # compared_section marches the three drives once, recording the section and the focal box
    # together: the section is sim.section's (1e-9 of its peak: the same batch march) and each
    # drive's metrics are focal_metrics' (their own marches to the box: 1e-6, single-precision
    # sums in another order; the -6 dB volume to an eighth of a voxel).
    p = predict(Scenario.load(head / "head.toml"), keep_simulation=True)
    section, metrics = compared_section(p)
    drives = compared_drives(p)
    alone = p.simulation.section(list(drives.values()), y_mm=p.target_mm[1])
    peak = np.abs(alone.pressure).max()
    assert np.abs(section.pressure - alone.pressure).max() <= 1e-9 * peak and alone.focal_metrics is None
    expected = focal_metrics(p)
    assert list(metrics) == list(drives) == list(DRIVE_LABELS)
    for name, m in metrics.items():
        for key in ("focal_peak_pa", "peak_to_target_mm", "isppa_w_cm2", "mechanical_index"):
            assert getattr(m, key) == pytest.approx(getattr(expected[name], key), rel=1e-6, abs=1e-9), (name, key)
        # The -6 dB volume counts 2 x 2 x 2 sub-samples a voxel (dy = dx here): one flipped by a
        # rounding moves it by an eighth of a voxel.
        dx, dz = section.x_mm[1] - section.x_mm[0], section.z_mm[1] - section.z_mm[0]
        assert abs(m.focal_volume_6db_mm3 - expected[name].focal_volume_6db_mm3) <= dx * dx * dz / 8 + 1e-9, name
        assert np.allclose(m.focal_peak_mm, expected[name].focal_peak_mm, atol=1e-6)
        assert m.target_mm == expected[name].target_mm and m.focal_tissue == expected[name].focal_tissue
    with pytest.raises(ValueError, match="target_mm"):
        p.simulation.section(y_mm=0.0, target_mm=(0.0, 0.0, -500.0))


def test_the_bone_speed_sensitivity_predicts_a_prediction_with_faster_bone(head, tmp_path, capsys):
    # predict's bone speed sensitivity: per element, rad per percent of the conversion's bone sound
    # speed (a +10 % difference through the wave model). Five times it must give the change to a
    # prediction made with bone 5 % faster: the phase through bone is close to linear in the
    # speed over 5 %; tolerance 25 % of that change's weighted RMS (at 220 kHz the change is about
    # 0.013 rad RMS and predicted to about 8 % of it; the 650 kHz head moves about three times as much).
    # On by default with the porosity conversion (the default one).
    js = tmp_path / "prediction.json"
    assert (
        main(["predict", "--scenario", str(head / "head.toml"), "--out", str(tmp_path / "p.npy"), "--json", str(js)])
        == 0
    )
    assert "bone speed sensitivity" in capsys.readouterr().out
    d = json.loads(js.read_text())
    g = np.asarray(d["bone_speed_sensitivity_rad_per_percent"])
    scenario = Scenario.load(head / "head.toml")
    faster = scenario.to_dict()
    faster["ct"]["bone_sound_speed_m_s"] = faster["ct"].get("bone_sound_speed_m_s", 2900.0) * 1.05  # 2900: aubry2003's
    moved = predict(Scenario.from_dict(faster, scenario.base_dir))
    w = np.abs(np.asarray(d["transmission"]))
    change = np.angle(np.exp(1j * (moved.phases_rad - np.asarray(d["phases_rad"]))))
    change -= np.angle(np.sum(w * np.exp(1j * change)))
    rms = lambda v: float(np.sqrt(np.average(v**2, weights=w)))  # noqa: E731
    err = rms(change - 5 * g)
    print(f"bone +5 %: change {rms(change):.3f} rad RMS, 5 x sensitivity {rms(5 * g):.3f}, difference {err:.3f}")
    assert g.shape == (256,) and rms(change) > 0.005 and err < 0.25 * rms(change), (err, rms(change))
    assert "bone_speed_sensitivity_rad_per_percent" not in predict(scenario).to_dict()
    assert (
        main(
            [
                "predict",
                "--scenario",
                str(head / "head.toml"),
                "--out",
                str(tmp_path / "p.npy"),
                "--json",
                str(js),
                "--no-bone-speed-sensitivity",
            ]
        )
        == 0
    )
    assert "bone_speed_sensitivity_rad_per_percent" not in json.loads(js.read_text())


def test_a_mode_is_fitted_on_the_head_with_its_bone(head):
    # Scenario.with_ct_bone: the CT read with its bone, steered as without it (the reference
    # steering). Simulation.fit_mode on images that model makes itself with a mode at a known
    # coefficient (three images, 0.02 rad noise) must find it within three of its own posterior
    # standard deviations, allowing for the prior's pull towards zero (a factor 1 / (1 + std^2));
    # a mode of the wrong length and a scenario without [ct] are named.
    skull = Simulation(Scenario.load(head / "head.toml").with_ct_bone(), groups=256)
    ct = skull.scenario.to_dict()["ct"]
    assert ct["steer_without_bone"] is True and ct["without_bone"] is False
    rng = np.random.default_rng(5)
    mode = np.convolve(rng.normal(size=256 + 15), np.ones(16) / 4.0, mode="valid")  # smooth, about 1 rad RMS
    known = [None] + [skull.focus_shift_phases((0.0, 0.0, dz)) for dz in (5.0, -5.0)]
    images = [skull.arfi_image(0.7 * mode + (0 if k is None else k), 0.02, i + 1) for i, k in enumerate(known)]
    fit = skull.fit_mode(images, known, mode)
    assert abs(fit.coefficient - 0.7 / (1 + fit.std**2)) < 3 * fit.std and fit.std < 0.3, fit
    assert 0.8 < fit.misfit < 1.2 and len(fit.tried) >= 4, fit
    with pytest.raises(ValueError, match="mode"):
        skull.fit_mode(images, known, mode[:5])
    with pytest.raises(ValueError, match=r'^scenario "vyas2014-phantom": has no \[ct\]: a model with the CT'):
        Scenario.default().with_ct_bone()


def test_predict_targets_equals_one_prediction_per_target(head, tmp_path, capsys):
    # Three targets from one plan of each head: each equals arfi.predict at that target to the
    # last bit (the same marches through the same plans); the CLI's --targets writes a row of
    # phases per target and the JSON a list of single predictions' keys.
    import arfi

    scenario = Scenario.load(head / "head.toml")
    focus = scenario.to_dict()["focus"]["position_mm"]
    targets = [focus, [focus[0] + 8.0, focus[1] - 5.0, focus[2]], [focus[0], focus[1] + 6.0, focus[2] + 10.0]]
    seen: list[tuple[int, int]] = []
    many = arfi.predict_targets(
        scenario, targets, bone_speed_sensitivity=True, progress=lambda d, t: seen.append((d, t))
    )
    assert seen[-1] == (9, 9) and len(seen) == 9  # per target: faster bone, reference and skull marches
    for target, p in zip(targets, many):
        alone = predict(scenario, target, bone_speed_sensitivity=True)
        assert p.target_mm == pytest.approx(target, abs=1e-9)
        assert np.array_equal(p.phases_rad, alone.phases_rad) and np.array_equal(p.transmission, alone.transmission)
        assert p.to_dict() == alone.to_dict()
    csv = tmp_path / "targets.csv"
    csv.write_text("name,x_mm,y_mm,z_mm\n" + "".join(f"t{k},{x},{y},{z}\n" for k, (x, y, z) in enumerate(targets[:2])))
    out, js = tmp_path / "p.npy", tmp_path / "p.json"
    argv = [
        "predict",
        "--scenario",
        str(head / "head.toml"),
        "--out",
        str(out),
        "--json",
        str(js),
        "--targets",
        str(csv),
    ]
    assert main([*argv, "--no-bone-speed-sensitivity"]) == 0
    printed = capsys.readouterr().out
    assert "predict: 2 targets, 256 elements, one plan of each head" in printed
    assert "predict: target 1 (" in printed and "predict: target 1: corrected: focus in 3-D" in printed
    rows = np.load(out)
    assert rows.shape == (2, 256) and np.array_equal(rows[1], many[1].phases_rad)
    result = json.loads(js.read_text())
    assert np.allclose([e["target_mm"] for e in result["targets"]], targets[:2])
    assert set(result["targets"][0]["focal_metrics"]) == {"uncorrected", "ray_steering", "corrected"}
    assert result["targets"][1]["focal_pressure_pa"] == pytest.approx(many[1].to_dict()["focal_pressure_pa"])


@pytest.mark.parametrize(
    "content, expected",
    [
        ("", "holds no targets"),
        ("x_mm,y_mm\n1,2\n", "lacks z_mm"),
        ("x_mm,y_mm,z_mm\n", "holds no targets below its header"),
        ("x_mm,y_mm,z_mm\n0,0,abc\n", "line 2: needs a number"),
        ("x_mm,y_mm,z_mm\n0,0,nan\n", "line 2: the target must be finite"),
        ("x_mm,y_mm,z_mm\n0,0,150\n0,0,-50\n", "target 1 (0.0, 0.0, -50.0) mm lies outside the grid"),
        ("x_mm,y_mm,z_mm\n0,0,150\n110,0,150\n", "target 1 (110.0, 0.0, 150.0) mm lies outside the CT"),
    ],
)
def test_a_bad_targets_file_is_one_line_and_nothing_written(head, tmp_path, capsys, content, expected):
    csv = tmp_path / "targets.csv"
    csv.write_text(content)
    out = tmp_path / "p.npy"
    argv = ["predict", "--scenario", str(head / "head.toml"), "--out", str(out), "--targets", str(csv)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("arfi: error: --targets: ") and expected in err and "\n" not in err, err
    assert not out.exists()


def test_targets_are_refused_with_a_single_target_or_a_report(head, tmp_path, capsys):
    csv = tmp_path / "targets.csv"
    csv.write_text("x_mm,y_mm,z_mm\n0,0,150\n")
    base = ["predict", "--scenario", str(head / "head.toml"), "--out", str(tmp_path / "p.npy"), "--targets", str(csv)]
    assert main([*base, "--target-mm", "0", "0", "150"]) == 2
    assert "--targets: not with --target-mm" in capsys.readouterr().err
    assert main([*base, "--report", str(tmp_path / "r")]) == 2
    assert "--targets: not with --report" in capsys.readouterr().err
    with pytest.raises(ValueError, match="targets_mm: must be points"):
        predict_targets_of(head, [[0.0, 0.0]])


def predict_targets_of(head, targets):
    import arfi

    return arfi.predict_targets(Scenario.load(head / "head.toml"), targets)
