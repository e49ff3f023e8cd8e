"""``arfi reproduce``: the paper's study (Vyas et al. 2014, Table 1 and Figures 2–10) re-run in
simulation on the embedded phantom scenario, with seeded skull-like aberrations.

Each repeat: calibrate W and the amplitude on a noisy no-aberration image; apply the aberration
(16 group phases, or 1024 element phases); estimate 16 group phases from one noisy aberrated
image; subtract them and image the corrected beam. Focal ARFI values (image maxima) are taken on
the noise-free simulated images, so that noise maxima do not inflate them; the noisy images are
the ones the method sees.
"""

from __future__ import annotations

import datetime as _dt
import html
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from arfi.analysis.ladder import EXTRA_IMAGES, Ladder, Rung, climb, defocused_images, focus_of
from arfi.analysis.loop import loop2
from arfi.checks import as_count, as_number
from arfi.estimation import gain, phase_error, recovered_fraction
from arfi.io.files import atomic_write_text, csv_text, write_json
from arfi.reports.figures import PHASE_GROUND, image_extent_mm, pyplot, save_figure
from arfi.reports.html import figure_html, rows_table_html
from arfi.scenario import Scenario
from arfi.simulation import Simulation

#: Largest first seed of a study: each acquisition's seed is derived from it (e.g. ``60_000 + 100·seed + k``)
#: and must stay a 64-bit seed.
MAX_STUDY_SEED = 10**17


@dataclass(frozen=True)
class PaperResult:
    """What the paper reports for one case: the means over its repeats."""

    recovered_fraction: float
    gain: float
    phase_error_rad: float


#: The paper's results per case (Vyas et al. 2014, Table 1 and text).
PAPER = {
    16: PaperResult(recovered_fraction=0.83, gain=0.44, phase_error_rad=0.42),
    1024: PaperResult(recovered_fraction=0.39, gain=0.52, phase_error_rad=2.10),
}


@dataclass
class Row:
    """One line of the paper's Table 1, with the recovered fraction, gain and phase error."""

    experiment: str
    repeat: int
    seed: int
    evaluations: int
    seconds: float
    final_cost: float
    broadening_width_mm: float
    focal_ideal_rad: float
    focal_aberrated_rad: float
    focal_corrected_rad: float
    recovered_fraction: float
    gain: float
    phase_error_rad: float
    ambiguous: bool
    images: int = 1
    """Images the final estimate was fitted to (aberrated + diversity + loop-2 acquisitions)."""
    loop2_kept: int = 0
    """Loop 2: the acquisition whose correction was kept (0 = none measured better than no correction)."""


@dataclass
class RepeatRun:
    """What one repeat produced, for the figures: the estimate, the correction applied, the
    calibration, the aberration (per element and condensed to the groups) and its images."""

    estimate: Any
    correction: np.ndarray
    calibration: Any
    elements: np.ndarray
    groups_truth: np.ndarray
    measured: np.ndarray
    aberrated: np.ndarray
    corrected: np.ndarray
    corrected_measured: np.ndarray
    calibration_image: np.ndarray


