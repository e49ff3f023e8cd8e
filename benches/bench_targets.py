#!/usr/bin/env python3
"""Predictions at many targets (``arfi.predict_targets``) against one ``arfi.predict`` per target.

The head phantom of ``arfi phantom --array hemisphere`` (650 kHz, 1024 elements, CT of 0.5 mm by
default). ``predict_targets`` builds each head's plan once (the head without bone, then the
skull) and marches from every target; ``predict`` builds both plans for its one target. Timed
in one process: ``predict`` at the focus (the first target), then ``predict_targets`` at ``n``
targets about the focus (a ring of radius 10 mm and ±10 mm along z); printed: the first
target's time, each further target's ``(T(n) - T(1 target)) / (n - 1)`` from the same call at
one target, the peak RSS of a fresh process per call (the process's maximum, so each call runs
in its own), and the largest difference between the two paths' phases (0: the same bits).

Usage::

    python benches/bench_targets.py [--targets 5] [--frequency-hz 650000] [--elements 1024] [--voxel-mm 0.5]
        [--json FILE]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import multiprocessing as mp
import resource
import tempfile
import time
from pathlib import Path

import numpy as np


def targets_about(focus_mm: tuple[float, float, float], n: int) -> list[tuple[float, float, float]]:
    """The focus and ``n - 1`` targets about it: a ring of radius 10 mm in the focal plane, then
    10 mm before and beyond the focus."""
    x, y, z = focus_mm
    out = [(x, y, z)]
    ring = max(n - 3, 1)
    for k in range(ring):
        a = 2 * np.pi * k / ring
        out.append((x + 10 * np.cos(a), y + 10 * np.sin(a), z))
    out += [(x, y, z - 10), (x, y, z + 10)]
    return out[:n]


def timed(toml: str, targets: list[tuple[float, float, float]] | None, queue: mp.Queue) -> None:
    """In a fresh process: ``predict`` (``targets`` None) or ``predict_targets``; its time, peak
    RSS and phases."""
    import arfi

    scenario = arfi.Scenario.load(toml)
    t = time.perf_counter()
    if targets is None:
        phases = [arfi.predict(scenario).phases_rad]
    else:
        phases = [p.phases_rad for p in arfi.predict_targets(scenario, targets)]
    seconds = time.perf_counter() - t
    queue.put((seconds, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, [p.tolist() for p in phases]))


def in_process(toml: str, targets: list[tuple[float, float, float]] | None) -> tuple[float, float, list]:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=timed, args=(toml, targets, q))
    p.start()
    out = q.get()
    p.join()
    return out


def run(n: int, frequency_hz: float, elements: int, voxel_mm: float) -> dict:
    from arfi import Scenario
    from arfi.cli import main as arfi_main

    with tempfile.TemporaryDirectory() as d:
        ct, toml = Path(d) / "head.nii.gz", Path(d) / "head.toml"
        argv = ["phantom", "--out", str(ct), "--scenario-out", str(toml), "--voxel-mm", str(voxel_mm)]
        assert arfi_main([*argv, "--array", "hemisphere"]) == 0
        text = toml.read_text().replace("frequency_hz = 650000.0", f"frequency_hz = {frequency_hz!r}")
        toml.write_text(text.replace("elements = 1024", f"elements = {elements}"))
        focus = tuple(Scenario.load(toml).to_dict()["focus"]["position_mm"])
        targets = targets_about(focus, n)
        t_single, rss_single, single = in_process(str(toml), None)
        t_one, rss_one, _ = in_process(str(toml), targets[:1])
        t_many, rss_many, many = in_process(str(toml), targets)
    return {
        "date": _dt.date.today().isoformat(),
        "frequency_hz": frequency_hz,
        "elements": elements,
        "voxel_mm": voxel_mm,
        "targets": n,
        "predict_s": t_single,
        "predict_peak_gib": rss_single,
        "predict_targets_one_s": t_one,
        "predict_targets_s": t_many,
        "predict_targets_peak_gib": rss_many,
        "further_target_s": (t_many - t_one) / (n - 1),
        "max_phase_difference_rad": float(np.max(np.abs(np.subtract(single[0], many[0])))),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--targets", type=int, default=5)
    ap.add_argument("--frequency-hz", type=float, default=650e3)
    ap.add_argument("--elements", type=int, default=1024)
    ap.add_argument("--voxel-mm", type=float, default=0.5)
    ap.add_argument("--json")
    a = ap.parse_args()
    if a.targets < 2:
        ap.error("--targets: at least 2 (the further targets' time is the difference from one)")
    r = run(a.targets, a.frequency_hz, a.elements, a.voxel_mm)
    print(f"{r['date']}: {r['elements']} elements at {r['frequency_hz'] / 1e3:.0f} kHz, CT {r['voxel_mm']} mm")
    print(f"  arfi.predict (one target): {r['predict_s']:.1f} s, peak RSS {r['predict_peak_gib']:.2f} GiB")
    print(
        f"  arfi.predict_targets: 1 target {r['predict_targets_one_s']:.1f} s, {r['targets']} targets "
        f"{r['predict_targets_s']:.1f} s (peak RSS {r['predict_targets_peak_gib']:.2f} GiB): each further target "
        f"{r['further_target_s']:.1f} s; phases at the focus differ from predict's by "
        f"{r['max_phase_difference_rad']:.1e} rad"
    )
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=2) + "\n")


if __name__ == "__main__":
    main()
