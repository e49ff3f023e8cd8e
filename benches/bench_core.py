#!/usr/bin/env python3
"""Timings of the arfi core on the embedded default scenario (the paper's phantom experiment), in
one Python process.

Times ``arfi.Simulation()`` (resolve + grid + steering + one HAS march to build the plan),
``sim.field()`` (one march over all planes; the focal plane and the axis are kept) and
``sim.arfi_image()`` (one HAS run to the focal slab + the MR forward model), and reports the
peak resident memory of the process (``resource.getrusage(...).ru_maxrss``). The 16 group
fields in one batch have no Python binding: they are timed by the Rust example
``crates/has-core/examples/group_fields.rs`` (run with cargo, in its own process), or read from
the criterion results of ``cargo bench -p has-bench`` with ``--group-fields criterion``.

Usage::

    python benches/bench_core.py [--repeats 5] [--group-fields cargo|criterion|skip] [--json FILE]

Prints a Markdown table with the date, the machine and the ratio of each figure to its target.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent

# Targets of the core benchmarks.
TARGET_RUN_S = 0.5  # one HAS run to the focal slab
TARGET_GROUPS_S = 3.0  # 16 group fields in one batch
TARGET_PEAK_BYTES = 1 << 30  # peak memory of the default run


def peak_rss_bytes() -> int:
    """Peak resident set size of this process so far (ru_maxrss is KiB on Linux, bytes on macOS)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(r) if sys.platform == "darwin" else int(r) * 1024


def timed(fn: Callable[[], Any], repeats: int) -> tuple[list[float], Any]:
    """Wall-clock seconds of `repeats` calls of `fn`, and the last result."""
    out = None
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return times, out


def median_time(fn: Callable[[], Any], repeats: int) -> float:
    """Median wall-clock seconds of `repeats` calls of `fn`, after one untimed call (thread pool
    start, page faults)."""
    fn()
    return statistics.median(timed(fn, repeats)[0])


def group_fields_cargo(repeats: int) -> dict[str, Any]:
    cargo = shutil.which("cargo")
    if cargo is None:
        raise RuntimeError("cargo not found on PATH (use --group-fields criterion or skip)")
    cmd = [cargo, "run", "--release", "-q", "-p", "has-core", "--example", "group_fields", str(repeats)]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{p.stderr[-2000:]}")
    d = json.loads(p.stdout.strip().splitlines()[-1])
    d["source"] = "cargo run --release --example group_fields"
    return d


def group_fields_criterion() -> dict[str, Any]:
    f = ROOT / "target/criterion/group_fields/16_groups_sources_and_batch/new/estimates.json"
    if not f.exists():
        raise RuntimeError(f"{f} not found: run `cargo bench -p has-bench -- group_fields` first")
    est = json.loads(f.read_text())
    return {
        "median_s": est["median"]["point_estimate"] * 1e-9,
        "mean_s": est["mean"]["point_estimate"] * 1e-9,
        "source": "criterion group_fields/16_groups_sources_and_batch (median)",
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="calls per timed operation (median reported)")
    ap.add_argument("--group-fields", choices=["cargo", "criterion", "skip"], default="cargo")
    ap.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    ap.add_argument("--date", default=_dt.date.today().isoformat(), help="date printed in the table")
    args = ap.parse_args(argv)
    repeats = max(1, args.repeats)

    t = time.perf_counter()
    import arfi  # noqa: PLC0415 - timed on purpose

    import_s = time.perf_counter() - t
    rss_after_import = peak_rss_bytes()

    # The first build also pays one-time costs (thread pool start, page faults of fresh memory).
    build, sim = timed(arfi.Simulation, repeats)
    g = sim.grid
    field, _ = timed(sim.field, repeats)
    image_t, image = timed(sim.arfi_image, repeats)
    peak = peak_rss_bytes()

    groups: dict[str, Any] | None = None
    groups_error = None
    if args.group_fields != "skip":
        try:
            groups = group_fields_cargo(repeats) if args.group_fields == "cargo" else group_fields_criterion()
        except (RuntimeError, OSError, ValueError, KeyError) as e:
            groups_error = str(e)

    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 0
    med = statistics.median
    res: dict[str, Any] = {
        "date": args.date,
        "machine": {
            "cores": cores,
            "cpu": platform.processor() or platform.machine(),
            "python": platform.python_version(),
        },
        "arfi_version": getattr(arfi, "__version__", "?"),
        "grid": {"nx": g.nx, "ny": g.ny, "nz": g.nz},
        "repeats": repeats,
        "import_s": import_s,
        "simulation_build_s": {"median": med(build), "min": min(build), "first": build[0], "all": build},
        "field_s": {"median": med(field), "min": min(field), "all": field},
        "arfi_image_s": {"median": med(image_t), "min": min(image_t), "all": image_t},
        "image_shape": list(image.shape),
        "peak_rss_bytes": peak,
        "rss_after_import_bytes": rss_after_import,
        "group_fields": groups,
        "group_fields_error": groups_error,
        "targets": {"one_run_s": TARGET_RUN_S, "group_fields_s": TARGET_GROUPS_S, "peak_bytes": TARGET_PEAK_BYTES},
    }

    def ratio(v: float | None, target: float) -> str:
        if v is None:
            return "—"
        return f"{v / target:.2f} ({'met' if v <= target else 'MISSED'})"

    mib = 1 << 20
    gs = groups["median_s"] if groups else None
    rows = [
        ("`arfi.Simulation()` (plan build, one HAS march)", f"{med(build):.3f} s (first {build[0]:.3f} s)", "—", "—"),
        ("`sim.field()` (march of all planes, keeping the focal plane + axis)", f"{med(field):.3f} s", "—", "—"),
        (
            "`sim.arfi_image()` (one HAS run to the focal slab)",
            f"{med(image_t):.3f} s",
            f"≤ {TARGET_RUN_S} s",
            ratio(med(image_t), TARGET_RUN_S),
        ),
        (
            "16 group fields in one batch (Rust)",
            f"{gs:.3f} s" if gs is not None else f"not measured ({groups_error or 'skipped'})",
            f"≤ {TARGET_GROUPS_S} s",
            ratio(gs, TARGET_GROUPS_S),
        ),
        (
            "peak memory of the default run (ru_maxrss)",
            f"{peak / mib:.0f} MiB ({(peak - rss_after_import) / mib:.0f} MiB above `import arfi`)",
            "≤ 1 GiB",
            ratio(peak, TARGET_PEAK_BYTES),
        ),
    ]
    print(
        f"arfi {res['arfi_version']} core benchmarks — {args.date}, {cores} cores ({res['machine']['cpu']}), Python "
        f"{res['machine']['python']}, default scenario, grid {g.nx} x {g.ny} x {g.nz}; median of {repeats}\n"
    )
    print("| operation | measured | target | ratio to target |")
    print("| --- | --- | --- | --- |")
    for r in rows:
        print("| " + " | ".join(r) + " |")
    if groups:
        print(f"\n16 group fields: {groups['source']}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
