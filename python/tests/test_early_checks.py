"""Bad phases and images are refused before any simulation is built: through a head a build takes
tens of seconds and gigabytes, so an input of the wrong length or from another scenario is named
(option and file, one line, exit 2) in milliseconds, by the simulation's own rules
(``Scenario.outline()``), and nothing is written."""

import json

import numpy as np
import pytest

import arfi
from arfi import simulation
from arfi.cli import main


@pytest.fixture
def no_build(monkeypatch):
    """Fails any test that builds a simulation."""

    def refuse(*args, **kwargs):
        raise AssertionError("a simulation was built before the input was checked")

    monkeypatch.setattr(simulation._core, "CoreSimulation", refuse)


@pytest.fixture(scope="module")
def image(tmp_path_factory, sim):
    """An MR-ARFI image of the default scenario, with known phases per default group."""
    d = tmp_path_factory.mktemp("early")
    known = d / "known.npy"
    np.save(known, np.linspace(-1.0, 1.0, sim.n_default_groups))
    out = d / "m.nii.gz"
    assert main(["simulate", "--known-phases", str(known), "--noise-rad", "0", "--out", str(out)]) == 0
    return out


def write(path, values):
    np.save(path, np.asarray(values, dtype=np.float64))
    return str(path)


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_the_outline_is_the_built_simulations(sim):
    outline = arfi.Scenario.default().outline()
    assert outline.n_elements == sim.n_elements and outline.n_default_groups == sim.n_default_groups
    assert outline.mr_volume_shape == sim.mr_volume_shape
    np.testing.assert_array_equal(outline.mr_affine_mm, sim.mr_affine_mm)
    np.testing.assert_array_equal(outline.focus_mm, sim.focus_mm)
    per_group = np.linspace(0.0, 1.0, sim.n_groups)
    np.testing.assert_array_equal(outline.element_phases(per_group), sim.element_phases(per_group))
    np.testing.assert_array_equal(
        outline.element_phases(np.arange(4.0), groups=4), sim.with_groups(4).element_phases(np.arange(4.0))
    )
    known = np.linspace(0.0, 1.0, sim.n_default_groups)
    # A prior per default group serves a per-element estimate (as known phases do), not a group
    # estimate of other groups.
    outline.check_prior(known, groups=sim.n_elements)
    with pytest.raises(ValueError, match="prior: has 16 values; expected 1024 .one per element. or 4 .one per group."):
        outline.check_prior(known, groups=4)
    np.testing.assert_array_equal(
        outline.known_per_element(known, groups=sim.n_elements),
        sim.with_groups(sim.n_elements).known_per_element(known),
    )


@pytest.mark.parametrize(
    "verb, option, extra",
    [
        ("field", "--correction", ["--out", "f.npz"]),
        ("field", "--phases", ["--out", "f.npz"]),
        ("simulate", "--phases", ["--out", "m.nii.gz"]),
        ("simulate", "--known-phases", ["--out", "m.nii.gz"]),
    ],
)
def test_phases_of_the_wrong_length_are_named_before_the_build(tmp_path, capsys, no_build, verb, option, extra):
    bad = write(tmp_path / "bad.npy", np.zeros(5))
    args = [verb, option, bad] + [str(tmp_path / a) if "." in a else a for a in extra]
    assert main(args) == 2
    err = one_line(capsys)
    assert f"{option}: {bad}: has 5 values; expected 1024 (one per element) or 16 (one per group)" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.npy"]


def test_estimates_inputs_are_checked_before_the_build(tmp_path, capsys, no_build, image):
    out = str(tmp_path / "e.json")
    # A prior for another array.
    prior = write(tmp_path / "prior.npy", np.zeros(7))
    assert main(["estimate", "--image", str(image), "--prior", prior, "--prior-std-rad", "0.3", "--json", out]) == 2
    assert f"--prior: {prior}: has 7 values; expected 1024 (one per element) or 16 (one per group)" in one_line(capsys)
    # A prior without its spread.
    prior = write(tmp_path / "prior16.npy", np.zeros(16))
    assert main(["estimate", "--image", str(image), "--prior", prior, "--json", out]) == 2
    assert "--prior-std-rad: is required with a prior" in one_line(capsys)
    # The estimate's own options, by the library's rules, named as typed.
    for option, value, message in (
        ("--max-evaluations", "0", "--max-evaluations: must be > 0"),
        ("--fit-nuisance", "bogus", '--fit-nuisance: unknown nuisance parameter "bogus"'),
        ("--prior-correlation-mm", "20", "--prior-correlation-mm: was given without a prior"),
    ):
        assert main(["estimate", "--image", str(image), option, value, "--json", out]) == 2
        assert message in one_line(capsys)
    # Transmissions for another array.
    transmission = write(tmp_path / "t.npy", np.ones(9))
    assert main(["estimate", "--image", str(image), "--prior-transmission", transmission, "--json", out]) == 2
    assert f"--prior-transmission: {transmission}: has 9 values for 1024 elements" in one_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["prior.npy", "prior16.npy", "t.npy"]


def test_an_image_of_another_scenario_is_named_before_the_build(tmp_path, capsys, no_build, image):
    # The same image, its MR slice 2 mm further along z: another scenario's geometry.
    import nibabel as nib

    moved = tmp_path / "moved.nii.gz"
    img = nib.load(str(image))
    affine = img.affine.copy()
    affine[2, 3] += 2.0
    nib.save(nib.Nifti1Image(np.asarray(img.dataobj), affine), str(moved))
    (tmp_path / "moved.json").write_text(json.dumps({}))
    for verb in (["calibrate"], ["estimate"], ["diagnose"]):
        assert main([*verb, "--image", str(moved)]) == 2, verb
        err = one_line(capsys)
        assert f"--image: {moved}: its affine does not match the scenario's MR geometry" in err, (verb, err)
    # Known phases in the sidecar that fit no grouping of the array.
    (tmp_path / "short.json").write_text(json.dumps({"applied_phases_rad": [0.1, 0.2, 0.3]}))
    short = tmp_path / "short.nii.gz"
    nib.save(nib.Nifti1Image(np.asarray(img.dataobj), img.affine), str(short))
    assert main(["estimate", "--image", str(short)]) == 2
    err = one_line(capsys)
    assert f"sidecar of {short}: applied_phases_rad: has 3 values; expected 1024 (one per element)" in err, err


def test_good_inputs_still_reach_the_simulation(tmp_path, capsys, image):
    # The checks refuse nothing a simulation takes: per group, per element and per default group.
    np.save(tmp_path / "g.npy", np.zeros(16))
    assert main(["field", "--correction", str(tmp_path / "g.npy"), "--out", str(tmp_path / "f.npz")]) == 0
    assert main(["calibrate", "--image", str(image), "--json", str(tmp_path / "c.json")]) == 0
