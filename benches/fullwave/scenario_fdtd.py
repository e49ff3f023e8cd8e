"""The ITRUSST bowl (500 kHz, R 64 mm, aperture 64 mm) through the 6.5 mm cortical plate, flat
(BM3, a slab region; as a fluid and as a solid of shear speed 1500 m/s) and turned 20° about y
(read from a CT of 0.25 mm voxels), computed three
ways: the exact angular-spectrum solution, arfi's march on its default grid, and the full-wave
engine BabelViscoFDTD run by ``arfi field --engine fdtd``'s code (arfi.validation.fdtd) on the same
scenario. Writes ``benches/results/fdtd_scenarios.json`` (merged: one entry per case and points
per wavelength), which ``python/tests/test_fullwave_reference.py`` reads.

    python benches/fullwave/scenario_fdtd.py [--case bm3 bm3_solid tilt20] [--ppw 6]

(bm3 at 6 points per wavelength: about 17 min on 2 cores; tilt20 about as long.)
"""

from __future__ import annotations

import argparse
import datetime
import json
import tempfile
from pathlib import Path

import numpy as np

import arfi
from arfi import _core
from arfi.validation import fdtd

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "results" / "fdtd_scenarios.json"


SHEAR_M_S = 1500.0


def case_of(name: str, d: str) -> tuple[object, object]:
    """The case whose scenario is run, and the case whose exact solution it is compared with."""
    if name.startswith("tilt"):
        c = _core.tilted_plate_case(d, float(name[4:]))
        return c, c
    if name == "bm3_solid":  # the flat plate as a solid: its exact solution is the untilted solid plate's
        return {c.name: c for c in _core.validation_cases(d)}["bm3"], _core.tilted_plate_case(d, 0.0, SHEAR_M_S)
    c = {c.name: c for c in _core.validation_cases(d)}[name]
    return c, c


def solid(toml: str) -> str:
    """The scenario's cortical material made a solid (shear 1500 m/s, its attenuation in dB/cm/MHz
    the compressional one's, as the exact solid plate takes them)."""
    marker = 'name = "cortical"'
    assert marker in toml
    i = toml.index("attenuation_power", toml.index(marker))
    j = toml.index("\n", i)
    return toml[: j + 1] + f"shear_sound_speed_m_s = {SHEAR_M_S}\nshear_attenuation_db_cm_mhz = 8.0\n" + toml[j + 1 :]


def run(name: str, ppw: float) -> dict:
    with tempfile.TemporaryDirectory() as d:
        case, exact = case_of(name, d)
        cmp = exact.run()  # the exact solution (and the march of its own scenario; writes a CT it reads)
        toml = solid(case.scenario_toml) if name == "bm3_solid" else case.scenario_toml
        sim = arfi.Simulation(arfi.Scenario.from_toml(toml, base_dir=d))
        march = sim.field(volume=True)
        r = fdtd.run(sim, march, None, fdtd.FdtdOptions(points_per_wavelength=ppw), progress=print)
        f = sim.field_from_volume(r.plane, r.z_mm, r.axis, r.magnitude)
    p0 = f.surface_pressure_pa
    fm, mm = f.focus(), march.focus()
    # |p| along z through the exact peak's column (the line the exact profile is compared on).
    volume = f.pressure_volume().pressure_pa
    col = int(np.argmin(np.abs(np.asarray(f.x_mm) - cmp.focal_point_mm[1][0])))
    row = int(np.argmin(np.abs(np.asarray(f.y_mm))))
    line = np.c_[np.asarray(f.axis_z_mm), volume[:, row, col] / p0]
    axis = np.c_[
        np.asarray(f.axis_z_mm), abs(np.asarray(march.axis_pressure)) / p0, abs(np.asarray(f.axis_pressure)) / p0
    ]
    keep = (axis[:, 0] > 40) & (axis[:, 0] < 75)
    return {
        "case": name,
        "description": case.description + (f" (a solid: shear {SHEAR_M_S:g} m/s)" if name == "bm3_solid" else ""),
        "points_per_wavelength": ppw,
        "exact_focal_pressure_p0": cmp.focal_pressure[1],
        "exact_focal_point_mm": list(cmp.focal_point_mm[1]),
        "march_focal_pressure_p0": mm["focal_peak_pa"] / p0 if mm["focal_peak_pa"] else None,
        "march_focal_point_mm": mm["focal_peak_mm"],
        "fdtd_focal_pressure_p0": fm["focal_peak_pa"] / p0 if fm["focal_peak_pa"] else None,
        "fdtd_focal_point_mm": fm["focal_peak_mm"],
        "fdtd_axis_peak_p0": fm["axis_peak_pa"] / p0,
        "fdtd_axis_peak_z_mm": fm["axis_peak_z_mm"],
        "march_axis_peak_p0": mm["axis_peak_pa"] / p0,
        "march_axis_peak_z_mm": mm["axis_peak_z_mm"],
        "axis_z_mm_march_fdtd_p0": np.round(axis[keep], 4).tolist(),
        "axis_read": "rms",
        "exact_line_z_mm_fdtd_p0": np.round(line[keep], 4).tolist(),
        "fdtd": {
            "engine": fdtd.ENGINE,
            "engine_version": fdtd.ENGINE_VERSION,
            "voxel_mm": r.plan.h_m * 1e3,
            "shape_xyz": list(r.plan.shape),
            "steps": r.plan.steps,
            "time_step_s": r.plan.dt_s,
            "materials": r.materials,
            "steady_change": r.steady_change,
            "seconds": round(r.seconds, 1),
        },
        "date": datetime.date.today().isoformat(),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", nargs="+", default=["bm3", "bm3_solid", "tilt20"])
    ap.add_argument("--ppw", type=float, default=6.0)
    args = ap.parse_args()
    rows = json.loads(OUT.read_text()) if OUT.exists() else []
    for name in args.case:
        row = run(name, args.ppw)
        print(json.dumps({k: v for k, v in row.items() if k != "axis_z_mm_march_fdtd_p0"}, indent=1))
        rows = [r for r in rows if (r["case"], r["points_per_wavelength"]) != (name, args.ppw)] + [row]
        OUT.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
