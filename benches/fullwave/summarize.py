"""Print the findings table (markdown) from benches/results/plate_transmission_*.json."""

import glob
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import plate_exact as pe  # noqa: E402


def main():
    files = sorted(glob.glob(os.path.join(HERE, "..", "results", "plate_transmission_*.json")))
    runs = {}
    for f in files:
        d = json.load(open(f))
        tag = os.path.basename(f)[len("plate_transmission_") : -5]
        runs[tag] = {round(r["angle_deg"], 3): r for r in d["rows"]}
    angles = [0, 10, 20, 25, 30, 35, 40, 50]
    variants = (
        ("lossy (4 dB/cm P and S), cs 1500 m/s", dict(), ""),
        ("lossless, cs 1500 m/s", dict(lossy=False), "_lossless"),
        ("lossy, cs 1300 m/s", dict(cs=1300.0), "_cs1300"),
        ("lossy, cs 1700 m/s", dict(cs=1700.0), "_cs1700"),
        ("lossy, FLUID plate (cs 0; the 'solid' column is then the fluid plate too)", dict(fluid=True), "_cs0"),
    )
    for variant, kw, suffix in variants:
        if suffix:
            cols = [t for t in runs if t.endswith(suffix)]
        else:
            cols = [t for t in runs if not any(t.endswith(v[2]) for v in variants[1:])]
        if not cols:
            continue
        print(
            f"\n### {variant}: cells: engine |T|^2 / exact |T|^2 for the same beam (engine / exact); the first two "
            "columns are single plane waves at the nominal angle\n"
        )
        print("| angle_deg | exact fluid plate | exact solid plate | " + " | ".join(cols) + " |")
        print("|---" * (3 + len(cols)) + "|")
        for a in angles:
            tf = abs(pe.bench_plate_T([a], fluid=True, lossy=kw.get("lossy", True))[0]) ** 2
            ts = abs(pe.bench_plate_T([a], **kw)[0]) ** 2
            cells = []
            for t in cols:
                r = runs[t].get(a)
                if r is None:
                    cells.append("")
                    continue
                cells.append(
                    f"{r['power_ratio_engine']:.3f} / {r['power_ratio_exact']:.3f} "
                    f"(x{r['ratio_engine_over_exact']:.2f})"
                )
            print(f"| {a} | {tf:.3f} | {ts:.3f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
