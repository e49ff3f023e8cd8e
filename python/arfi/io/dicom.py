"""MR-ARFI from scanner DICOM: two phase series acquired with opposite motion-encoding polarity.

The displacement phase is ``Δφ = ½·wrap(φ+ − φ−)`` (background phase, B0 and coil phase cancel in
the difference; ``wrap`` maps to (−π, π], so ``|Δφ| < π/2`` is recovered whatever the background
wrapping). The image plane is carried from the scanner's patient frame (DICOM LPS, mm) into the
transducer frame by a user-given rigid transform, and must then lie along the frame's axes
(arfi's MR planes are ``xy``, ``xz`` and ``yz``). The result is arfi's MR-ARFI NIfTI (one slice,
the displacement phase in rad, the affine mapping voxels to the transducer frame in mm) and the
scenario's matching ``[mr]`` section.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

PHASE_UNITS = ("auto", "rad", "mrad", "siemens")
"""How stored phase values (after the DICOM rescale) become radians: ``rad`` as is, ``mrad``
×1e-3 (GE), ``siemens`` ×π/4096 (12-bit, −4096…4094 ↦ −π…π); ``auto`` picks by Manufacturer and
otherwise takes values within ±π as radians."""

_TOL_MM = 1e-3  # geometry agreement between the two series, and axis alignment after the transform


@dataclass(frozen=True)
class PhaseImage:
    """One DICOM phase slice: pixel values in rad, shape (rows, columns), and its geometry."""

    path: Path
    phase_rad: NDArray[np.float64]
    position_mm: NDArray[np.float64]
    """ImagePositionPatient: centre of the first transmitted pixel (LPS, mm)."""
    row_direction: NDArray[np.float64]
    """Direction of increasing column index (first triple of ImageOrientationPatient)."""
    column_direction: NDArray[np.float64]
    """Direction of increasing row index (second triple)."""
    spacing_mm: tuple[float, float]
    """PixelSpacing: (between rows, between columns)."""
    slice_thickness_mm: float
    echo_time_ms: float | None

    def affine_mm(self) -> NDArray[np.float64]:
        """4x4 map from (column, row, 0, 1) to the patient frame (mm)."""
        a = np.eye(4)
        a[:3, 0] = self.row_direction * self.spacing_mm[1]
        a[:3, 1] = self.column_direction * self.spacing_mm[0]
        a[:3, 2] = np.cross(self.row_direction, self.column_direction) * self.slice_thickness_mm
        a[:3, 3] = self.position_mm
        return a


@dataclass(frozen=True)
class DicomArfi:
    """An MR-ARFI image from a DICOM pair, in the transducer frame."""

    image_rad: NDArray[np.float64]
    """Δφ (rad) on the image axes (u, v) of ``mr["plane"]``, shape ``mr["matrix"]``."""
    affine_mm: NDArray[np.float64]
    """NIfTI affine: voxel indices of ``volume_shape`` to the transducer frame (mm)."""
    volume_shape: tuple[int, int, int]
    mr: dict[str, Any]
    """The scenario ``[mr]`` section that matches this image: ``plane``, ``center_mm``, ``fov_mm``,
    ``matrix``, ``slice_thickness_mm``."""
    echo_time_ms: float | None
    sources: tuple[str, str]

    def mr_toml(self) -> str:
        """The ``[mr]`` section as TOML, to paste into a scenario file."""
        m = self.mr
        fmt = ", ".join
        return (
            f'[mr]\nplane = "{m["plane"]}"\ncenter_mm = [{fmt(f"{v:.6g}" for v in m["center_mm"])}]\n'
            f"fov_mm = [{fmt(f'{v:.6g}' for v in m['fov_mm'])}]\nmatrix = "
            f"[{fmt(str(v) for v in m['matrix'])}]\nslice_thickness_mm = {m['slice_thickness_mm']:.6g}\n"
        )


def _dicom_files(path: Path, name: str) -> list[Path]:
    if path.is_file():
        return [path]
    if not path.exists():
        raise FileNotFoundError(f"{name}: {path}: no such file or directory")
    files = sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
    if not files:
        raise ValueError(f"{name}: {path}: no phase images (empty directory)")
    return files


def _number(ds: Any, keyword: str, where: str, count: int = 1) -> NDArray[np.float64]:
    value = ds.get(keyword)
    if value is None:
        raise ValueError(f"{where}: missing {keyword}")
    try:
        a = np.atleast_1d(np.asarray([float(v) for v in (value if count > 1 else [value])], dtype=np.float64))
    except (TypeError, ValueError):
        raise ValueError(f"{where}: {keyword} is not numeric ({value!r})") from None
    if a.size != count or not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: {keyword} must hold {count} finite number(s), got {value!r}")
    return a


def _to_radians(values: NDArray[np.float64], ds: Any, units: str, where: str) -> NDArray[np.float64]:
    if units == "auto":
        maker = str(ds.get("Manufacturer", "")).upper()
        units = "siemens" if "SIEMENS" in maker else "mrad" if maker.startswith("GE") else "rad"
    scale = {"rad": 1.0, "mrad": 1e-3, "siemens": math.pi / 4096}[units]
    phase = values * scale
    lo, hi = float(phase.min()), float(phase.max())
    if lo < -math.pi * 1.001 or hi > math.pi * 1.001:
        raise ValueError(
            f"{where}: values span [{lo:.4g}, {hi:.4g}] rad with phase units '{units}', beyond ±π: not a phase image "
            "(a magnitude image?), or pass --phase-units"
        )
    return phase


def read_phase_image(path: str | os.PathLike[str], name: str = "phase", units: str = "auto") -> PhaseImage:
    """Reads one DICOM phase slice (a file, or a directory holding exactly one image). Raises
    FileNotFoundError or ValueError naming `name` and the file."""
    import pydicom
    from pydicom.errors import InvalidDicomError

    if units not in PHASE_UNITS:
        raise ValueError(f"phase_units: must be one of {', '.join(PHASE_UNITS)}, got {units!r}")
    files = _dicom_files(Path(path), name)
    if len(files) > 1:
        raise ValueError(f"{name}: {path}: holds {len(files)} files; give the one phase slice to use")
    f = files[0]
    where = f"{name}: {f}"
    try:
        ds = pydicom.dcmread(f)
    except (InvalidDicomError, OSError, EOFError, ValueError) as e:
        raise ValueError(f"{where}: not a readable DICOM file ({e})") from None
    image_type = [str(v).upper() for v in ds.get("ImageType", [])]
    if "M" in image_type or "MAGNITUDE" in image_type:
        shown = "\\".join(image_type)
        raise ValueError(f"{where}: is a magnitude image (ImageType {shown}), not a phase image")
    if "PixelData" not in ds:
        raise ValueError(f"{where}: has no pixel data")
    try:
        stored = np.asarray(ds.pixel_array, dtype=np.float64)
    except Exception as e:  # pydicom raises many types for unsupported or corrupt pixel data
        raise ValueError(f"{where}: pixel data not readable ({e})") from None
    if stored.ndim != 2:
        raise ValueError(f"{where}: must hold one 2-D slice, got pixel data of shape {stored.shape}")
    slope = float(ds.get("RescaleSlope", 1.0))
    intercept = float(ds.get("RescaleIntercept", 0.0))
    orientation = _number(ds, "ImageOrientationPatient", where, 6)
    row_dir, col_dir = orientation[:3], orientation[3:]
    if (
        abs(np.linalg.norm(row_dir) - 1) > 1e-3
        or abs(np.linalg.norm(col_dir) - 1) > 1e-3
        or abs(row_dir @ col_dir) > 1e-3
    ):
        raise ValueError(f"{where}: ImageOrientationPatient is not two orthonormal directions ({orientation.tolist()})")
    spacing = _number(ds, "PixelSpacing", where, 2)
    if np.any(spacing <= 0):
        raise ValueError(f"{where}: PixelSpacing must be positive, got {spacing.tolist()}")
    thickness = float(_number(ds, "SliceThickness", where)[0])
    if thickness <= 0:
        raise ValueError(f"{where}: SliceThickness must be positive, got {thickness}")
    echo = ds.get("EchoTime")
    return PhaseImage(
        path=f,
        phase_rad=_to_radians(stored * slope + intercept, ds, units, where),
        position_mm=_number(ds, "ImagePositionPatient", where, 3),
        row_direction=row_dir / np.linalg.norm(row_dir),
        column_direction=col_dir / np.linalg.norm(col_dir),
        spacing_mm=(float(spacing[0]), float(spacing[1])),
        slice_thickness_mm=thickness,
        echo_time_ms=None if echo is None else float(echo),
    )


def _check_pair(plus: PhaseImage, minus: PhaseImage) -> None:
    """The two polarities must be the same acquisition but for the encoding sign."""
    where = f"minus: {minus.path}"
    if plus.phase_rad.shape != minus.phase_rad.shape:
        raise ValueError(f"{where}: size {minus.phase_rad.shape} differs from the plus series' {plus.phase_rad.shape}")
    geometry = {
        "position (ImagePositionPatient)": (plus.position_mm, minus.position_mm),
        "orientation (ImageOrientationPatient)": (
            np.r_[plus.row_direction, plus.column_direction],
            np.r_[minus.row_direction, minus.column_direction],
        ),
        "pixel spacing": (np.array(plus.spacing_mm), np.array(minus.spacing_mm)),
        "slice thickness": (np.array([plus.slice_thickness_mm]), np.array([minus.slice_thickness_mm])),
    }
    for what, (a, b) in geometry.items():
        if not np.allclose(a, b, rtol=0, atol=_TOL_MM):
            raise ValueError(f"{where}: {what} {b.tolist()} differs from the plus series' {a.tolist()}")
    te_plus, te_minus = plus.echo_time_ms, minus.echo_time_ms
    if (te_plus is None) != (te_minus is None) or (
        te_plus is not None and te_minus is not None and abs(te_plus - te_minus) > 1e-6
    ):
        raise ValueError(
            f"{where}: echo time {minus.echo_time_ms} ms differs from the plus series' {plus.echo_time_ms} ms"
        )


def read_transform(path: str | os.PathLike[str]) -> NDArray[np.float64]:
    """A rigid 4x4 transform from the patient frame (DICOM LPS, mm) to the transducer frame (mm):
    ``.npy``, text with four rows of four numbers, or JSON ``{"patient_to_transducer_mm": [[…]×4]}``."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"transform: {p}: no such file")
    try:
        if p.suffix == ".npy":
            m = np.load(p, allow_pickle=False)
        elif p.suffix == ".json":
            m = json.loads(p.read_text(encoding="utf-8"))["patient_to_transducer_mm"]
        else:
            m = np.loadtxt(p, ndmin=2)
        m = np.asarray(m, dtype=np.float64)
    except Exception as e:  # numpy/json raise many types for bad files
        raise ValueError(f"transform: {p}: not a 4x4 matrix ({e})") from None
    return check_rigid(m, f"transform: {p}")


