"""The march against stored full-wave results, for media with no exact solution: the textured
skull caps of :mod:`arfi.validation.textured_caps`.

The references were computed once by BabelViscoFDTD (a viscoelastic staggered-grid FDTD code we
did not write; ``benches/fullwave/caps_fdtd.py``, through ``arfi field --engine fdtd``'s code) and
stored small in ``arfi/validation/data/fullwave_caps.json``: the focal peak, ``|p|/p0`` along z through it and
on the focal plane about it. ``arfi validate`` writes each case's CT again (the same HU: the
texture comes from a hash, not a random generator, and the CT's fingerprint is checked), marches it on the scenario's
default grid
and compares, as the exact cases are compared: focal pressure, 3-D focal position (negative when
the march's peak lies short along z), the axial profile (largest difference over 10 mm either side
of the reference focus, relative to its peak) and the focal plane's correlation within 10 mm of
the focus (a disc). The uniform cap is held to :data:`TOLERANCES`: the spread of the full-wave codes of the
ITRUSST benchmark (Aubry et al., JASA 152(2), 2022: 10 % and 1 mm), since the reference is itself a
finite-difference solution (0.5 mm voxels, the bone's faces staircased). The textured caps are held
where the march is, :data:`TEXTURED_TOLERANCES`: it leaves out the loss of the wave a fine texture
scatters (measured: 9.4 % more focal pressure than the engine behind a texture of 1 mm), so that an
install check holds what is known and fails on anything worse.

The engine at 6 points per wavelength (0.5 mm voxels) puts the focus of the suite's homogeneous
cortical shell, whose exact solution is known and whose faces the caps share, 10 % too high; the
references are scaled by that measured error (:func:`grid_correction`).
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from arfi import _core
from arfi.validation import textured_caps

#: The stored references.
REFERENCES = Path(__file__).resolve().parent / "data" / "fullwave_caps.json"

#: Relative focal pressure, focal position (mm), axial profile (relative to the reference's peak)
#: and the smallest focal-plane correlation: the uniform cap's (the ITRUSST spread; the correlation
#: the tilted plates' own).
TOLERANCES = (0.10, 1.0, 0.10, 0.95)
#: The textured caps' own: the march's measured accuracy there (+9.4 % focal pressure, 0.98 mm,
#: profile 11.2 %, correlation 0.992), rounded up.
TEXTURED_TOLERANCES = (0.15, 1.5, 0.15, 0.95)

#: The voxel size the references are compared at (points per wavelength in water), and the case
#: that measures the engine's discretisation error there (:func:`grid_correction`): the validation
#: suite's homogeneous cortical shell, radii 30-36.5 mm about the focus, whose exact solution is
#: known.
REFERENCE_PPW = 6.0
CALIBRATION = "shell"

#: The half-length (mm) of the axial profile compared, either side of the reference focus.
PROFILE_MM = 10.0


@dataclass(frozen=True)
class FullWaveResult:
    """One case against its full-wave reference: the attributes of
    :class:`arfi._core.ValidationResult`, the reference in place of the exact solution (each pair
    is simulated, reference)."""

    name: str
    description: str
    focal_pressure: tuple[float, float]
    focal_z_mm: tuple[float, float]
    focal_point_mm: tuple[tuple[float, float, float], tuple[float, float, float]]
    focal_pressure_error: float
    focal_position_error_mm: float
    axial_error: float
    correlation: float
    #: Columns z (mm), march, reference (|p|/p0) along z through the reference focus.
    axis: NDArray[np.float64]
    #: Columns x (mm), march, reference on the focal plane's line y = focus.
    focal_line: NDArray[np.float64]
    step_mm: float
    spacing_mm: float
    seconds: float
    tolerances: tuple[float, float, float, float]
    engine: str

    @classmethod
    def from_comparison(
        cls,
        name: str,
        description: str,
        m: dict[str, Any],
        grid: _core.Grid,
        seconds: float,
        tolerances: tuple[float, float, float, float],
        engine: dict[str, Any],
    ) -> FullWaveResult:
        """The result of a comparison ``m`` (the dict of :func:`compare_fields` or of
        :func:`arfi.validation.fullwave_head.metrics`), the march on ``grid`` (``Simulation.grid``) against
        the full-wave ``engine`` (its stored ``engine`` and ``engine_version``)."""
        ps, pe = m["focal_pressure"]
        return cls(
            name=name,
            description=description,
            focal_pressure=(ps, pe),
            focal_z_mm=(m["focal_point_mm"][0][2], m["focal_point_mm"][1][2]),
            focal_point_mm=m["focal_point_mm"],
            focal_pressure_error=ps / pe - 1.0,
            focal_position_error_mm=m["focal_position_error_mm"],
            axial_error=m["axial_error"],
            correlation=m["correlation"],
            axis=m["axis"],
            focal_line=m["focal_line"],
            step_mm=grid.dz_mm,
            spacing_mm=grid.dx_mm,
            seconds=seconds,
            tolerances=tolerances,
            engine=f"{engine['engine']} {engine['engine_version']}",
        )

    @property
    def passed(self) -> bool:
        p, z, a, c = self.tolerances
        return (
            abs(self.focal_pressure_error) <= p
            and abs(self.focal_position_error_mm) <= z
            and self.axial_error <= a
            and self.correlation >= c
        )


#: Half-width (mm) of the focal plane stored about the focus, and half-length of the line along z.
PLANE_MM = 10.0
LINE_MM = 15.0


def stored_parts(f: Any) -> dict[str, Any]:
    """What is stored of a field ``f`` (:class:`arfi.simulation.Field` with its volume), as
    ``|p|/p0`` (``p0`` its pressure at the source): the focal peak, the line along z through it
    and the focal plane about it, on the field's own samples."""
    p0 = f.surface_pressure_pa
    focus = f.focal_metrics
    fx, fy, fz = focus.focal_peak_mm
    volume = f.pressure_volume().pressure_pa
    x, y, z = np.asarray(f.x_mm), np.asarray(f.y_mm), np.asarray(f.axis_z_mm)
    col, row, k = int(np.argmin(np.abs(x - fx))), int(np.argmin(np.abs(y - fy))), int(np.argmin(np.abs(z - fz)))
    along = np.abs(z - fz) <= LINE_MM
    cols, rows = np.abs(x - fx) <= PLANE_MM, np.abs(y - fy) <= PLANE_MM
    return {
        "focal_pressure_p0": focus.focal_peak_pa / p0,
        "focal_point_mm": [float(v) for v in focus.focal_peak_mm],
        "line_xy_mm": [float(x[col]), float(y[row])],
        "line_z_mm": np.round(z[along], 4).tolist(),
        "line_p0": np.round(volume[along, row, col] / p0, 5).tolist(),
        "plane_z_mm": float(z[k]),
        "plane_x_mm": np.round(x[cols], 4).tolist(),
        "plane_y_mm": np.round(y[rows], 4).tolist(),
        "plane_p0": np.round(volume[k][np.ix_(rows, cols)] / p0, 5).tolist(),
    }


