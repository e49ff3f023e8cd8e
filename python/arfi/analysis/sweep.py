"""``arfi sweep``: Monte-Carlo studies of the hybrid estimate on a dask.distributed cluster.

Every trial is one repeat of the paper's study (``arfi.analysis.reproduce``) at one noise level, number
of images (the aberrated one plus diversity images with seeded random known group phases),
estimator and seed: calibrate on a noisy no-aberration image, estimate, correct, and score the
corrected focus (recovered fraction, gain, phase error) on noise-free images. Trials are
independent and fully seeded, so a result does not depend on which worker ran it, nor on how many
threads it had.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from arfi.analysis.cluster import client_on, distributed
from arfi.analysis.reproduce import MAX_STUDY_SEED, study_aberration, study_images
from arfi.checks import as_count
from arfi.estimation import METHODS, gain, phase_error, recovered_fraction
from arfi.io.files import atomic_write_text, csv_text, write_json
from arfi.progress import Progress
from arfi.reports.figures import pyplot, save_figure
from arfi.reports.html import figure_html, rows_table_html, write_html
from arfi.scenario import Scenario
from arfi.simulation import Simulation


@dataclass(frozen=True)
class Trial:
    """One point of the sweep."""

    noise_rad: float
    images: int
    """Images fitted jointly: the aberrated one and ``images - 1`` diversity images."""
    method: str
    seed: int
    case: int = 16
    """16 group aberrations or 1024 element aberrations (estimated on 16 groups)."""


@dataclass(frozen=True)
class TrialResult:
    """One trial's outcome: the corrected focus scored on noise-free images."""

    trial: Trial
    recovered_fraction: float
    """Corrected over ideal focal ARFI."""
    gain: float
    """Corrected over aberrated focal ARFI, minus 1."""
    phase_error_rad: float
    """RMS of the wrapped difference between the estimated and true group phases."""
    ambiguous: bool
    evaluations: int
    seconds: float
    broadening_width_mm: float
    """The calibration's W."""

    def to_dict(self) -> dict[str, Any]:
        """The row of ``sweep.csv`` and ``sweep.json``: the trial's fields, then the outcome's."""
        return {**asdict(self.trial), **{f.name: getattr(self, f.name) for f in fields(self) if f.name != "trial"}}


@dataclass(frozen=True)
class SweepPoint:
    """The trials of one (method, images, noise) over their seeds: means and spreads."""

    method: str
    images: int
    noise_rad: float
    trials: int
    recovered_fraction_mean: float
    recovered_fraction_std: float
    gain_mean: float
    phase_error_rad_mean: float
    ambiguous_fraction: float

    def to_dict(self) -> dict[str, Any]:
        """The row of ``summary.csv`` and ``sweep.json``."""
        return asdict(self)


@lru_cache(maxsize=4)
def _simulation(scenario_toml: str | None) -> Simulation:
    """One simulation per scenario per process (a worker runs many trials)."""
    return Simulation(None if scenario_toml is None else Scenario.from_toml(scenario_toml))


def run_trial(trial: Trial, scenario_toml: str | None = None) -> TrialResult:
    """Runs one trial (in whatever process calls it)."""
    sim = _simulation(scenario_toml)
    s = trial.seed
    cal = sim.calibrate(sim.arfi_image(noise_rad=trial.noise_rad, seed=10_000 + s))
    model = sim.calibrated(cal)
    _, groups_truth, applied = study_aberration(sim, trial.case, s)
    images, known = study_images(sim, applied, trial.noise_rad, s, trial.images - 1)
    est = model.estimate(images, known, method=trial.method, seed=s)
    focal_ideal = sim.focal_arfi(sim.arfi_image())[0]
    focal_aberrated = sim.focal_arfi(sim.arfi_image(applied))[0]
    focal_corrected = sim.focal_arfi(sim.arfi_image(applied - est.phases_rad[sim.groups]))[0]
    return TrialResult(
        trial=trial,
        recovered_fraction=recovered_fraction(focal_corrected, focal_ideal),
        gain=gain(focal_corrected, focal_aberrated),
        phase_error_rad=phase_error(est.phases_rad, groups_truth),
        ambiguous=bool(est.ambiguous),
        evaluations=int(est.evaluations),
        seconds=float(est.seconds),
        broadening_width_mm=float(cal.broadening_width_mm),
    )


