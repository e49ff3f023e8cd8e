#!/usr/bin/env python3
"""Timings of ``arfi diagnose`` (target: one 128 x 96 image with the full library in at
most 30 s on 2 cores), in one Python process, on the embedded default scenario.

Cases (0.02 rad noise, seeded): noise only; the paper's story (a model without broadening meets
W = 2.7 mm); a hidden 1 mm registration shift; a hidden 5 mm slice offset; a hidden dead group;
a hidden 16-group skull-like aberration in one image (the slowest: the aberration competes with
simpler effects, so both paths are fitted in full) and in three images with known diversity
phases. Each case runs ``Simulation.diagnose`` with the whole library and reports the wall time,
the effects named and the final gap (residual RMS over the noise floor).

Usage::

    python benches/bench_diagnose.py [--repeats 1] [--json FILE]

Prints a Markdown table with the date, the machine and the ratio of each time to the target.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import time

import numpy as np

import arfi

TARGET_S = 30.0


def cases(sim: arfi.Simulation) -> list[tuple[str, arfi.Simulation, list[np.ndarray], list[np.ndarray | None]]]:
    rng = np.random.default_rng(7)

    def noisy(images: list[np.ndarray]) -> list[np.ndarray]:
        return [m + rng.normal(0.0, 0.02, m.shape) for m in images]

    aberration = sim.condense(sim.skull_phases(seed=1))
    diversity = [None] + [rng.uniform(-1.5, 1.5, sim.n_groups) for _ in range(2)]
    return [
        ("noise only", sim, noisy(sim.effect_images({})), [None]),
        (
            "paper story: model W = 0, image W = 2.7 mm",
            sim.with_calibration(0.0, sim.amplitude),
            noisy(sim.effect_images({})),
            [None],
        ),
        ("hidden shift (0.8, -0.6) mm", sim, noisy(sim.effect_images({"dx_mm": 0.8, "dy_mm": -0.6})), [None]),
        ("hidden slice offset 5 mm", sim, noisy(sim.effect_images({"dz_mm": 5.0})), [None]),
        ("hidden dead group 5", sim, noisy(sim.effect_images({"dead_groups": [5]})), [None]),
        (
            "hidden 16-group aberration, 1 image",
            sim,
            noisy(sim.effect_images({"group_phases_rad": list(aberration)})),
            [None],
        ),
        (
            "hidden 16-group aberration, 3 images",
            sim,
            noisy(sim.effect_images({"group_phases_rad": list(aberration)}, known=diversity)),
            diversity,
        ),
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args()
    sim = arfi.Simulation()
    rows = []
    for name, model, images, known in cases(sim):
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            d = model.diagnose(images, known)
            times.append(time.perf_counter() - t)
        best = min(times)
        rows.append(
            {
                "case": name,
                "images": len(images),
                "seconds": best,
                "named": d.names,
                "alternative": d.alternative.effects if d.alternative else None,
                "gap": d.residual_rms_final / d.noise_floor,
                "ratio_to_target": best / (TARGET_S * len(images)),
            }
        )
    print(
        f"arfi diagnose, {_dt.date.today()}, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"RAYON_NUM_THREADS={os.environ.get('RAYON_NUM_THREADS', 'all')}, best of {args.repeats}\n"
    )
    print("| case | images | seconds | named | alternative | gap | ratio to 30 s per image |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(
            f"| {r['case']} | {r['images']} | {r['seconds']:.1f} | {', '.join(r['named']) or '-'} | "
            f"{', '.join(r['alternative'] or []) or '-'} | {r['gap']:.2f} | {r['ratio_to_target']:.2f} |"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"date": str(_dt.date.today()), "rows": rows}, f, indent=2)


if __name__ == "__main__":
    main()
