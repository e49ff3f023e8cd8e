"""``arfi predict`` and ``Simulation.predict``: the CT-based prediction of each element's aberration."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from arfi.cli import main
from arfi.prediction import predict
from arfi.scenario import Scenario
from arfi.simulation import Simulation


@pytest.fixture(scope="module")
def head(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The head phantom (2 mm voxels) in the hemisphere, at 220 kHz with 256 elements to keep the
    tests short; the scenario file is ``head.toml`` in the returned folder."""
    d = tmp_path_factory.mktemp("head")
    assert main(["phantom", "--out", str(d / "head.nii.gz"), "--scenario-out", str(d / "head.toml"), "--voxel-mm", "2",
                 "--array", "hemisphere"]) == 0
    text = (d / "head.toml").read_text()
    (d / "head.toml").write_text(text.replace("frequency_hz = 650000.0", "frequency_hz = 220000.0")
                                 .replace("elements = 1024", "elements = 256"))
    return d


def test_cli_predict_writes_the_prior_and_the_focal_pressures(head, tmp_path, capsys):
    out, js = tmp_path / "prior.npy", tmp_path / "prediction.json"
    assert main(["predict", "--scenario", str(head / "head.toml"), "--out", str(out), "--json", str(js)]) == 0
    assert "predict: 256 elements" in capsys.readouterr().out
    phases = np.load(out)
    result = json.loads(js.read_text())
    assert phases.shape == (256,) and np.allclose(phases, result["phases_rad"])
    assert np.all(np.abs(phases) <= np.pi + 1e-12)
    p = result["focal_pressure_pa"]
    # The skull aberrates and attenuates; the predicted phases bring back the best focus the skull
    # allows (the model's own optimum, sum |h|, to within 10 %), better than straight rays.
    assert p["uncorrected"] < p["corrected"] <= p["optimal"] * (1 + 1e-9) < p["reference"]
    assert p["corrected"] >= 0.9 * p["optimal"] and p["corrected"] >= p["ray_steering"], p
    t = np.array(result["transmission"])
    assert t.shape == (256,) and 0.02 < t.mean() < 1.0


def test_predicted_phases_applied_by_the_forward_march_give_the_predicted_focus(head):
    # The prediction sums reciprocal responses; the forward march of the whole array with the
    # correction added must give the same focal pressure (to 1e-4: single-precision Rayleigh sums).
    scenario = Scenario.load(head / "head.toml")
    p, sim = predict(scenario), Simulation(scenario)
    f = sim.field(p.correction_rad(sim.steering_phases_rad), p.target_mm[2])
    i, j = np.argmin(np.abs(f.x_mm - p.target_mm[0])), np.argmin(np.abs(f.y_mm - p.target_mm[1]))
    assert abs(abs(f.pressure[j, i]) - p.corrected_pa) < 1e-4 * p.corrected_pa
    with pytest.raises(ValueError, match="target_mm"):
        predict(scenario, [0.0, 1.0])


def test_cli_predict_refuses_a_scenario_without_ct_and_a_bad_out(tmp_path, capsys):
    out = tmp_path / "prior.npy"
    assert main(["predict", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "[ct]" in err, err
    assert main(["predict", "--out", str(tmp_path / "prior.txt")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--out" in err, err
    assert not out.exists() and not (tmp_path / "prior.txt").exists()