def references() -> dict[str, dict[float, dict[str, Any]]]:
    """The stored runs by case name and points per wavelength; ValueError when the file is missing."""
    if not REFERENCES.is_file():
        raise ValueError(f"{REFERENCES}: no stored full-wave references (made by benches/fullwave/caps_fdtd.py)")
    out: dict[str, dict[float, dict[str, Any]]] = {}
    for r in json.loads(REFERENCES.read_text()):
        out.setdefault(r["case"], {})[float(r["points_per_wavelength"])] = r
    return out


def grid_correction(stored: dict[str, dict[float, dict[str, Any]]]) -> float:
    """The engine's discretisation error at :data:`REFERENCE_PPW`, measured where the exact answer
    is known on the caps' geometry: the exact focal pressure of the :data:`CALIBRATION` case over
    the engine's. ValueError when that run is not stored."""
    row = stored.get(CALIBRATION, {}).get(REFERENCE_PPW)
    if row is None:
        raise ValueError(
            f"{REFERENCES}: no stored run of the calibration case {CALIBRATION} at {REFERENCE_PPW:g} points per "
            "wavelength (benches/fullwave/caps_fdtd.py --case shell makes it)"
        )
    return float(row["exact_focal_pressure_p0"] / row["fdtd"]["focal_pressure_p0"])


