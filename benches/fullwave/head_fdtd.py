"""The reference of ``arfi validate``'s case ``head220`` (:mod:`arfi.validation.fullwave_head`): the head
phantom at 220 kHz with the 256-element hemisphere, run by ``arfi field --engine fdtd``
(BabelViscoFDTD) at 6 and 5 points per wavelength, the first scaled by the engine's error there
(second order: ``p(h) = p + c·h²``), and beside it the march (``arfi field``) as it was when the runs were made.
Writes ``python/arfi/validation/data/fullwave_head.json``.

    python benches/fullwave/head_fdtd.py [--work DIR]

The engine takes about 23 min at 6 points per wavelength (316 x 316 x 157 voxels of 1.136 mm, 1440
steps) and 12 min at 5 (268 x 268 x 136 of 1.364 mm) on 2 cores; the march about 2 s (made
each time). The engine's runs whose output files are in ``--work`` already are not made again
(refused when that folder's CT was another).
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from arfi.validation import fdtd
from arfi.validation import fullwave_head as vh

PPW = (6.0, 5.0)


def arfi(*args: str) -> None:
    """Runs an ``arfi`` command, its output shown; stops on failure."""
    subprocess.run([sys.executable, "-m", "arfi", *args], check=True)


def run(work: Path, scenario: Path, engine: str, ppw: float | None = None) -> tuple[Any, dict[str, Any]]:
    """``arfi field`` on the scenario with ``engine`` (the engine's runs reused from ``work``): its
    npz and JSON."""
    stem = work / (engine if ppw is None else f"{engine}{ppw:g}")
    npz, js = stem.with_suffix(".npz"), stem.with_suffix(".json")
    if engine == "has" or not js.exists():
        extra = ["--engine", "fdtd", "--fdtd-points-per-wavelength", f"{ppw:g}"] if engine == "fdtd" else []
        arfi("field", "--scenario", str(scenario), "--out", str(npz), "--json", str(js), *extra)
    return np.load(npz), json.loads(js.read_text())


def parts(f: Any, j: dict[str, Any], cut: bool = True) -> dict[str, Any]:
    """:func:`arfi.validation.fullwave_head.parts` of a run's npz ``f`` and JSON ``j``."""
    return vh.parts(
        f["pressure"],
        f["x_mm"],
        f["y_mm"],
        float(f["z_mm"]),
        f["axis_z_mm"],
        f["axis_pressure"],
        j["focal_peak_pa"],
        j["focal_peak_mm"],
        float(f["surface_pressure_pa"]),
        cut=cut,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--work",
        type=Path,
        default=None,
        help="folder for the CT, the scenario and the engines' outputs (default: a temporary one)",
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        scenario, sha = vh.write_inputs(work)
        # The engine's runs kept in the folder must be of this CT.
        made = work / "ct.sha256"
        if made.exists() and made.read_text().strip() != sha:
            raise SystemExit(f"{work}: its engine runs were made on another CT; empty the folder")
        made.write_text(sha + "\n")
        f, j = run(work, scenario, "has")
        march_whole, march = parts(f, j, cut=False), parts(f, j)
        runs = []
        for ppw in PPW:
            f, j = run(work, scenario, "fdtd", ppw)
            runs.append({"points_per_wavelength": ppw, "fdtd": j["fdtd"], "parts": parts(f, j)})
        fine, coarse = sorted(runs, key=lambda r: r["fdtd"]["voxel_mm"])[:2]
        ref = vh.scaled(fine["parts"], coarse["parts"], fine["fdtd"]["voxel_mm"], coarse["fdtd"]["voxel_mm"])
        m = vh.metrics(march_whole, ref)
        out = {
            "case": vh.NAME,
            "frequency_hz": vh.FREQUENCY_HZ,
            "elements": vh.ELEMENTS,
            "seed": vh.SEED,
            "ct_voxel_mm": vh.VOXEL_MM,
            "ct_sha256": sha,
            "engine": fdtd.ENGINE,
            "engine_version": fdtd.ENGINE_VERSION,
            "reference": ref,
            "runs": runs,
            "march": march,
            "march_against_reference": {
                k: m[k]
                for k in ("focal_pressure", "focal_point_mm", "focal_position_error_mm", "axial_error", "correlation")
            },
            "date": datetime.date.today().isoformat(),
        }
        vh.REFERENCE.write_text(json.dumps(out, indent=1) + "\n")
        print(json.dumps(out["march_against_reference"], indent=1))
        for r in runs:
            print(
                f"{r['points_per_wavelength']:g} points per wavelength: {r['parts']['focal_pressure_p0']:.4f} p0 at "
                f"{np.round(r['parts']['focal_point_mm'], 2).tolist()} mm, {r['fdtd']['seconds']:.0f} s; limit "
                f"{ref['focal_pressure_p0']:.4f} at {np.round(ref['extrapolated_focal_point_mm'], 2).tolist()} mm"
            )


if __name__ == "__main__":
    main()
