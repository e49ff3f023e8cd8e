#!/usr/bin/env python3
"""The treatment envelope (``arfi envelope``): its time per target, in one process and on two
local dask.distributed workers.

The head phantom of ``arfi phantom --array hemisphere`` (650 kHz, 1024 elements, CT of 0.5 mm by
default) and a box of targets about the focus. ``run_envelope`` in one process (one task: the
plans built once) at one target and at ``n`` targets gives the first target's time and each
further target's, ``(T(n) - T(1)) / (n - 1)``; then the same ``n`` targets on a local cluster of
two worker processes (two tasks, each building its own plans, the cores shared between them),
whose values must equal the single process's. Peak RSS: of the fresh process running the call,
and of the largest worker.

Usage::

    python benches/bench_envelope.py [--targets 6] [--frequency-hz 650000] [--elements 1024] [--voxel-mm 0.5]
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


def box_about(focus_mm: list[float], n: int) -> list[list[float]]:
    """``n`` targets of a box 10 mm apart about the focus, the focus first."""
    x, y, z = focus_mm
    out = [[x, y, z]]
    for dz in (0.0, -10.0, 10.0):
        for dy in (0.0, -10.0, 10.0):
            for dx in (0.0, -10.0, 10.0):
                if (dx, dy, dz) != (0.0, 0.0, 0.0):
                    out.append([x + dx, y + dy, z + dz])
    return out[:n]


def timed(toml: str, targets: list[list[float]], out: str, workers: int, queue: mp.Queue) -> None:
    """In a fresh process: ``run_envelope``; its time, this process's peak RSS, the largest
    worker's (the children reaped once the cluster closes) and the points."""
    import arfi
    from arfi.analysis.envelope import run_envelope

    scenario = arfi.Scenario.load(toml)
    t = time.perf_counter()
    size = -(-len(targets) // workers)
    points, _ = run_envelope(scenario, targets, out, task_size=size, workers=workers)
    seconds = time.perf_counter() - t
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20
    queue.put((seconds, own, children, [p.to_row() for p in points]))


def in_process(*args: object) -> tuple[float, float, float, list]:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=timed, args=(*args, q))
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
        targets = box_about(Scenario.load(toml).to_dict()["focus"]["position_mm"], n)
        t_one, rss_one, _, _ = in_process(str(toml), targets[:1], str(Path(d) / "one"), 1)
        t_many, rss_many, _, alone = in_process(str(toml), targets, str(Path(d) / "many"), 1)
        t_two, rss_two, rss_worker, shared = in_process(str(toml), targets, str(Path(d) / "two"), 2)
    return {
        "date": _dt.date.today().isoformat(),
        "frequency_hz": frequency_hz,
        "elements": elements,
        "voxel_mm": voxel_mm,
        "targets": n,
        "first_target_s": t_one,
        "first_target_peak_gib": rss_one,
        "envelope_s": t_many,
        "envelope_peak_gib": rss_many,
        "further_target_s": (t_many - t_one) / (n - 1),
        "two_workers_s": t_two,
        "two_workers_peak_gib_per_worker": rss_worker,
        "speed_up": t_many / t_two,
        "two_workers_equal": alone == shared,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--targets", type=int, default=6)
    ap.add_argument("--frequency-hz", type=float, default=650e3)
    ap.add_argument("--elements", type=int, default=1024)
    ap.add_argument("--voxel-mm", type=float, default=0.5)
    ap.add_argument("--json")
    a = ap.parse_args()
    if not 2 <= a.targets <= 27:
        ap.error("--targets: between 2 and 27 (the further targets' time is the difference from one)")
    r = run(a.targets, a.frequency_hz, a.elements, a.voxel_mm)
    print(f"{r['date']}: {r['elements']} elements at {r['frequency_hz'] / 1e3:.0f} kHz, CT {r['voxel_mm']} mm")
    whole = r["first_target_s"] + 99 * r["further_target_s"]
    print(
        f"  one process: 1 target {r['first_target_s']:.1f} s (peak RSS {r['first_target_peak_gib']:.2f} GiB), "
        f"{r['targets']} targets {r['envelope_s']:.1f} s ({r['envelope_peak_gib']:.2f} GiB): each further target "
        f"{r['further_target_s']:.1f} s; 100 targets would take {whole:.0f} s"
    )
    print(
        f"  two local workers: {r['two_workers_s']:.1f} s (speed-up {r['speed_up']:.2f}), peak RSS "
        f"{r['two_workers_peak_gib_per_worker']:.2f} GiB per worker; values equal: {r['two_workers_equal']}"
    )
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=2) + "\n")


if __name__ == "__main__":
    main()