def reference(name: str, stored: dict[str, dict[float, dict[str, Any]]] | None = None) -> dict[str, Any]:
    """The reference of case ``name``: its run at :data:`REFERENCE_PPW` points per wavelength,
    ``|p|`` scaled by the engine's discretisation error on the calibration shell
    (:func:`grid_correction`), the factor recorded as ``grid_factor``. That the factor carries over
    is an assumption: the caps share the shell's outer and inner faces (radii 30 and 36.5 mm about
    the focus) and its path through water, but add the diploë's two faces and lose most of the
    focus to it. ValueError when it is not stored."""
    stored = references() if stored is None else stored
    runs = stored.get(name, {})
    if REFERENCE_PPW not in runs:
        raise ValueError(
            f"{name}: no stored full-wave reference at {REFERENCE_PPW:g} points per wavelength in {REFERENCES} "
            "(benches/fullwave/caps_fdtd.py makes it)"
        )
    factor = grid_correction(stored)
    row = json.loads(json.dumps(runs[REFERENCE_PPW]))
    fdtd = row["fdtd"]
    fdtd["focal_pressure_p0"] *= factor
    fdtd["line_p0"] = [v * factor for v in fdtd["line_p0"]]
    fdtd["plane_p0"] = [[v * factor for v in r] for r in fdtd["plane_p0"]]
    row["grid_factor"] = factor
    return row


def _linear(axis: NDArray[np.float64], at: float, name: str) -> tuple[int, float]:
    """The sample before ``at`` on the increasing ``axis`` and the fraction of the way to the next;
    ValueError naming ``name`` where ``at`` lies outside the axis (no silent clamping)."""
    if not axis[0] <= at <= axis[-1]:
        raise ValueError(f"{name}: {at:.3f} mm lies outside the march's grid ({axis[0]:.3f} to {axis[-1]:.3f} mm)")
    i = int(np.clip(np.searchsorted(axis, at) - 1, 0, len(axis) - 2))
    return i, float((at - axis[i]) / (axis[i + 1] - axis[i]))