@dataclass
class StudyResult:
    """What :func:`run_study` gives (and writes as ``results.json``: :meth:`to_dict`)."""

    case: int
    repeats: int
    method: str
    noise_rad: float
    seed: int
    diversity_images: int
    loop2_iterations: int
    date: str
    table: list[Row]
    """The paper's Table 1, one row per repeat."""
    paper: PaperResult
    figures: dict[str, str]
    """Figure name -> file name in the output folder."""
    ladder: list[Rung]
    """Every path to a correction on the same seeds (empty without the ladder)."""
    seconds: float

    @property
    def mean_recovered_fraction(self) -> float:
        return float(np.mean([r.recovered_fraction for r in self.table]))

    @property
    def mean_gain(self) -> float:
        return float(np.mean([r.gain for r in self.table]))

    @property
    def mean_phase_error_rad(self) -> float:
        return float(np.mean([r.phase_error_rad for r in self.table]))

    @property
    def ambiguous(self) -> int:
        """Repeats whose estimate the method flags ambiguous."""
        return sum(bool(r.ambiguous) for r in self.table)

    def to_dict(self) -> dict[str, Any]:
        """``results.json``: the fields, the three means after the table, each rung with its mean."""
        d = asdict(self)
        head = list(d)[: list(d).index("table") + 1]
        return {
            **{k: d[k] for k in head},
            "mean_recovered_fraction": self.mean_recovered_fraction,
            "mean_gain": self.mean_gain,
            "mean_phase_error_rad": self.mean_phase_error_rad,
            "paper": d["paper"],
            "figures": d["figures"],
            "ladder": [r.to_dict() for r in self.ladder],
            "seconds": d["seconds"],
        }


def _progress(enabled: bool) -> Callable[[str], None]:
    def say(msg: str) -> None:
        if enabled:
            print(f"reproduce: {msg}", file=sys.stderr, flush=True)

    return say


