"""The full-wave references of the textured caps (:mod:`arfi.validation.textured_caps`): the ITRUSST bowl
(500 kHz) through a three-layer skull cap about its focus, uniform or with a diploë textured over
1 and 3 mm, computed by BabelViscoFDTD through ``arfi field --engine fdtd``'s code
(:mod:`arfi.validation.fdtd`) at 6 points per wavelength, with the calibration case: the suite's
homogeneous cortical shell, the engine's error where the exact answer is known, which ``arfi
validate`` divides out. Writes ``python/arfi/validation/data/fullwave_caps.json`` (merged: one entry per case
and points per wavelength), which ``arfi validate`` compares the march with.

    python benches/fullwave/caps_fdtd.py [--case cap_uniform cap_texture1 cap_texture3 shell] [--ppw 6] [--solid]

Bone is a fluid by default (each case about 14 min on 2 cores at 0.5 mm). ``--solid`` gives it the
dense bone's shear (1500 m/s, scaled by 1 - porosity): 750 m/s in the uniform diploë, which sets
voxels of 0.25 mm (about 3 h a case); a textured diploë's most porous voxels carry 150-225 m/s,
which needs voxels beyond this machine's memory.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import tempfile
from pathlib import Path

import arfi
from arfi.validation import fdtd, textured_caps
from arfi.validation.fullwave_caps import stored_parts

OUT = Path(__file__).resolve().parents[2] / "python" / "arfi" / "validation" / "data" / "fullwave_caps.json"


def run(name: str, ppw: float, solid: bool) -> dict:
    cap = textured_caps.case(name)
    with tempfile.TemporaryDirectory() as d:
        fingerprint = textured_caps.write_ct(cap, Path(d) / "cap.nii")
        sim = arfi.Simulation(arfi.Scenario.from_toml(textured_caps.scenario_toml(cap, "cap.nii", solid), base_dir=d))
        march = sim.field(volume=True)
        r = fdtd.run(sim, march, None, fdtd.FdtdOptions(points_per_wavelength=ppw), progress=print)
        f = sim.field_from_volume(r.plane, r.z_mm, r.axis, r.magnitude)
    engine_parts, marched = stored_parts(f), stored_parts(march)
    return {
        "case": name,
        "description": cap.description,
        "correlation_mm": cap.correlation_mm,
        "seed": cap.seed,
        "ct_sha256": fingerprint,
        "solid": {
            "shear_sound_speed_m_s": textured_caps.SHEAR_M_S,
            "shear_attenuation_db_cm_mhz": textured_caps.SHEAR_DB_CM_MHZ,
        }
        if solid
        else None,
        "points_per_wavelength": ppw,
        "fdtd": engine_parts,
        "march_when_made": {k: marched[k] for k in ("focal_pressure_p0", "focal_point_mm")},
        "engine": {
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


def calibration(ppw: float) -> dict:
    """The calibration case: the validation suite's homogeneous cortical shell (radii 30-36.5 mm
    about the focus, the caps' faces), whose exact solution is known, through the engine at
    ``ppw``: taken from ``benches/results/fdtd_scenarios.json`` where ``scenario_fdtd.py`` stored
    it, else run by it."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import scenario_fdtd

    rows = json.loads(scenario_fdtd.OUT.read_text()) if scenario_fdtd.OUT.exists() else []
    found = [r for r in rows if (r["case"], r["points_per_wavelength"]) == ("shell", ppw)]
    r = found[0] if found else scenario_fdtd.run("shell", ppw)
    return {
        "case": "shell",
        "description": r["description"],
        "points_per_wavelength": ppw,
        "exact_focal_pressure_p0": r["exact_focal_pressure_p0"],
        "exact_focal_point_mm": r["exact_focal_point_mm"],
        "fdtd": {"focal_pressure_p0": r["fdtd_focal_pressure_p0"], "focal_point_mm": r["fdtd_focal_point_mm"]},
        "march_when_made": {
            "focal_pressure_p0": r["march_focal_pressure_p0"],
            "focal_point_mm": r["march_focal_point_mm"],
        },
        "engine": r["fdtd"],
        "date": r["date"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--case",
        nargs="+",
        default=[c.name for c in textured_caps.CAPS] + ["shell"],
        help="the caps, and shell: the calibration (the engine's error where the exact answer is known)",
    )
    ap.add_argument("--ppw", type=float, default=6.0)
    ap.add_argument("--solid", action="store_true", help="bone as a solid (see above); default a fluid")
    args = ap.parse_args()
    for name in args.case:
        row = calibration(args.ppw) if name == "shell" else run(name, args.ppw, args.solid)
        rows = json.loads(OUT.read_text()) if OUT.exists() else []
        print(
            json.dumps(
                {k: v for k, v in row.items() if k != "fdtd"}
                | {"fdtd_focus": row["fdtd"]["focal_pressure_p0"], "fdtd_point": row["fdtd"]["focal_point_mm"]}
            )
        )
        rows = [r for r in rows if (r["case"], r["points_per_wavelength"]) != (name, args.ppw)] + [row]
        OUT.parent.mkdir(exist_ok=True)
        OUT.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
