"""``arfi envelope``: the corrected focus over a grid of targets, the skull's cost, volumes on the CT."""

from __future__ import annotations

import json
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from arfi.analysis.envelope import COLUMNS, VOLUMES, box_targets, read_points, run_envelope
from arfi.analysis.prediction import compared_drives, focal_metrics, predict
from arfi.cli import main
from arfi.scenario import Scenario


@pytest.fixture(scope="module")
def head(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The head phantom (2 mm voxels) in the hemisphere at 220 kHz with 256 elements (as
    test_predict's): ``head.toml`` in the returned folder."""
    d = tmp_path_factory.mktemp("head")
    argv = ["phantom", "--out", str(d / "head.nii.gz"), "--scenario-out", str(d / "head.toml"), "--voxel-mm", "2"]
    assert main([*argv, "--array", "hemisphere"]) == 0
    text = (d / "head.toml").read_text()
    (d / "head.toml").write_text(
        text.replace("frequency_hz = 650000.0", "frequency_hz = 220000.0").replace("elements = 1024", "elements = 256")
    )
    return d


#: Three targets in the brain about the focus (0, 0, 150) and one in the skull above it.
TARGETS = [[0.0, 0.0, 150.0], [12.0, -8.0, 140.0], [-10.0, 14.0, 165.0]]
IN_SKULL = [0.0, 0.0, 90.0]


def test_box_targets_span_the_box_from_its_lowest_corner():
    t = box_targets([-10, 10, 0, 5, 100, 100], 5.0)
    assert t.shape == (5 * 2 * 1, 3)
    assert np.allclose(t[0], [-10, 0, 100]) and np.allclose(t[1], [-5, 0, 100]) and np.allclose(t[-1], [10, 5, 100])
    with pytest.raises(ValueError, match="^box_mm: each axis must run from low to high"):
        box_targets([10, -10, 0, 1, 0, 1], 1.0)
    with pytest.raises(ValueError, match="^spacing_mm: must be a positive number"):
        box_targets([0, 1, 0, 1, 0, 1], 0.0)
    with pytest.raises(ValueError, match="^spacing_mm: 0.01 mm gives"):
        box_targets([0, 100, 0, 100, 0, 100], 0.01)


def test_envelope_equals_single_predictions_and_its_volumes_overlay_the_ct(head, tmp_path):
    # Each target's values are those of arfi.predict at that target (the same plans and marches:
    # equal to the last bit), its focus distance that of the corrected beam's focal metrics, and
    # the skull's hottest place that of arfi field's volume march; the skull target is counted,
    # not evaluated.
    scenario = Scenario.load(head / "head.toml")
    seen: list[tuple[int, int]] = []
    points, counts = run_envelope(
        scenario, [*TARGETS, IN_SKULL], tmp_path / "env", progress=lambda d, t: seen.append((d, t))
    )
    assert counts == {"brain": 3, "skull": 1} and seen[-1] == (3, 3)
    assert [list(p.target_mm) for p in points] == TARGETS
    for target, point in zip(TARGETS, points):
        alone = predict(scenario, target, keep_simulation=True)
        assert point.corrected_pa == alone.corrected_pa and point.uncorrected_pa == alone.uncorrected_pa
        assert point.ray_steering_pa == alone.ray_steering_pa and point.water_pa == alone.water_pa
        # The water focus is the in-phase sum of direct Rayleigh sums: above any focus through
        # the bone (which only loses: reflection and absorption) for this phantom.
        assert point.water_pa > alone.optimal_pa >= point.corrected_pa
        corrected = focal_metrics(alone)["corrected"]
        assert point.focus_distance_mm == pytest.approx(corrected.peak_to_target_mm, rel=1e-9)
        assert point.focal_peak_pa == pytest.approx(corrected.focal_peak_pa, rel=1e-9)
        if target == TARGETS[0]:  # at the focus, arfi field's volume march of the same drive
            sim = alone.kept_simulation()
            field = sim.field(compared_drives(alone)["corrected"], volume=True)
            assert field.hottest is not None
            skull = field.hottest["skull"]
            assert point.skull_hottest_pa == pytest.approx(skull.pressure_pa, rel=1e-6)
            assert point.skull_isppa_w_cm2 == pytest.approx(skull.isppa_w_cm2, rel=1e-6)
    rows = (tmp_path / "env" / "envelope.csv").read_text().splitlines()
    assert rows[0] == ",".join(COLUMNS) and len(rows) == 4
    assert read_points(tmp_path / "env" / "envelope.csv") == points

    # The volumes on the CT's voxels: the CT's own affine, and the cube each target fills centred
    # on the target (the voxels' centres through the affine to RAS, to LPS, then by the scenario's
    # patient_to_transducer_mm: the documented chain, not the code's).
    from arfi.analysis.envelope import on_ct_voxels, write_volumes

    names = write_volumes(on_ct_voxels(scenario, points, 6.0), tmp_path / "env")
    assert names == [f"{v}.nii.gz" for v in VOLUMES]
    ct = nib.load(str(head / "head.nii.gz"))
    img = nib.load(str(tmp_path / "env" / "corrected_pa.nii.gz"))
    assert img.shape == ct.shape and np.allclose(img.affine, ct.affine)
    data = np.asarray(img.dataobj)
    t = np.array(scenario.to_dict()["ct"]["patient_to_transducer_mm"], dtype=float)
    for point in points:
        ijk = np.argwhere(data == np.float32(point.corrected_pa))
        assert len(ijk) == 27  # 6 mm cube of 2 mm voxels
        ras = ct.affine @ np.append(ijk.mean(axis=0), 1.0)
        lps = ras * [-1, -1, 1, 1]
        # The cube's voxel centres straddle the target by up to half a voxel along each axis.
        assert np.all(np.abs((t @ lps)[:3] - point.target_mm) <= 1.0 + 1e-9)


def test_a_stopped_envelope_resumes_where_it_stopped(head, tmp_path):
    scenario = Scenario.load(head / "head.toml")
    first, _ = run_envelope(scenario, TARGETS[:2], tmp_path)
    seen: list[tuple[int, int]] = []
    again, _ = run_envelope(scenario, TARGETS, tmp_path, progress=lambda d, t: seen.append((d, t)))
    assert seen == [(1, 1)]  # only the new target is evaluated
    assert again[:2] == first and len(again) == 3
    other = Scenario.from_toml(scenario.to_toml().replace("220000.0", "230000.0"), scenario.base_dir)
    with pytest.raises(ValueError, match="holds the envelope of another scenario"):
        run_envelope(other, TARGETS, tmp_path)


def test_two_local_workers_give_the_same_envelope(head, tmp_path):
    scenario = Scenario.load(head / "head.toml")
    alone, _ = run_envelope(scenario, TARGETS, tmp_path / "one", task_size=2)
    shared, _ = run_envelope(scenario, TARGETS, tmp_path / "two", task_size=2, workers=2)
    assert shared == alone


def test_cli_envelope_writes_its_files_and_one_line(head, tmp_path, capsys):
    out, js = tmp_path / "env", tmp_path / "env.json"
    argv = ["envelope", "--scenario", str(head / "head.toml"), "--out", str(out), "--json", str(js)]
    assert main([*argv, "--box-mm", "-10", "10", "0", "0", "150", "150", "--spacing-mm", "10"]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("envelope: ") and "of 3 targets in the brain" in printed
    for name in ["envelope.csv", "envelope.png", "scenario.toml", *[f"{v}.nii.gz" for v in VOLUMES]]:
        assert (out / name).exists(), name
    result = json.loads(js.read_text())
    assert len(result["targets"]) == 3 and result["tissues"] == {"brain": 3}
    assert set(result["targets"][0]) == set(COLUMNS)


@pytest.mark.parametrize(
    "extra, expected",
    [
        (["--box-mm", "0", "1", "0", "1", "150", "151"], "--spacing-mm: required with --box-mm"),
        (["--box-mm", "0", "0", "0", "0", "-50", "-50", "--spacing-mm", "1"], "lies outside the grid"),
        (["--box-mm", "0", "0", "0", "0", "150", "150", "--spacing-mm", "1", "--workers", "0"], "--workers: must be"),
        (
            ["--box-mm", "0", "0", "0", "0", "150", "150", "--spacing-mm", "1", "--scheduler", "tcp://127.0.0.1:9"],
            "--scheduler: cannot connect",
        ),
        (["--targets", "missing.csv"], "--targets: "),
        (["--box-mm", "0", "0", "0", "0", "150", "150", "--spacing-mm", "1", "--reachable-mpa", "-1"], "--reachable"),
    ],
)
def test_bad_envelope_input_is_one_line_and_nothing_written(head, tmp_path, capsys, extra, expected):
    out = tmp_path / "env"
    assert main(["envelope", "--scenario", str(head / "head.toml"), "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("arfi: error: ") and expected in err and "\n" not in err, err
    assert not out.exists()