def study_aberration(sim: Simulation, case: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seeded skull-like aberration of one repeat: per element, condensed to the groups, and
    the one applied (the group phases on their elements for case 16, the element phases for 1024)."""
    elements = sim.skull_phases(seed)
    groups_truth = sim.condense(elements)
    return elements, groups_truth, groups_truth[sim.groups] if case == 16 else elements


def study_images(
    sim: Simulation, applied: np.ndarray, noise: float, seed: int, diversity: int
) -> tuple[list[np.ndarray], list[Any]]:
    """The noisy aberrated image of one repeat and ``diversity`` more, each with seeded random
    known group phases added; returns (images, known phases or None per image)."""
    images: list[np.ndarray] = [sim.arfi_image(applied, noise_rad=noise, seed=20_000 + seed)]
    known: list[Any] = [None]
    rng = np.random.default_rng(40_000 + seed)
    for k in range(diversity):
        d = rng.uniform(-np.pi, np.pi, sim.n_groups)
        images.append(sim.arfi_image(applied + d[sim.groups], noise_rad=noise, seed=50_000 + 100 * seed + k))
        known.append(d)
    return images, known


def run_study(
    case: int,
    repeats: int,
    out: Path | str,
    seed: int = 0,
    method: str = "nelder-mead",
    noise_rad: float | None = None,
    diversity: int = 0,
    loop2_iterations: int = 0,
    progress: bool | None = None,
    ladder: bool = True,
) -> StudyResult:
    """Runs the study and writes figures, ``table.csv``, ``results.json`` and ``report.html`` to
    ``out``. Returns the results (``table`` rows as in the paper plus the recovered fraction, gain
    and phase error).

    ``diversity`` > 0 adds that many images per repeat, each with seeded random known group
    phases added (phase diversity: one in-focus image hardly tells an aberration from its twin),
    to the paper's single aberrated image; ``loop2_iterations`` > 0 runs the paper's loop 2 with
    that many more acquisitions per repeat. ``seed`` is the first repeat's seed (at most
    ``MAX_STUDY_SEED``); ``noise_rad`` defaults to the scenario's ARFI noise.

    ``ladder`` (default) also runs, for the same seeds, every path to a correction side by side
    (:mod:`arfi.analysis.ladder`: the paper's single image, loop 2, diversity images, a CT-like prediction
    alone, and the prediction with MR-ARFI), reported as ``ladder`` and in ``fig11_ladder.png``.

    Bad arguments raise ``ValueError`` naming them; ``out`` is created and written only once the
    study has run, so a failed run leaves nothing behind."""
    if case not in (16, 1024):
        raise ValueError(f"case: must be 16 or 1024, got {case}")
    repeats = as_count(repeats, "repeats", 1, 100)
    seed = as_count(seed, "seed", 0, MAX_STUDY_SEED)
    diversity = as_count(diversity, "diversity", 0, 32)
    loop2_iterations = as_count(loop2_iterations, "loop2_iterations", 0, 20)
    noise_rad = None if noise_rad is None else as_number(noise_rad, "noise_rad", 0.0)
    out = Path(out)
    say = _progress(sys.stderr.isatty() if progress is None else progress)
    t_start = time.perf_counter()
    sim = Simulation()
    noise = sim.noise_rad if noise_rad is None else noise_rad
    ideal = sim.arfi_image()
    rows: list[Row] = []
    runs: list[RepeatRun] = []
    rungs = Ladder(case)
    paper_faithful = method == "nelder-mead" and not diversity and not loop2_iterations
    for r in range(repeats):
        s = seed + r
        say(f"repeat {r + 1}/{repeats}: calibrating")
        cal = sim.calibrate(sim.arfi_image(noise_rad=noise, seed=10_000 + s))
        model = sim.calibrated(cal)
        elements, groups_truth, applied = study_aberration(sim, case, s)
        say(f"repeat {r + 1}/{repeats}: estimating ({method})")
        images, known = study_images(sim, applied, noise, s, diversity)
        measured = images[0]
        if loop2_iterations:
            say(f"repeat {r + 1}/{repeats}: loop 2 ({loop2_iterations} acquisitions)")
            loop = loop2(
                model,
                measured,
                _acquirer(sim, applied, noise, s),
                iterations=loop2_iterations,
                extra_images=images[1:],
                extra_known=known[1:],
                method=method,
                seed=s,
            )
            # The table reports the last fit (all images); the correction is the one measured best.
            est = loop.steps[-1].estimate
            assert est is not None
            correction, kept, n_images = loop.correction_rad, loop.kept, len(loop.images)
        else:
            est = model.estimate(images, known, method=method, seed=s)
            correction, kept, n_images = est.phases_rad, 0, len(images)
        corrected_phases = applied - correction[sim.groups]
        aberrated = sim.arfi_image(applied)
        corrected = sim.arfi_image(corrected_phases)
        f_i, f_a, f_c = (sim.focal_arfi(img)[0] for img in (ideal, aberrated, corrected))
        rows.append(
            Row(
                experiment=f"{case}-aberration",
                repeat=r + 1,
                seed=s,
                evaluations=est.evaluations,
                seconds=est.seconds,
                final_cost=est.cost,
                broadening_width_mm=cal.broadening_width_mm,
                focal_ideal_rad=f_i,
                focal_aberrated_rad=f_a,
                focal_corrected_rad=f_c,
                recovered_fraction=recovered_fraction(f_c, f_i),
                gain=gain(f_c, f_a),
                phase_error_rad=phase_error(correction, groups_truth),
                ambiguous=est.ambiguous,
                images=n_images,
                loop2_kept=kept,
            )
        )
        runs.append(
            RepeatRun(
                estimate=est,
                correction=correction,
                calibration=cal,
                elements=elements,
                groups_truth=groups_truth,
                measured=measured,
                aberrated=aberrated,
                corrected=corrected,
                corrected_measured=sim.arfi_image(corrected_phases, noise_rad=noise, seed=30_000 + s),
                calibration_image=sim.arfi_image(noise_rad=noise, seed=10_000 + s),
            )
        )
        if ladder:
            say(f"repeat {r + 1}/{repeats}: the ladder (loop 2, diversity, prediction, prediction + MR-ARFI)")
            paper = (rows[-1].recovered_fraction, rows[-1].ambiguous, rows[-1].seconds) if paper_faithful else None
            # The same aberrated image as the study's; its diversity images when they are the ladder's.
            if case == 1024:
                images, known = defocused_images(sim, applied, measured, noise, s)
            elif diversity != EXTRA_IMAGES:
                images, known = study_images(sim, applied, noise, s, EXTRA_IMAGES)
            climb(
                sim,
                model,
                case,
                applied,
                images,
                known,
                _acquirer(sim, applied, noise, s),
                s,
                focus_of(sim, applied, float(ideal.max())),
                rungs,
                paper,
            )
    say("drawing figures")
    out.mkdir(parents=True, exist_ok=True)
    figures = _figures(sim, case, rows, runs, ideal, out, method)
    ladder_rungs = rungs.rungs() if ladder else []
    if ladder_rungs:
        figures["fig11"] = _ladder_figure(ladder_rungs, case, out)
    result = StudyResult(
        case=case,
        repeats=repeats,
        method=method,
        noise_rad=noise,
        seed=seed,
        diversity_images=diversity,
        loop2_iterations=loop2_iterations,
        date=_dt.date.today().isoformat(),
        table=rows,
        paper=PAPER[case],
        figures=figures,
        ladder=ladder_rungs,
        seconds=time.perf_counter() - t_start,
    )
    _write_table(out / "table.csv", rows)
    write_json(out / "results.json", result.to_dict())
    atomic_write_text(out / "report.html", _html(result, out))
    return result


def _acquirer(sim: Simulation, applied: np.ndarray, noise: float, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """A seeded scanner for loop 2: each call images the aberration with per-group phases added
    (noise seeds ``60_000 + 100·seed + k`` for the k-th acquisition)."""
    count = [0]

    def acquire(added: np.ndarray) -> np.ndarray:
        count[0] += 1
        return sim.arfi_image(
            applied + np.asarray(added)[sim.groups], noise_rad=noise, seed=60_000 + 100 * seed + count[0]
        )

    return acquire


def _ladder_figure(rungs: list[Rung], case: int, out: Path) -> str:
    """Bar chart of each rung's recovered fraction (mean, and each repeat as a dot)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4))
    x = np.arange(len(rungs))
    ax.bar(x, [r.mean_recovered_fraction for r in rungs], color="0.6")
    for i, r in enumerate(rungs):
        ax.plot([i] * len(r.recovered_fractions), r.recovered_fractions, "k.")
    ax.axhline(PAPER[case].recovered_fraction, color="r", ls="--", label="paper")
    ax.set_xticks(
        x,
        [r.name.replace(" + ", "\n+ ").replace(" alone", "\nalone").replace(" (paper)", "\n(paper)") for r in rungs],
        fontsize=8,
    )
    ax.set(
        ylabel="recovered fraction of the ideal focus", ylim=(0, 1.1), title=f"{case}-aberration: paths to a correction"
    )
    ax.legend()
    fig.tight_layout()
    return save_figure(fig, out / "fig11_ladder.png")


