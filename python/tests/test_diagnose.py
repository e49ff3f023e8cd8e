"""``arfi diagnose`` (SPEC §5, §7): the JSON keys and the paper's broadening story end to end."""

import json

import pytest

import arfi
from arfi.cli import main


def test_cli_diagnose_names_the_missing_broadening(tmp_path):
    # The paper's story: a model without broadening (W = 0, calibration file) meets an image
    # with W = 2.7 mm; the workflow names `broadening` with W within 0.2 mm and stops.
    sim = arfi.Simulation()
    image = tmp_path / "m.nii.gz"
    assert main(["simulate", "--noise-rad", "0.02", "--seed", "5", "--out", str(image)]) == 0
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"broadening_width_mm": 0.0, "amplitude": sim.amplitude}))
    js = tmp_path / "d.json"
    assert main(["diagnose", "--image", str(image), "--calibration", str(cal), "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    for key in ("effects", "cost_initial", "cost_final", "noise_floor"):
        assert key in d
    assert [e["name"] for e in d["effects"]] == ["broadening"]
    e = d["effects"][0]
    assert set(e) >= {"name", "params", "cost_before", "cost_after", "evidence"}
    assert e["params"]["broadening_width_mm"] == pytest.approx(2.7, abs=0.2)
    assert d["cost_final"] < d["cost_initial"] and d["residual_rms_final"] < 1.2 * d["noise_floor"]


def test_diagnose_on_noise_only_names_nothing_and_rejects_bad_input(sim):
    d = sim.diagnose(sim.arfi_image(noise_rad=0.02, seed=11))
    assert d.names == [] and len(d.rejected) == 5
    with pytest.raises(ValueError, match="image"):
        sim.diagnose(sim.arfi_image()[:10])
    assert sim.diagnose(sim.arfi_image()).names == []  # noise-free and the exact model: nothing to add
    with pytest.raises(ValueError, match="threshold"):
        sim.diagnose(sim.arfi_image(noise_rad=0.02), threshold=float("nan"))


def test_cli_diagnose_bad_input_is_one_line_exit_2(tmp_path, capsys):
    assert main(["diagnose", "--image", str(tmp_path / "missing.nii.gz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("arfi: error:")
    assert not list(tmp_path.iterdir())
