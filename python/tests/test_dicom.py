"""Scanner input: real DICOM files written with pydicom, read back by ``arfi dicom``."""

import json
import math
from pathlib import Path

import numpy as np
import pydicom
import pytest
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import ExplicitVRLittleEndian, MRImageStorage, generate_uid

import arfi
from arfi.cli import main
from arfi.io.dicom import read_dicom_arfi

# A rigid transform patient (LPS, mm) -> transducer frame: patient z -> frame x, patient y ->
# frame -y, patient x -> frame z, and a translation.
TO_FRAME = np.array([[0.0, 0.0, 1.0, 12.5], [0.0, -1.0, 0.0, -30.0], [1.0, 0.0, 0.0, 40.0], [0.0, 0.0, 0.0, 1.0]])


def write_phase(
    path: Path,
    phase_rad: np.ndarray,
    position,
    row_dir,
    col_dir,
    spacing,
    *,
    thickness=3.0,
    echo_ms=12.0,
    image_type=("ORIGINAL", "PRIMARY", "P", "ND"),
    manufacturer="SIEMENS",
) -> Path:
    """One Siemens-style phase slice: 12-bit stored values, RescaleSlope 2, RescaleIntercept -4096
    (so that -4096..4094 maps to -pi..pi)."""
    wrapped = np.angle(np.exp(1j * phase_rad))
    stored = np.clip(np.round((wrapped * 4096 / math.pi + 4096) / 2), 0, 4095).astype(np.uint16)
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = MRImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID, ds.SOPInstanceUID = MRImageStorage, meta.MediaStorageSOPInstanceUID
    ds.Modality, ds.Manufacturer, ds.ImageType = "MR", manufacturer, list(image_type)
    ds.Rows, ds.Columns = stored.shape
    ds.ImagePositionPatient = [float(v) for v in position]
    ds.ImageOrientationPatient = [float(v) for v in [*row_dir, *col_dir]]
    ds.PixelSpacing = [float(spacing[0]), float(spacing[1])]
    ds.SliceThickness, ds.EchoTime = thickness, echo_ms
    ds.RescaleSlope, ds.RescaleIntercept = 2, -4096
    ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 12, 11, 0
    ds.PixelData = stored.tobytes()
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.save_as(path, enforce_file_format=True)
    return path


def scanner_pair(tmp_path: Path, sim: arfi.Simulation, arfi_rad: np.ndarray, *, transpose=False, flip=False, **kw):
    """Writes phi+ and phi- (with a smooth background phase that wraps) of the scenario's MR
    image as the scanner would store it, seen from the patient frame through TO_FRAME: ``flip``
    stores the columns from the frame's +y end, ``transpose`` stores y along the rows."""
    a = sim.mr_affine_mm  # voxel (i, j, 0) of the xy image -> frame
    image, origin = arfi_rad, a[:3, 3]
    steps = [a[:3, 0], a[:3, 1]]  # frame displacement per index along the array axes
    if flip:
        image, origin = image[:, ::-1], origin + steps[1] * (image.shape[1] - 1)
        steps[1] = -steps[1]
    if transpose:
        image, steps = image.T, steps[::-1]
    to_patient = np.linalg.inv(TO_FRAME)
    first = (to_patient @ np.append(origin, 1.0))[:3]
    col_dir, row_dir = (to_patient[:3, :3] @ (s / np.linalg.norm(s)) for s in steps)
    spacing = [float(np.linalg.norm(s)) for s in steps]
    yy, xx = np.mgrid[0 : image.shape[0], 0 : image.shape[1]]
    background = 0.11 * xx + 0.07 * yy - 2.0  # wraps several times across the image
    plus = write_phase(tmp_path / "plus" / "IM0001.dcm", background + image, first, row_dir, col_dir, spacing, **kw)
    minus = write_phase(tmp_path / "minus" / "IM0001.dcm", background - image, first, row_dir, col_dir, spacing, **kw)
    np.savetxt(tmp_path / "to_frame.txt", TO_FRAME)
    return plus, minus


@pytest.fixture(scope="module")
def arfi_rad(sim):
    # An aberrated, asymmetric focus: a flipped or transposed read cannot pass for the original.
    image = sim.arfi_image(np.random.default_rng(3).uniform(-2.5, 2.5, 16), noise_rad=0.0)
    assert np.max(np.abs(image - image[::-1])) > 0.02 and np.max(np.abs(image - image[:, ::-1])) > 0.02
    return image


@pytest.mark.parametrize("transpose", [False, True])
@pytest.mark.parametrize("flip", [False, True])
def test_phase_difference_and_geometry_come_back_in_the_transducer_frame(tmp_path, sim, arfi_rad, transpose, flip):
    plus, minus = scanner_pair(tmp_path, sim, arfi_rad, transpose=transpose, flip=flip)
    got = read_dicom_arfi(plus.parent, minus.parent, TO_FRAME)
    # 12-bit phase: steps of 2pi/4096 = 1.5 mrad on each series; half their difference is off by
    # at most one step.
    assert got.image_rad.shape == arfi_rad.shape
    assert np.max(np.abs(got.image_rad - arfi_rad)) <= 2 * math.pi / 4096
    np.testing.assert_allclose(got.affine_mm, sim.mr_affine_mm, atol=1e-9)
    assert got.volume_shape == sim.mr_volume_shape
    assert got.mr["plane"] == "xy" and got.mr["matrix"] == [128, 96]
    np.testing.assert_allclose(got.mr["center_mm"], [0.0, 0.0, 85.0], atol=1e-9)
    np.testing.assert_allclose(got.mr["fov_mm"], [180.0, 135.0], atol=1e-9)
    assert got.echo_time_ms == 12.0