def _ladder_html(ladder: list[Rung], paper: float) -> str:
    """The ladder as a table (empty without one)."""
    if not ladder:
        return ""
    rows = [
        {
            "path": r.name,
            "what": r.what,
            "recovered_fraction": r.mean_recovered_fraction,
            "per_repeat": " ".join(f"{v:.2f}" for v in r.recovered_fractions),
            "ambiguous": r.ambiguous,
            "seconds": r.seconds,
        }
        for r in ladder
    ]
    return (
        "<h2>Paths to a correction</h2><p>The same seeded aberrations, calibrations and noisy images for every path "
        f"(paper's recovered fraction: {paper}). The prediction is a CT-like stand-in: the true aberration plus a "
        "seeded smooth error field and per-element jitter; its expected error is given to the posterior as the "
        "prior's width.</p>"
        + rows_table_html(rows, ["path", "what", "recovered_fraction", "per_repeat", "ambiguous", "seconds"])
    )


def _write_table(path: Path, rows: list[Row]) -> None:
    atomic_write_text(path, csv_text([asdict(r) for r in rows]))


def _figures(
    sim: Simulation, case: int, rows: list[Row], runs: list[RepeatRun], ideal: np.ndarray, out: Path, method: str
) -> dict[str, str]:
    plt = pyplot()
    figs: dict[str, str] = {}
    run0 = runs[0]
    ext = image_extent_mm(sim, ideal)
    zoom = 20.0
    a = sim.mr_affine_mm
    xs = a[0, 3] + a[0, 0] * np.arange(ideal.shape[0])
    jy = int(np.argmax(ideal.max(axis=0)))

    # Figure 2: calibration — force without broadening vs measured calibration image, profiles.
    force = sim.with_calibration(0.0, 1.0).arfi_image()
    cal_img = run0.calibration_image
    model = sim.calibrated(run0.calibration).arfi_image()
    fig, ax = plt.subplots(2, 2, figsize=(10, 8))
    for k, (img, title) in enumerate(
        [
            (force / force.max(), "(a) simulated radiation force (normalised)"),
            (cal_img / cal_img.max(), "(b) calibration MR-ARFI image (normalised)"),
        ]
    ):
        im = ax[0, k].imshow(img.T, origin="lower", extent=ext, cmap="viridis")
        ax[0, k].set(xlim=(-zoom, zoom), ylim=(-zoom, zoom), xlabel="x (mm)", ylabel="y (mm)", title=title)
        fig.colorbar(im, ax=ax[0, k], label="normalised")
    ax[1, 0].plot(xs, cal_img[:, jy] / cal_img.max(), "k-", label="MR-ARFI (calibration)")
    ax[1, 0].plot(xs, force[:, jy] / force.max(), "k:", label="simulated force")
    ax[1, 0].set(xlim=(-zoom, zoom), xlabel="x (mm)", ylabel="normalised", title="(c) without Gaussian filtering")
    ax[1, 1].plot(xs, cal_img[:, jy] / cal_img.max(), "k-", label="MR-ARFI (calibration)")
    ax[1, 1].plot(
        xs, model[:, jy] / model.max(), "k:", label=f"simulated, W = {run0.calibration.broadening_width_mm:.2f} mm"
    )
    ax[1, 1].set(xlim=(-zoom, zoom), xlabel="x (mm)", ylabel="normalised", title="(d) with Gaussian filtering")
    for k in range(2):
        ax[1, k].legend()
    figs["fig2"] = save_figure(fig, out / "fig2_calibration.png")

    # Figure 3: optimisation example — noise-free image, estimated vs applied group phases.
    truth = sim.condense(sim.skull_phases(999))
    ex = sim.estimate(sim.arfi_image(truth), method=method)
    off = np.angle(np.sum(np.exp(1j * (truth - ex.phases_rad))))
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    im = ax[0].imshow(sim.arfi_image(truth).T, origin="lower", extent=ext, cmap="viridis")
    ax[0].set(
        xlim=(-zoom, zoom), ylim=(-zoom, zoom), xlabel="x (mm)", ylabel="y (mm)", title="(a) aberrated, noise-free"
    )
    fig.colorbar(im, ax=ax[0], label="ARFI phase (rad)")
    g = np.arange(len(truth))
    ax[1].plot(g, np.angle(np.exp(1j * (truth - off))), "ko-", label="applied")
    ax[1].plot(g, ex.phases_rad, "rx--", label=f"estimated ({method})")
    ax[1].set(
        xlabel="group", ylabel="phase (rad)", title=f"(b) phase error {phase_error(ex.phases_rad, truth):.3f} rad"
    )
    ax[1].legend()
    figs["fig3"] = save_figure(fig, out / "fig3_optimisation_example.png")

    # Figure 4c/d: the applied aberration on the element map.
    pos = sim.element_positions_mm
    fig, ax = plt.subplots(1, 2, figsize=(10, 4.5))
    for k, (ph, title) in enumerate(
        [(run0.groups_truth[sim.groups], "(c) 16-aberration"), (run0.elements, "(d) 1024-aberration")]
    ):
        sc = ax[k].scatter(
            pos[:, 0], pos[:, 1], c=np.angle(np.exp(1j * ph)), cmap="twilight", vmin=-np.pi, vmax=np.pi, s=9, marker="s"
        )
        ax[k].set(aspect="equal", xlabel="x (mm)", ylabel="y (mm)", title=title)
        ax[k].set_facecolor(PHASE_GROUND)
        fig.colorbar(sc, ax=ax[k], label="phase (rad)")
    figs["fig4"] = save_figure(fig, out / "fig4_aberrations.png")

    # Figure 5: simulated radiation force in the plane containing the beam (x-z), normalised to ideal.
    xz = Scenario.default().to_dict()
    xz["mr"].update({"plane": "xz", "fov_mm": [40.0, 60.0], "matrix": [80, 120], "slice_thickness_mm": 1.0})
    xz["arfi"]["broadening_width_mm"] = 0.0
    sxz = Simulation(Scenario.from_dict(xz))
    pats = [sxz.arfi_image(), sxz.arfi_image(run0.groups_truth[sim.groups]), sxz.arfi_image(run0.elements)]
    fig, ax = plt.subplots(1, 3, figsize=(14, 4), layout="constrained")
    az = sxz.mr_affine_mm
    zext = [
        az[2, 3] - az[2, 2] / 2,
        az[2, 3] + (pats[0].shape[1] - 0.5) * az[2, 2],
        az[0, 3] - az[0, 0] / 2,
        az[0, 3] + (pats[0].shape[0] - 0.5) * az[0, 0],
    ]
    for k, (p, title) in enumerate(zip(pats, ["(a) ideal", "(b) 16-aberration", "(c) 1024-aberration"])):
        cs = ax[k].contourf(p / pats[0].max(), levels=np.linspace(0, 1, 11), extent=zext, cmap="viridis")
        ax[k].set(xlabel="z, along the beam (mm)", ylabel="x (mm)", title=title)
    fig.colorbar(cs, ax=list(ax), label="radiation force / ideal maximum")
    figs["fig5"] = save_figure(fig, out / "fig5_beam_patterns.png")

    # Figure 6: ideal, aberrated and corrected MR-ARFI images (what the scanner would show).
    vmax = float(ideal.max())
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for k, (img, title) in enumerate(
        [
            (sim.arfi_image(noise_rad=sim.noise_rad, seed=1), "ideal"),
            (run0.measured, f"aberrated ({case})"),
            (run0.corrected_measured, "corrected"),
        ]
    ):
        im = ax[k].imshow(img.T, origin="lower", extent=ext, cmap="viridis", vmin=-0.05, vmax=vmax)
        ax[k].set(xlim=(-zoom, zoom), ylim=(-zoom, zoom), xlabel="x (mm)", ylabel="y (mm)", title=title)
        fig.colorbar(im, ax=ax[k], label="ARFI phase (rad)")
    figs["fig6"] = save_figure(fig, out / "fig6_images.png")

    # Figure 7: transverse focal profiles.
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(xs, ideal[:, jy], "k:", label="ideal")
    ax.plot(xs, run0.aberrated[:, jy], "k--", label="aberrated")
    ax.plot(xs, run0.corrected[:, jy], "k-", label="corrected")
    ax.set(xlim=(-zoom, zoom), xlabel="x (mm)", ylabel="ARFI phase (rad)", title="transverse focal profile")
    ax.legend()
    figs["fig7"] = save_figure(fig, out / "fig7_profiles.png")

    # Figure 8: convergence.
    fig, ax = plt.subplots(figsize=(6, 4))
    for k, run in enumerate(runs):
        h = run.estimate.cost_history
        ax.semilogy(np.arange(1, len(h) + 1), h, label=f"repeat {k + 1}")
    ax.set(xlabel="cost evaluation", ylabel="best cost J (rad²)", title=f"convergence ({method})")
    ax.legend()
    figs["fig8"] = save_figure(fig, out / "fig8_convergence.png")

    # Figure 9: applied vs estimated phases.
    fig, ax = plt.subplots(figsize=(7, 4))
    t0 = run0.groups_truth
    c0 = run0.correction
    off = np.angle(np.sum(np.exp(1j * (t0 - c0))))
    if case == 1024:
        e = np.arange(len(run0.elements)) / len(run0.elements) * len(t0)
        ax.plot(e, np.angle(np.exp(1j * (run0.elements - off))), color="0.7", lw=0.6, label="applied (per element)")
    ax.plot(np.arange(len(t0)) + 0.5, np.angle(np.exp(1j * (t0 - off))), "ko-", label="applied (group average)")
    ax.plot(np.arange(len(t0)) + 0.5, c0, "rx--", label="estimated (the correction applied)")
    ax.set(xlabel="group", ylabel="phase (rad)", title=f"phase error {rows[0].phase_error_rad:.2f} rad")
    ax.legend()
    figs["fig9"] = save_figure(fig, out / "fig9_phases.png")

    # Figure 10: focal ARFI, mean ± s.d. over repeats.
    vals = np.array([[r.focal_ideal_rad, r.focal_aberrated_rad, r.focal_corrected_rad] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.bar(
        ["ideal", "aberrated", "corrected"],
        vals.mean(axis=0),
        yerr=vals.std(axis=0),
        color=["0.8", "0.5", "0.2"],
        capsize=5,
    )
    ax.set(ylabel="focal ARFI phase (rad)", title=f"{case}-aberration, {len(rows)} repeats")
    figs["fig10"] = save_figure(fig, out / "fig10_focal.png")
    return figs


def _html(result: StudyResult, out: Path) -> str:
    rows = [asdict(r) for r in result.table]
    cols = [
        "experiment",
        "repeat",
        "evaluations",
        "seconds",
        "final_cost",
        "broadening_width_mm",
        "focal_ideal_rad",
        "focal_aberrated_rad",
        "focal_corrected_rad",
        "recovered_fraction",
        "gain",
        "phase_error_rad",
        "ambiguous",
        "images",
        "loop2_kept",
    ]

    table = rows_table_html(rows, cols)
    imgs = figure_html(out, [(name, name) for name in result.figures.values()])
    p = result.paper
    return f"""<!doctype html><html><head><meta charset="utf-8">
<title>arfi reproduce: {result.case}-aberration</title>
<style>body{{font-family:sans-serif;max-width:1200px;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #999;padding:3px 6px}}img{{max-width:100%}}</style></head>
<body><h1>Hybrid simulation–MR-ARFI correction: {result.case}-aberration case</h1>
<p>Vyas, Kaye &amp; Butts Pauly, Med Phys 41(3):032901 (2014), re-run in simulation with arfi on the embedded phantom
scenario; method {html.escape(result.method)}, ARFI noise {result.noise_rad} rad, {result.repeats} repeats,
{result.diversity_images} added diversity images and {result.loop2_iterations} loop-2 acquisitions per repeat
(loop2_kept: which acquisition's correction was kept, 0 = none measured better than no correction), {result.date}.
Rows marked ambiguous are estimates the
method itself flags: clearly different solutions fit that image within the noise (one in-focus image hardly tells
phi(u) from -phi(-u); images with known added phases tell them apart).</p>
<p>Mean recovered fraction <b>{result.mean_recovered_fraction:.2f}</b> (paper {p.recovered_fraction}), mean gain
<b>{result.mean_gain:+.0%}</b> (paper {p.gain:+.0%}), mean phase error <b>{result.mean_phase_error_rad:.2f}
rad</b>
(paper {p.phase_error_rad} rad). Focal values are taken on noise-free simulated images.</p>
{_ladder_html(result.ladder, p.recovered_fraction)}<h2>Table 1</h2>{table}<h2>Figures</h2>{imgs}</body></html>
"""
