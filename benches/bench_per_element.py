#!/usr/bin/env python3
"""Timings and recovery of per-element estimation (the paper's clinical case: 1024 element-level
aberrations) on the embedded default scenario, from Python.

Workload per seed: the skull-like 1024-element aberration ``sim.skull_phases(seed)``, one noisy
aberrated image and three with seeded random known group phases (0.02 rad noise), and a CT-like
prediction (``arfi.analysis.ladder.predicted_aberration``: the aberration plus a smooth 5 rad peak-to-peak
error over 15 mm and 0.3 rad per-element jitter). Times, end to end:

* ``sim.with_groups(1024).estimate(images, known)``: the default-group warm start, the element
  field basis (one march per element) and L-BFGS on it;
* the same with ``prior=prediction, prior_std_rad=0.8`` (independent errors per element), on the
  element basis the first estimate kept (the same simulation object and images);
* the same with the errors as a smooth field, ``prior_correlation_mm=15``;

and reports each one's recovered fraction (focal ARFI after correction over the ideal, noise-free)
next to the aberrated beam's and the prediction's, and the process's peak memory.

Usage::

    python benches/bench_per_element.py [--seeds 1 2] [--json FILE]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import resource
import time

import numpy as np

from arfi import Simulation
from arfi.analysis.ladder import PREDICTION_CORRELATION_MM, PREDICTION_STD_RAD, predicted_aberration

TARGET_S = 60.0


def run(seed: int) -> dict[str, float]:
    sim = Simulation()
    truth = sim.skull_phases(seed)
    rng = np.random.default_rng(seed)
    images = [sim.arfi_image(truth, noise_rad=0.02, seed=seed)]
    known: list[np.ndarray | None] = [None]
    for k in range(3):
        d = rng.uniform(-np.pi, np.pi, sim.n_groups)
        images.append(sim.arfi_image(truth + d[sim.groups], noise_rad=0.02, seed=100 * seed + k))
        known.append(d)
    ideal = float(sim.arfi_image().max())

    def focus(correction: np.ndarray) -> float:
        return float(sim.arfi_image(truth - correction).max()) / ideal

    per_element = sim.with_groups(sim.n_elements)
    prediction = predicted_aberration(sim, truth, seed)
    row = {"seed": seed, "aberrated": focus(np.zeros(sim.n_elements)), "prediction": focus(prediction)}
    t = time.perf_counter()
    est = per_element.estimate(images, known, method="lbfgs", seed=seed)
    row.update(images_s=time.perf_counter() - t, images=focus(est.phases_rad))
    t = time.perf_counter()
    est = per_element.estimate(
        images, known, method="lbfgs", seed=seed, prior=prediction, prior_std_rad=PREDICTION_STD_RAD
    )
    row.update(prior_s=time.perf_counter() - t, prior=focus(est.phases_rad))
    t = time.perf_counter()
    est = per_element.estimate(
        images,
        known,
        method="lbfgs",
        seed=seed,
        prior=prediction,
        prior_std_rad=PREDICTION_STD_RAD,
        prior_correlation_mm=PREDICTION_CORRELATION_MM,
    )
    row.update(smooth_s=time.perf_counter() - t, smooth=focus(est.phases_rad))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--json", help="write the rows as JSON")
    args = ap.parse_args()
    rows = [run(s) for s in args.seeds]
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"per-element estimation from 4 images, 1024 elements, {_dt.date.today()} (target <= {TARGET_S:.0f} s each)\n"
    )
    print(
        "| seed | aberrated | prediction alone | 4 images: focus | s (basis included) | prediction + 4 images, "
        "independent: focus | s | prediction + 4 images, smooth: focus | s |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(
            f"| {r['seed']} | {r['aberrated']:.3f} | {r['prediction']:.3f} | {r['images']:.3f} | {r['images_s']:.1f} | "
            f"{r['prior']:.3f} | {r['prior_s']:.1f} | {r['smooth']:.3f} | {r['smooth_s']:.1f} |"
        )
    print(f"\npeak memory {peak_mib:.0f} MiB")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"date": _dt.date.today().isoformat(), "rows": rows, "peak_mib": peak_mib}, f, indent=1)


if __name__ == "__main__":
    main()
