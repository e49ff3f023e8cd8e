#!/usr/bin/env python3
"""CT-based prediction (``arfi.predict``) against the naive one march per element.

The head phantom of ``arfi phantom --array hemisphere`` in the hemisphere (R 150 mm, out to
60°): ``arfi.predict`` gets every element's pressure at the focus from two transposed marches
(through the skull and through the head without bone) and one transposed projection. The naive
approach marches each element's source plane through the skull on its own: one march per
element, each costing what one forward march of the whole array costs (``Simulation.field``,
timed here; a single element's projection onto the source plane is a small part of it), plus
the same simulation build, and the reference head again. Printed: the prediction's time and
peak memory, the simulation build and one march, the naive estimate
``build + 2·n_elements·march`` (skull and reference) and the ratio. The naive time is an
estimate from the timed march, not run (hours at 650 kHz).

Usage::

    python benches/bench_predict.py [--frequency-hz 650000] [--elements 1024] [--voxel-mm 0.5] [--json FILE]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import resource
import tempfile
import time
from pathlib import Path

from arfi.analysis.prediction import predict
from arfi.cli import main as arfi_main
from arfi.scenario import Scenario
from arfi.simulation import Simulation


def run(frequency_hz: float, elements: int, voxel_mm: float) -> dict[str, float | int | str]:
    with tempfile.TemporaryDirectory() as d:
        ct, toml = Path(d) / "head.nii.gz", Path(d) / "head.toml"
        assert (
            arfi_main(
                [
                    "phantom",
                    "--out",
                    str(ct),
                    "--scenario-out",
                    str(toml),
                    "--voxel-mm",
                    str(voxel_mm),
                    "--array",
                    "hemisphere",
                ]
            )
            == 0
        )
        text = toml.read_text().replace("frequency_hz = 650000.0", f"frequency_hz = {frequency_hz!r}")
        toml.write_text(text.replace("elements = 1024", f"elements = {elements}"))
        scenario = Scenario.load(toml)
        t = time.perf_counter()
        p = predict(scenario)
        t_predict = time.perf_counter() - t
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
        t = time.perf_counter()
        sim = Simulation(scenario)
        t_build = time.perf_counter() - t
        t = time.perf_counter()
        sim.field()
        t_march = time.perf_counter() - t
        grid = sim.grid
    naive = t_build + 2 * elements * t_march
    return {
        "date": _dt.date.today().isoformat(),
        "frequency_hz": frequency_hz,
        "elements": elements,
        "voxel_mm": voxel_mm,
        "grid": f"{grid.nx} x {grid.ny} x {grid.nz}, {grid.dx_mm:.3f} mm",
        "predict_s": t_predict,
        "predict_peak_gib": peak,
        "simulation_build_s": t_build,
        "one_march_s": t_march,
        "naive_estimate_s": naive,
        "ratio": naive / t_predict,
        "corrected_of_optimal": p.corrected_pa / p.optimal_pa,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frequency-hz", type=float, default=650e3)
    ap.add_argument("--elements", type=int, default=1024)
    ap.add_argument("--voxel-mm", type=float, default=0.5)
    ap.add_argument("--json")
    a = ap.parse_args()
    r = run(a.frequency_hz, a.elements, a.voxel_mm)
    print(
        f"{r['date']}: {r['elements']} elements at {r['frequency_hz'] / 1e3:.0f} kHz, CT {r['voxel_mm']} mm, grid "
        f"{r['grid']}"
    )
    print(
        f"  arfi.predict: {r['predict_s']:.1f} s, peak RSS {r['predict_peak_gib']:.2f} GiB (the process's: the "
        "prediction runs first)"
    )
    print(
        f"  naive: build {r['simulation_build_s']:.1f} s + 2 x {r['elements']} marches of {r['one_march_s']:.2f} s = "
        f"{r['naive_estimate_s']:.0f} s (estimated); ratio {r['ratio']:.0f}x"
    )
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=2) + "\n")


if __name__ == "__main__":
    main()