def test_cli_dicom_to_calibration(tmp_path, sim, arfi_rad):
    plus, minus = scanner_pair(tmp_path, sim, arfi_rad)
    out = tmp_path / "measured.nii.gz"
    assert (
        main(
            [
                "dicom",
                "--plus",
                str(plus),
                "--minus",
                str(minus),
                "--transform",
                str(tmp_path / "to_frame.txt"),
                "--out",
                str(out),
                "--json",
                str(tmp_path / "d.json"),
                "--known-phases",
                str(_zeros(tmp_path)),
            ]
        )
        == 0
    )
    d = json.loads((tmp_path / "d.json").read_text())
    assert d["mr"]["plane"] == "xy" and d["mr"]["slice_thickness_mm"] == 3.0
    side = json.loads((tmp_path / "measured.json").read_text())
    assert side["applied_phases_rad"] == [0.0] * 16 and side["arfi_dicom"]["echo_time_ms"] == 12.0
    # The NIfTI goes straight into the workflow: the estimate recovers the aberration (within
    # the twin ambiguity of one image, so compare the images it predicts).
    assert main(["estimate", "--image", str(out), "--method", "lbfgs", "--json", str(tmp_path / "e.json")]) == 0
    phases = np.array(json.loads((tmp_path / "e.json").read_text())["phases_rad"])
    assert np.max(np.abs(sim.arfi_image(phases, noise_rad=0.0) - arfi_rad)) < 0.01


def _zeros(tmp_path: Path) -> Path:
    p = tmp_path / "zeros.txt"
    p.write_text("\n".join(["0"] * 16))
    return p


def _run(capsys, args):
    code = main(args)
    err = capsys.readouterr().err.strip()
    return code, err


@pytest.mark.parametrize(
    "problem, match",
    [
        ("size", "size (64, 96) differs from the plus series' (128, 96)"),
        ("position", "position (ImagePositionPatient)"),
        ("echo", "echo time 15.0 ms differs from the plus series' 12.0 ms"),
        ("magnitude", "is a magnitude image"),
        ("missing", "no such file or directory"),
        ("empty", "no phase images"),
        ("not dicom", "not a readable DICOM file"),
        ("oblique", "oblique to the transducer frame"),
        ("units", "not a phase image"),
    ],
)
def test_bad_dicom_is_one_line_naming_the_file(tmp_path, sim, arfi_rad, capsys, problem, match):
    plus, minus = scanner_pair(tmp_path, sim, arfi_rad)
    ds = pydicom.dcmread(minus)
    if problem == "size":
        ds.Rows = 64
        ds.PixelData = ds.PixelData[: 64 * 96 * 2]
    elif problem == "position":
        ds.ImagePositionPatient = [v + 2.0 for v in ds.ImagePositionPatient]
    elif problem == "echo":
        ds.EchoTime = 15.0
    elif problem == "magnitude":
        ds.ImageType = ["ORIGINAL", "PRIMARY", "M", "ND"]
    elif problem == "oblique":
        c, s = math.cos(0.3), math.sin(0.3)
        rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        for d in (ds, pydicom.dcmread(plus)):
            o = np.array(d.ImageOrientationPatient, dtype=float).reshape(2, 3) @ rot.T
            d.ImageOrientationPatient = [float(v) for v in o.ravel()]
            d.save_as(minus if d is ds else plus)
    elif problem == "units":
        ds.Manufacturer = "ACME"  # auto units: values within ±pi taken as rad; these span ±4096
    if problem != "oblique":
        ds.save_as(minus)
    if problem == "missing":
        minus.unlink()
        minus.parent.rmdir()
    elif problem == "empty":
        minus.unlink()
    elif problem == "not dicom":
        minus.write_bytes(b"not a DICOM file at all")
    code, err = _run(
        capsys,
        [
            "dicom",
            "--plus",
            str(plus),
            "--minus",
            str(minus.parent if problem == "empty" else minus),
            "--transform",
            str(tmp_path / "to_frame.txt"),
            "--out",
            str(tmp_path / "m.nii.gz"),
        ],
    )
    assert code == 2 and len(err.splitlines()) == 1 and match in err, err
    assert "minus" in err or "plus" in err
    assert not (tmp_path / "m.nii.gz").exists()


def test_a_transform_that_is_not_rigid_is_refused(tmp_path, sim, arfi_rad, capsys):
    plus, minus = scanner_pair(tmp_path, sim, arfi_rad)
    np.savetxt(tmp_path / "scaled.txt", np.diag([2.0, 1.0, 1.0, 1.0]))
    code, err = _run(
        capsys,
        [
            "dicom",
            "--plus",
            str(plus),
            "--minus",
            str(minus),
            "--transform",
            str(tmp_path / "scaled.txt"),
            "--out",
            str(tmp_path / "m.nii.gz"),
        ],
    )
    assert code == 2 and "transform" in err and "rigid" in err


def test_scenario_geometry_must_match(tmp_path, sim, arfi_rad, capsys):
    plus, minus = scanner_pair(tmp_path, sim, arfi_rad)
    scenario = tmp_path / "s.toml"
    scenario.write_text(
        arfi.Scenario.default().to_toml().replace("center_mm = [0.0, 0.0, 85.0]", "center_mm = [0.0, 0.0, 90.0]")
    )
    assert "90.0" in scenario.read_text()
    code, err = _run(
        capsys,
        [
            "dicom",
            "--plus",
            str(plus),
            "--minus",
            str(minus),
            "--scenario",
            str(scenario),
            "--transform",
            str(tmp_path / "to_frame.txt"),
            "--out",
            str(tmp_path / "m.nii.gz"),
        ],
    )
    assert code == 2 and "does not match the DICOM image" in err and len(err.splitlines()) == 1
