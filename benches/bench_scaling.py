#!/usr/bin/env python3
"""How the cost of arfi grows: time and peak memory against the lateral grid size, the number of
slices, the number of groups and the number of threads, each configuration in its own process
(so that its peak resident memory, ``ru_maxrss``, is its own).

- lateral grid: the default scenario with ``[grid] lateral_size_mm`` set for 128² … 1024²
  samples at the default spacing (0.68 mm; the grid rounds to FFT-friendly lengths and the
  table gives the lengths used); ``Simulation()`` (plan build: one march of the reference beam)
  and ``sim.field()`` (one march over all planes), compared with ``N²·log N`` from 128²;
- slices: the default grid with ``[grid] step_mm`` 0.68, 0.34, 0.17 mm (189 … ~750 planes);
- groups: ``Simulation(groups=G)`` for 16, 32, 64, 128, 256 (the most the group kernels take)
  and, with ``--elements``, 1024 (one per element, the field-basis estimator, L-BFGS only):
  the group fields and model, then the time per evaluation of ``sim.estimate``: cost and
  gradient (L-BFGS) and cost alone (Nelder–Mead), the optimiser's own seconds over its
  evaluations;
- threads: ``RAYON_NUM_THREADS`` 1 and 2 for ``sim.field()`` and the 16-group estimation.

Usage::

    python benches/bench_scaling.py [--repeats 3] [--elements] [--parts groups ...] [--png scaling.png] [--json FILE]

``--parts`` runs only some of ``lateral slices groups threads``; with ``--json FILE`` naming an
existing file, the other parts are kept from it (the table and plot show them all).

Prints Markdown tables with the date and the machine.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

from bench_core import median_time

SPACING_MM = 0.6818181818181819  # the default scenario's lateral spacing (lambda/4 in water at 550 kHz)


def scenario(grid: dict[str, float]) -> str:
    import arfi

    text = arfi.Scenario.default().to_toml()
    lines = "".join(f"{k} = {v}\n" for k, v in grid.items())
    return text.replace("[grid]\n", "[grid]\n" + lines, 1)


def one(config: dict) -> dict:
    """Runs one configuration in this process and returns its measurements."""
    import arfi

    out: dict = dict(config)
    kind, repeats = config["kind"], config["repeats"]
    if kind in ("lateral", "slices", "threads_field"):
        t = time.perf_counter()
        sim = arfi.Simulation(arfi.Scenario.from_toml(scenario(config.get("grid", {}))))
        out["build_s"] = time.perf_counter() - t
        g = sim._core.grid
        out["nx"], out["ny"], out["nz"] = g.nx, g.ny, g.nz
        out["field_s"] = median_time(sim.field, repeats)
    else:  # groups, threads_estimate
        sim = arfi.Simulation(groups=config["groups"])
        image = sim.arfi_image(sim.skull_phases(1), noise_rad=0.02, seed=1)
        per_element = config["groups"] == sim.n_elements  # Nelder-Mead is not offered per element
        for method, key in (("lbfgs", "gradient"),) + ((("nelder-mead", "cost"),) if not per_element else ()):
            t = time.perf_counter()
            est = sim.estimate(image, method=method, max_evaluations=config["evaluations"])
            wall = time.perf_counter() - t
            # est.seconds is the optimiser alone: the rest is the group fields and the model.
            out[f"{key}_per_evaluation_s"] = est.seconds / max(est.evaluations, 1)
            out[f"{key}_evaluations"] = est.evaluations
            out[f"{key}_estimate_s"] = wall
            out["model_s"] = wall - est.seconds
    out["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def run(config: dict, threads: int | None = None) -> dict:
    env = dict(os.environ)
    if threads is not None:
        env["RAYON_NUM_THREADS"] = str(threads)
    r = subprocess.run([sys.executable, __file__, "--one", json.dumps(config)], env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{config}: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode}")
    res = json.loads(r.stdout)
    res["threads"] = threads or os.cpu_count()
    print(f"  {res}", file=sys.stderr)
    return res


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 4, figsize=(19, 4.5))
    lat = results["lateral"]
    n = [r["nx"] for r in lat]
    ax[0].loglog(n, [r["field_s"] for r in lat], "o-", label="sim.field() (march, all planes)")
    ax[0].loglog(n, [r["build_s"] for r in lat], "s-", label="Simulation() (plan build)")
    ref = [lat[0]["field_s"] * (m * m * math.log(m)) / (n[0] ** 2 * math.log(n[0])) for m in n]
    ax[0].loglog(n, ref, "k--", label="N² log N from the smallest")
    ax[0].set(xlabel="lateral samples N (grid N x N)", ylabel="time (s)", title="lateral grid")
    ax[0].legend(fontsize=8)
    sl = results["slices"]
    ax[1].plot([r["nz"] for r in sl], [r["field_s"] for r in sl], "o-")
    ax[1].set(xlabel="planes", ylabel="sim.field() time (s)", title="slices (180 x 180)")
    gr = results["groups"]
    g = [r["groups"] for r in gr]
    nm = [r for r in gr if "cost_per_evaluation_s" in r]
    ax[2].loglog([r["groups"] for r in nm], [r["cost_per_evaluation_s"] * 1e3 for r in nm], "o-", label="cost (ms)")
    ax[2].loglog(g, [r["gradient_per_evaluation_s"] * 1e3 for r in gr], "^-", label="cost + gradient (ms)")
    ax[2].loglog(g, [r["model_s"] for r in gr], "s-", label="group fields + model (s)")
    ax[2].set(xlabel="groups", title="estimation")
    ax[2].legend(fontsize=8)
    ax[3].loglog(n, [r["peak_rss_mib"] for r in lat], "o-", label="lateral grid N x N (x axis: N)")
    ax[3].loglog(g, [r["peak_rss_mib"] for r in gr], "s-", label="groups (x axis: groups)")
    ax[3].set(xlabel="N or groups", ylabel="peak resident memory (MiB)", title="memory (whole process)")
    ax[3].legend(fontsize=8)
    fig.suptitle(f"arfi scaling, {results['date']}, {results['machine']}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


PARTS = ("lateral", "slices", "groups", "threads")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--elements", action="store_true", help="also 1024 groups (per element; ~1 min of basis build)")
    ap.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    ap.add_argument("--png", type=Path, default=Path("scaling.png"))
    ap.add_argument("--json", type=Path)
    ap.add_argument("--one", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(json.loads(args.one))))
        return 0
    rep = args.repeats
    results: dict = json.loads(args.json.read_text()) if args.json and args.json.is_file() else {}
    results.update({"machine": f"{platform.machine()}, {os.cpu_count()} cpus"})
    for part in args.parts:
        results.setdefault("dates", {})[part] = _dt.date.today().isoformat()
    if "lateral" in args.parts:
        results["lateral"] = [
            run({"kind": "lateral", "repeats": rep, "grid": {"lateral_size_mm": n * SPACING_MM}})
            for n in (128, 256, 512, 1024)
        ]
    if "slices" in args.parts:
        results["slices"] = [
            run({"kind": "slices", "repeats": rep, "grid": {"step_mm": dz}}) for dz in (0.68, 0.34, 0.17)
        ]
    if "groups" in args.parts:
        groups = (16, 32, 64, 128, 256) + ((1024,) if args.elements else ())
        results["groups"] = [run({"kind": "groups", "repeats": 1, "groups": g, "evaluations": 400}) for g in groups]
    if "threads" in args.parts:
        results["threads"] = [
            run({"kind": kind, "repeats": rep, "groups": 16, "evaluations": 400}, threads=t)
            for kind in ("threads_field", "threads_estimate")
            for t in (1, 2)
        ]
    results["date"] = max(results["dates"].values()) if "dates" in results else _dt.date.today().isoformat()

    print(f"Scaling, {results['date']}, {results['machine']}\n")
    print(
        "| lateral grid | planes | `Simulation()` (s) | `sim.field()` (s) | field / N²logN from 128² | peak memory "
        "(MiB) |"
    )
    print("| --- | --- | --- | --- | --- | --- |")
    lat = results["lateral"]
    n0 = lat[0]["nx"]
    for r in lat:
        model = lat[0]["field_s"] * (r["nx"] ** 2 * math.log(r["nx"])) / (n0**2 * math.log(n0))
        print(
            f"| {r['nx']} x {r['ny']} | {r['nz']} | {r['build_s']:.2f} | {r['field_s']:.3f} | "
            f"{r['field_s'] / model:.2f} | {r['peak_rss_mib']:.0f} |"
        )
    print(
        "\n| step (mm) | planes | `sim.field()` (s) | per plane (ms) | peak memory (MiB) |\n| --- | --- | --- | --- | "
        "--- |"
    )
    for r in results["slices"]:
        print(
            f"| {r['grid']['step_mm']} | {r['nz']} | {r['field_s']:.3f} | {r['field_s'] / (r['nz'] - 1) * 1e3:.3f} | "
            f"{r['peak_rss_mib']:.0f} |"
        )
    print(
        "\n| groups | group fields + model (s) | cost (µs) | cost + gradient (µs) | L-BFGS estimate (s) | peak memory "
        "(MiB) |"
    )
    print("| --- | --- | --- | --- | --- | --- |")
    for r in results["groups"]:
        cost = f"{r['cost_per_evaluation_s'] * 1e6:.0f}" if "cost_per_evaluation_s" in r else "-"
        print(
            f"| {r['groups']} | {r['model_s']:.2f} | {cost} | {r['gradient_per_evaluation_s'] * 1e6:.0f} | "
            f"{r['gradient_estimate_s']:.2f} | {r['peak_rss_mib']:.0f} |"
        )
    th = {(r["kind"], r["threads"]): r for r in results["threads"]}
    f1, f2 = th[("threads_field", 1)]["field_s"], th[("threads_field", 2)]["field_s"]
    e1, e2 = th[("threads_estimate", 1)]["gradient_estimate_s"], th[("threads_estimate", 2)]["gradient_estimate_s"]
    print("\n| threads | `sim.field()` (s) | 16-group L-BFGS estimate (s) |\n| --- | --- | --- |")
    print(f"| 1 | {f1:.3f} | {e1:.2f} |\n| 2 | {f2:.3f} | {e2:.2f} |")
    print(f"| speed-up | {f1 / f2:.2f}x | {e1 / e2:.2f}x |")
    plot(results, args.png)
    print(f"\nplot: {args.png}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