def check_rigid(matrix: ArrayLike, name: str = "transform") -> NDArray[np.float64]:
    """The matrix, checked to be a 4x4 rigid transform (rotation + translation, mm)."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"{name}: must be a finite 4x4 matrix, got shape {m.shape}")
    r = m[:3, :3]
    if (
        not np.allclose(r @ r.T, np.eye(3), atol=1e-6)
        or abs(np.linalg.det(r) - 1) > 1e-6
        or not np.allclose(m[3], [0, 0, 0, 1])
    ):
        raise ValueError(f"{name}: must be rigid (a rotation and a translation; last row 0 0 0 1)")
    return m


def arfi_from_phase_images(plus: PhaseImage, minus: PhaseImage, transform: ArrayLike | None = None) -> DicomArfi:
    """``Δφ = ½·wrap(φ+ − φ−)`` on the transducer frame's axes (see the module docstring)."""
    _check_pair(plus, minus)
    t = np.eye(4) if transform is None else check_rigid(transform)
    delta = 0.5 * np.angle(np.exp(1j * (plus.phase_rad - minus.phase_rad)))
    a = t @ plus.affine_mm()
    # Frame displacement (mm) per index step along array axis 0 (rows: the DICOM column
    # direction) and axis 1 (columns: the row direction).
    steps = [a[:3, 1], a[:3, 0]]
    image, origin = delta, a[:3, 3].copy()
    frame_axes, spacing = [], []
    for k, step in enumerate(steps):
        axis = int(np.argmax(np.abs(step)))
        # Aligned when the off-axis drift over the whole image stays under half a pixel.
        drift = np.linalg.norm(np.delete(step, axis)) * (image.shape[k] - 1)
        if drift > 0.5 * abs(step[axis]):
            raise ValueError(
                f"plus: {plus.path}: after the transform the image is oblique to the transducer frame (array axis {k} "
                f"along {np.round(step / np.linalg.norm(step), 4).tolist()}); arfi's MR planes are xy, xz and yz"
            )
        if step[axis] < 0:  # flip so that indices increase along the frame axis
            origin = origin + step * (image.shape[k] - 1)
            image = np.flip(image, axis=k)
        frame_axes.append(axis)
        spacing.append(float(abs(step[axis])))
    if frame_axes[0] == frame_axes[1]:
        raise ValueError(f"plus: {plus.path}: degenerate orientation")
    # arfi's image axes (u, v) are in increasing frame-axis order: xy, xz, yz.
    if frame_axes[0] > frame_axes[1]:
        image = image.T
        frame_axes.reverse()
        spacing.reverse()
    normal = 3 - sum(frame_axes)
    plane = "".join("xyz"[i] for i in frame_axes)
    matrix = [int(n) for n in image.shape]
    fov = [spacing[0] * matrix[0], spacing[1] * matrix[1]]
    center = origin.copy()
    for k, ax in enumerate(frame_axes):
        center[ax] = origin[ax] - 0.5 * spacing[k] + 0.5 * fov[k]
    shape = [1, 1, 1]
    affine = np.eye(4)
    for k, ax in enumerate(frame_axes):
        shape[ax] = matrix[k]
        affine[ax, ax] = spacing[k]
        affine[ax, 3] = origin[ax]
    affine[normal, normal] = plus.slice_thickness_mm
    affine[normal, 3] = origin[normal]
    mr = {
        "plane": plane,
        "center_mm": [float(c) for c in center],
        "fov_mm": fov,
        "matrix": matrix,
        "slice_thickness_mm": plus.slice_thickness_mm,
    }
    return DicomArfi(
        image_rad=np.ascontiguousarray(image),
        affine_mm=affine,
        volume_shape=(shape[0], shape[1], shape[2]),
        mr=mr,
        echo_time_ms=plus.echo_time_ms,
        sources=(str(plus.path), str(minus.path)),
    )


def read_dicom_arfi(
    plus: str | os.PathLike[str],
    minus: str | os.PathLike[str],
    transform: ArrayLike | None = None,
    phase_units: str = "auto",
) -> DicomArfi:
    """Reads the φ+ and φ− phase slices (files, or directories of one image each) and returns the
    MR-ARFI image in the transducer frame (``transform``: 4x4 patient → transducer, mm; None =
    identity)."""
    return arfi_from_phase_images(
        read_phase_image(plus, "plus", phase_units), read_phase_image(minus, "minus", phase_units), transform
    )