def _bilinear(
    plane: NDArray[np.float64],
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    xs: NDArray[np.float64],
    ys: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``plane`` (indexed y, x on the axes ``y``, ``x``) at every point of the grid ``ys`` x ``xs``."""
    out = np.empty((len(ys), len(xs)))
    for c, xv in enumerate(xs):
        i, u = _linear(x, float(xv), "the reference's plane, x")
        column = (1 - u) * plane[:, i] + u * plane[:, i + 1]
        for r, yv in enumerate(ys):
            j, v = _linear(y, float(yv), "the reference's plane, y")
            out[r, c] = (1 - v) * column[j] + v * column[j + 1]
    return out


def compare_fields(field: Any, ref: dict[str, Any]) -> dict[str, Any]:
    """The metrics of ``field`` (a :class:`arfi.simulation.Field` with its volume) against the
    stored reference ``ref`` (:func:`stored_parts` of the engine's field): see the module docs."""
    p0 = field.surface_pressure_pa
    volume = field.pressure_volume().pressure_pa / p0
    x, y, z = np.asarray(field.x_mm), np.asarray(field.y_mm), np.asarray(field.axis_z_mm)
    focus = field.focal_metrics
    if focus.focal_peak_pa is None or focus.focal_peak_mm is None:
        raise ValueError("the march has no focal peak to compare")
    point = tuple(float(v) for v in focus.focal_peak_mm)
    ref_point = tuple(float(v) for v in ref["focal_point_mm"])
    # Along z through the reference focus's column, bilinear across.
    lx, ly = ref["line_xy_mm"]
    i, u = _linear(x, lx, "the reference's line, x")
    j, v = _linear(y, ly, "the reference's line, y")
    line = (
        (1 - u) * (1 - v) * volume[:, j, i]
        + u * (1 - v) * volume[:, j, i + 1]
        + (1 - u) * v * volume[:, j + 1, i]
        + u * v * volume[:, j + 1, i + 1]
    )
    lz, lp = np.asarray(ref["line_z_mm"]), np.asarray(ref["line_p0"])
    near = np.abs(lz - ref_point[2]) <= PROFILE_MM
    _linear(z, float(lz[near].min()), "the reference's line, z")
    _linear(z, float(lz[near].max()), "the reference's line, z")
    ours_line = np.interp(lz, z, line)
    # The focal plane within PLANE_MM of the reference focus (a disc), linear between planes.
    k, t = _linear(z, float(ref["plane_z_mm"]), "the reference's plane, z")
    px, py, pp = np.asarray(ref["plane_x_mm"]), np.asarray(ref["plane_y_mm"]), np.asarray(ref["plane_p0"])
    ours = _bilinear((1 - t) * volume[k] + t * volume[k + 1], x, y, px, py)
    disc = np.hypot(px[None, :] - ref_point[0], py[:, None] - ref_point[1]) <= PLANE_MM
    row = int(np.argmin(np.abs(py - ref_point[1])))
    return {
        "focal_pressure": (focus.focal_peak_pa / p0, ref["focal_pressure_p0"]),
        "focal_point_mm": (point, ref_point),
        # Negative when the march's peak lies short along z (as the exact cases).
        "focal_position_error_mm": math.copysign(math.dist(point, ref_point), point[2] - ref_point[2]),
        "axial_error": float(np.max(np.abs(ours_line[near] - lp[near])) / ref["focal_pressure_p0"]),
        "correlation": float(np.corrcoef(ours[disc], pp[disc])[0, 1]),
        "axis": np.c_[lz, ours_line, lp],
        "focal_line": np.c_[px, ours[row], pp[row]],
    }


def compare(name: str, row: dict[str, Any] | None = None) -> FullWaveResult:
    """The march on the case ``name``'s default grid against its :func:`reference` (or ``row``, as
    :func:`reference` gives it). ValueError when there is none, or when it was made on another CT
    than the one written now."""
    import arfi

    cap = textured_caps.case(name)
    ref = row if row is not None else reference(name)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="arfi-validate-") as d:
        written = textured_caps.write_ct(cap, Path(d) / "cap.nii")
        if ref.get("ct_sha256") not in (None, written):
            raise ValueError(
                f"{name}: the stored full-wave reference was made on another CT than the one written now (re-run "
                "benches/fullwave/caps_fdtd.py)"
            )
        toml = textured_caps.scenario_toml(cap, "cap.nii", solid=ref.get("solid") is not None)
        sim = arfi.Simulation(arfi.Scenario.from_toml(toml, base_dir=d))
        march = sim.field(volume=True)
    engine = ref["engine"]
    return FullWaveResult.from_comparison(
        name,
        f"{cap.description}; against {engine['engine']} ({engine['voxel_mm']:g} mm voxels"
        + (f", x{ref['grid_factor']:.3f} for its grid error)" if "grid_factor" in ref else ")"),
        compare_fields(march, ref["fdtd"]),
        sim.grid,
        time.perf_counter() - t0,
        TOLERANCES if cap.correlation_mm is None else TEXTURED_TOLERANCES,
        engine,
    )
