#!/usr/bin/env python3
"""arfi's HAS against a plain NumPy implementation of the same algorithm (``numpy_has.py``), in
one process, on the same inputs: the default scenario's steered source plane marched through all
planes, keeping the focal plane and the on-axis samples (what ``sim.field()`` does).

Checks that the two agree (max |p_numpy - p_arfi| / max |p_arfi| on the focal plane ≤ 1e-6,
the required bound; they differ by FFT rounding only) and prints the medians and the ratio:

- ``arfi sim.field()``: source plane (1024 elements) + march, through the Python binding;
- ``numpy march``: the march alone (its plan, like arfi's, built beforehand);
- ``numpy plan``: building the per-step operators with the reference beam (arfi does this in
  ``arfi.Simulation()``);
- ``numpy FFTs alone``: ``fft2`` + ``ifft2`` once per step, the floor of the NumPy march.

Usage::

    python benches/bench_numpy_has.py [--repeats 7] [--json FILE]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy_has  # noqa: E402
from bench_core import median_time  # noqa: E402

import arfi  # noqa: E402

TOLERANCE = 1e-6
TARGET_RATIO = 3.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)

    sim = arfi.Simulation()
    grid = numpy_has.Grid.from_simulation(sim)
    scenario = arfi.Scenario.default().to_dict()
    medium = numpy_has.Medium(scenario, sim._core.frequency_hz)
    source = sim.source_field()

    t = time.perf_counter()
    plan = numpy_has.Plan(grid, medium, source)
    plan_s = time.perf_counter() - t
    ours = sim.field()
    plane = int(round((ours.z_mm * 1e-3 - grid.z0) / grid.dz))
    theirs, axis = plan.march(source, plane)
    error = float(np.max(np.abs(theirs - ours.pressure)) / np.max(np.abs(ours.pressure)))
    axis_error = float(np.max(np.abs(axis - ours.axis_pressure)) / np.max(np.abs(ours.axis_pressure)))

    arfi_s = median_time(sim.field, args.repeats)
    numpy_s = median_time(lambda: plan.march(source, plane), args.repeats)

    def ffts_alone() -> None:
        field = source
        for _ in plan.steps:
            field = np.fft.ifft2(np.fft.fft2(field))

    fft_s = median_time(ffts_alone, args.repeats)

    result = {
        "date": _dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cpus, "
        f"RAYON_NUM_THREADS={os.environ.get('RAYON_NUM_THREADS', 'all')}",
        "grid": f"{grid.nx} x {grid.ny} x {grid.nz}",
        "focal_plane_relative_error": error,
        "axis_relative_error": axis_error,
        "arfi_field_s": arfi_s,
        "numpy_march_s": numpy_s,
        "numpy_plan_s": plan_s,
        "numpy_ffts_s": fft_s,
        "ratio": numpy_s / arfi_s,
    }
    print(f"HAS, default scenario ({result['grid']}, {len(plan.steps)} steps), {result['date']}, {result['machine']}")
    print(f"agreement: focal plane {error:.1e}, axis {axis_error:.1e} (bound {TOLERANCE:g})")
    print("| what | median (ms) |\n| --- | --- |")
    for name, key in [
        ("arfi `sim.field()` (source + march)", "arfi_field_s"),
        ("NumPy march", "numpy_march_s"),
        ("NumPy FFTs alone (fft2 + ifft2 per step)", "numpy_ffts_s"),
        ("NumPy plan (once)", "numpy_plan_s"),
    ]:
        print(f"| {name} | {result[key] * 1e3:.1f} |")
    print(f"arfi is {result['ratio']:.2f}x faster than NumPy (target >= {TARGET_RATIO:g}x)")
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0 if error <= TOLERANCE and axis_error <= TOLERANCE else 1


if __name__ == "__main__":
    sys.exit(main())
