#!/usr/bin/env python3
"""A poor prediction raised by the acquisitions ``arfi estimate --suggest`` asks for, one at a time.

Per seed, on the embedded default scenario (1024 elements, the default phantom): the truth is the
skull-like aberration ``sim.skull_phases(seed)``; the prediction is the truth plus an error screen
``sim.skull_phases(1000 + seed, correlation_length_mm=20, peak_to_peak_rad=3, jitter_rad=0.5)``
(a smooth field over 20 mm of about 0.7 rad RMS plus 0.5 rad independent per element: 0.9 rad
RMS in all). The element-level 0.5 rad is what no few images resolve: applied exactly, the rest
of the prediction would leave ``exp(-0.5²/2) = 0.88`` of the ideal focal pressure.

The first image is the aberrated beam in focus (0.02 rad noise); each step estimates per element
with the prediction as smooth prior (``prior_std_rad=0.9, prior_correlation_mm=20``,
``suggest=True``), scores the phases it recommends, and takes the acquisition it suggests (the
truth imaged with the suggested known phases added), up to four images in all.

Focus: the focal pressure at the target, ``|Σ_e c_e·exp(i·(truth_e − applied_e))| / |Σ_e c_e|``
with ``c_e`` each element's steered response there (``sim.element_responses()``, one reciprocal
march): the fraction of the ideal. Printed per seed per step: the focus, the suggested design and
the expected focus the suggestion gave, and the seconds of the estimate.

Usage::

    python benches/bench_poor_prediction.py [--seeds 11 12 13 14] [--images 4] [--json FILE]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import time

import numpy as np

import arfi

PRIOR_ERROR = {"correlation_length_mm": 20.0, "peak_to_peak_rad": 3.0, "jitter_rad": 0.5}
PRIOR_STD_RAD = 0.9
PRIOR_CORRELATION_MM = 20.0
NOISE_RAD = 0.02


def design(n) -> str:
    """The suggested acquisition (a focus shift, mm), for the table."""
    return "-" if n is None else "shift " + ",".join(f"{v:+g}" for v in n.focus_shift_mm)


def run(sim: arfi.Simulation, seed: int, n_images: int) -> dict:
    el = sim.with_groups(sim.n_elements)
    c = sim.element_responses() * np.exp(1j * sim.steering_phases_rad)

    def focus(applied: np.ndarray) -> float:
        return float(abs(np.sum(c * np.exp(1j * (truth - applied)))) / abs(np.sum(c)))

    truth = sim.skull_phases(seed)
    prior = truth + sim.skull_phases(1000 + seed, **PRIOR_ERROR)
    images = [sim.arfi_image(truth, noise_rad=NOISE_RAD, seed=seed)]
    known: list[np.ndarray | None] = [None]
    row: dict = {"seed": seed, "prior": focus(prior), "steps": []}
    for k in range(n_images):
        t = time.perf_counter()
        e = el.estimate(
            images,
            known,
            prior=prior,
            prior_std_rad=PRIOR_STD_RAD,
            prior_correlation_mm=PRIOR_CORRELATION_MM,
            suggest=True,
            seed=seed,
        )
        seconds = time.perf_counter() - t
        n = e.next_acquisition
        step = {
            "images": len(images),
            "focus": focus(e.recommended_phases_rad),
            "estimate": focus(e.phases_rad),
            "misfit": e.misfit,
            "seconds": seconds,
            "recommended": e.recommended,
            "kept_prediction": e.kept_prediction,
            "evaluations": e.evaluations,
            "next": None if n is None else n.to_dict(),
            "design": design(n),
        }
        row["steps"].append(step)
        print(
            f"seed {seed}: {len(images)} image(s): focus {step['focus']:.3f} ({seconds:.1f} s, {e.evaluations} "
            f"evaluations{', prediction kept' if e.kept_prediction else ''}; recommends {e.recommended}, the "
            f"estimate's own {step['estimate']:.3f}, misfit {e.misfit:.2f}); next {step['design']}"
            + ("" if n is None else f" (expected {n.expected_focus_now:.3f} -> {n.expected_focus:.3f})"),
            flush=True,
        )
        if k + 1 == n_images or n is None:
            break
        images.append(sim.arfi_image(truth + e.suggested_phases_rad, noise_rad=NOISE_RAD, seed=100 * seed + k))
        known.append(np.asarray(e.suggested_phases_rad))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13, 14])
    ap.add_argument("--images", type=int, default=4, help="images in all, the first in focus")
    ap.add_argument("--json", help="write the rows as JSON")
    args = ap.parse_args()
    sim = arfi.Simulation()
    t = time.perf_counter()
    rows = [run(sim, s, args.images) for s in args.seeds]
    total = time.perf_counter() - t
    print(
        f"\npoor prediction raised by suggested acquisitions, 1024 elements, {_dt.date.today()}, {total:.0f} s in all\n"
    )
    heads = " | ".join(f"{k} image{'s' if k > 1 else ''}" for k in range(1, args.images + 1))
    print(f"| seed | prior alone | {heads} | designs suggested |")
    print("| --- | --- |" + " --- |" * args.images + " --- |")
    for r in rows:
        focus = " | ".join(f"{s['focus']:.3f}" for s in r["steps"])
        print(f"| {r['seed']} | {r['prior']:.3f} | {focus} | {'; '.join(s['design'] for s in r['steps'][:-1])} |")
    last = [r["steps"][-1]["focus"] for r in rows]
    worst = min(min(s["focus"] for s in r["steps"]) - r["prior"] for r in rows)
    print(f"\nmean after the last image {np.mean(last):.3f}; worst step against the prior alone {worst:+.3f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"date": _dt.date.today().isoformat(), "rows": rows, "seconds": total}, f, indent=1)


if __name__ == "__main__":
    main()
