#!/usr/bin/env python3
"""One evaluation of the hybrid cost (paper Eq. 4), and of the cost with its gradient, in arfi
against the same algorithm in NumPy (``numpy_cost.py``), in one process, on the same kernels.

For each number of groups: the scenario's image with a seeded random aberration and noise
(σ = the scenario's noise), ``sim.cost_model(image)``, and its kernels handed to NumPy. Checks
that the two agree (relative difference of J ≤ 1e-9, of the gradient ≤ 1e-9 of its norm: they
differ by summation order only) at seeded random phases, then prints medians and ratios:

- ``arfi``: ``CostModel.cost`` through the Python API (argument checks included);
- ``arfi core``: the extension's method alone (what an optimiser inside arfi pays, plus one call);
- ``numpy``: ``numpy_cost.cost`` (a complex mat-vec per image, BLAS) and ``cost_and_gradient``.

Usage::

    python benches/bench_numpy_cost.py [--groups 16 64] [--repeats 2000] [--json FILE]
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
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy_cost  # noqa: E402
from bench_core import median_time  # noqa: E402

import arfi  # noqa: E402

TOLERANCE = 1e-9


def per_call(fn, repeats: int) -> float:
    """Median seconds per call, timed in batches of 20 calls (one call is microseconds)."""

    def batch():
        for _ in range(20):
            fn()

    return median_time(batch, max(1, repeats // 20)) / 20


def measure(groups: int, repeats: int) -> dict[str, Any]:
    sim = arfi.Simulation(groups=groups)
    rng = np.random.default_rng(groups)
    image = sim.arfi_image(rng.uniform(-np.pi, np.pi, groups), noise_rad=sim.noise_rad, seed=1)
    t = time.perf_counter()
    model = sim.cost_model(image)
    build_s = time.perf_counter() - t
    terms = model.terms()
    phases = rng.uniform(-np.pi, np.pi, groups)
    j, grad = model.cost_and_gradient(phases)
    ref_j, ref_grad = numpy_cost.cost_and_gradient(terms, phases)
    cost_error = abs(numpy_cost.cost(terms, phases) - j) / abs(j)
    grad_error = float(np.max(np.abs(ref_grad - grad)) / np.linalg.norm(grad))
    if max(cost_error, abs(ref_j - j) / abs(j), grad_error) > TOLERANCE:
        raise SystemExit(f"{groups} groups: arfi and NumPy disagree (J {cost_error:.2e}, gradient {grad_error:.2e})")
    core = model._core
    r = {
        "groups": groups,
        "n_pixels": model.n_pixels,
        "model_build_s": build_s,
        "cost_relative_difference": cost_error,
        "gradient_relative_difference": grad_error,
        "arfi_cost_s": per_call(lambda: model.cost(phases), repeats),
        "arfi_core_cost_s": per_call(lambda: core.cost(phases), repeats),
        "numpy_cost_s": per_call(lambda: numpy_cost.cost(terms, phases), repeats),
        "arfi_cost_and_gradient_s": per_call(lambda: model.cost_and_gradient(phases), repeats),
        "arfi_core_cost_and_gradient_s": per_call(lambda: core.cost_and_gradient(phases), repeats),
        "numpy_cost_and_gradient_s": per_call(lambda: numpy_cost.cost_and_gradient(terms, phases), repeats),
    }
    return r


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--groups", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--repeats", type=int, default=2000)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = [measure(g, args.repeats) for g in args.groups]
    print(
        f"# arfi cost vs NumPy, {_dt.date.today()}, {platform.processor() or platform.machine()}, {os.cpu_count()} "
        f"CPUs, RAYON_NUM_THREADS={os.environ.get('RAYON_NUM_THREADS', 'all')}\n"
    )
    print(
        "| groups | pixels | agreement J / gradient | cost: arfi (core) / NumPy (µs) | ratio | cost + gradient: arfi "
        "(core) / NumPy (µs) | ratio |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        us = {k: v * 1e6 for k, v in r.items() if k.endswith("_s")}
        print(
            f"| {r['groups']} | {r['n_pixels']} | {r['cost_relative_difference']:.1e} / "
            f"{r['gradient_relative_difference']:.1e} | {us['arfi_cost_s']:.1f} ({us['arfi_core_cost_s']:.1f}) / "
            f"{us['numpy_cost_s']:.1f} | {r['numpy_cost_s'] / r['arfi_cost_s']:.1f}x | "
            f"{us['arfi_cost_and_gradient_s']:.1f} ({us['arfi_core_cost_and_gradient_s']:.1f}) / "
            f"{us['numpy_cost_and_gradient_s']:.1f} | "
            f"{r['numpy_cost_and_gradient_s'] / r['arfi_cost_and_gradient_s']:.1f}x |"
        )
    if args.json:
        args.json.write_text(json.dumps({"date": str(_dt.date.today()), "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