def trials(
    noise_levels: Sequence[float],
    image_counts: Sequence[int],
    methods: Sequence[str],
    seeds: int,
    case: int = 16,
    first_seed: int = 0,
) -> list[Trial]:
    """Every combination, checked (ValueError naming the parameter); the trials' seeds are
    ``first_seed``, ``first_seed + 1``, ... (``first_seed`` at most ``MAX_STUDY_SEED``)."""
    if not noise_levels or any(not (np.isfinite(n) and n >= 0) for n in noise_levels):
        raise ValueError(f"noise_rad: need finite levels >= 0, got {list(noise_levels)}")
    if not image_counts or any(not 1 <= int(k) <= 33 for k in image_counts):
        raise ValueError(f"images: need counts between 1 and 33, got {list(image_counts)}")
    if not methods or any(m not in METHODS for m in methods):
        raise ValueError(f"methods: each must be one of {', '.join(METHODS)}, got {list(methods)}")
    if not 1 <= seeds <= 10_000:
        raise ValueError(f"seeds: must be between 1 and 10000, got {seeds}")
    if case not in (16, 1024):
        raise ValueError(f"case: must be 16 or 1024, got {case}")
    first_seed = as_count(first_seed, "first_seed", 0, MAX_STUDY_SEED)
    return [
        Trial(float(n), int(k), m, first_seed + s, case)
        for n, k, m, s in itertools.product(noise_levels, image_counts, methods, range(seeds))
    ]


def run_sweep(
    points: Sequence[Trial],
    scenario: Scenario | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
) -> list[TrialResult]:
    """Runs the trials on dask.distributed (an existing cluster at ``scheduler``, or a local one)
    and returns their results in the order of ``points``."""
    as_completed = distributed("sweep").as_completed
    toml = None if scenario is None else scenario.to_toml()
    client, cluster = client_on(scheduler, workers or os.cpu_count() or 1, "sweep")
    bar = Progress("sweep", len(points), "trials", enabled=progress)
    try:
        futures = client.map(run_trial, list(points), scenario_toml=toml, pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        rows: list[TrialResult | None] = [None] * len(points)
        for f in as_completed(futures):
            rows[index[f.key]] = f.result()
            bar.advance()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return [r for r in rows if r is not None]


def summarise(rows: Sequence[TrialResult]) -> list[SweepPoint]:
    """Mean and standard deviation of the metrics per (method, images, noise)."""
    groups: dict[tuple[str, int, float], list[TrialResult]] = {}
    for r in rows:
        groups.setdefault((r.trial.method, r.trial.images, r.trial.noise_rad), []).append(r)
    out = []
    for (method, images, noise), rs in sorted(groups.items()):
        rec = np.array([r.recovered_fraction for r in rs])
        out.append(
            SweepPoint(
                method=method,
                images=images,
                noise_rad=noise,
                trials=len(rs),
                recovered_fraction_mean=float(rec.mean()),
                recovered_fraction_std=float(rec.std()),
                gain_mean=float(np.mean([r.gain for r in rs])),
                phase_error_rad_mean=float(np.mean([r.phase_error_rad for r in rs])),
                ambiguous_fraction=float(np.mean([r.ambiguous for r in rs])),
            )
        )
    return out


def plot(summary: Sequence[SweepPoint], path: Path) -> None:
    """Recovered fraction against noise, one line per number of images, one panel per method."""
    plt = pyplot()
    methods = sorted({s.method for s in summary})
    fig, axes = plt.subplots(1, len(methods), figsize=(4.5 * len(methods), 3.6), squeeze=False, sharey=True)
    for ax, method in zip(axes[0], methods):
        for images in sorted({s.images for s in summary}):
            pts = sorted(
                (s.noise_rad, s.recovered_fraction_mean, s.recovered_fraction_std)
                for s in summary
                if s.method == method and s.images == images
            )
            x, y, e = (np.array(v) for v in zip(*pts))
            ax.errorbar(x, y, yerr=e, marker="o", capsize=3, label=f"{images} image{'s' if images > 1 else ''}")
        ax.set(title=method, xlabel="ARFI noise σ (rad)", ylim=(0, 1.05))
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("recovered fraction of the ideal focus")
    axes[0][-1].legend(fontsize=8)
    save_figure(fig, path)


def sweep_json(rows: Sequence[TrialResult], summary: Sequence[SweepPoint]) -> dict[str, Any]:
    """The JSON document of a sweep: ``trials`` and ``summary`` (the CSV files' rows) and
    ``files``."""
    return {
        "trials": [r.to_dict() for r in rows],
        "summary": [p.to_dict() for p in summary],
        "files": ["sweep.csv", "summary.csv", "sweep.png", "report.html"],
    }


def write_results(rows: Sequence[TrialResult], out: Path) -> list[SweepPoint]:
    """``sweep.csv`` (one row per trial), ``summary.csv``, ``sweep.png``, ``report.html`` and
    ``sweep.json`` in ``out``; returns the summary."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summarise(rows)
    doc = sweep_json(rows, summary)
    points = doc["summary"]
    atomic_write_text(out / "sweep.csv", csv_text(doc["trials"]))
    atomic_write_text(out / "summary.csv", csv_text(points))
    plot(summary, out / "sweep.png")
    table = rows_table_html(points, list(points[0]))
    write_html(
        out / "report.html",
        "arfi sweep",
        f"<p>{len(rows)} trials; recovered fraction of the ideal focus (corrected over ideal focal ARFI) per method, "
        f"number of images and ARFI noise, mean and standard deviation over seeds.</p>{table}"
        + figure_html(out, [("recovered fraction against noise and images", "sweep.png")]),
    )
    write_json(out / "sweep.json", doc)
    return summary
