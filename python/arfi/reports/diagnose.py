"""The report of ``arfi diagnose`` (``--report``): per step the measured image, the model, the
residual and the candidates' evidence, and the gap shrinking against the noise floor."""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from arfi._core import Diagnosis
from arfi.io.files import atomic_write_text
from arfi.reports.figures import axis_labels, focal_box_mm, image_extent_mm, pyplot, save_figure
from arfi.reports.html import figure_html

# Simulation is needed for an annotation only.
if TYPE_CHECKING:
    from arfi.simulation import Simulation


def evidence_bars(ax: Any, candidates: Sequence[Any], title: str) -> None:
    """The candidates' evidence as horizontal bars (green: would be added), each named with its
    value, on a symmetric log axis (linear within ±10)."""
    ev = np.array([np.nan if c.evidence is None else c.evidence for c in candidates], dtype=np.float64)
    names = [f"{c.name} ({'n/a' if np.isnan(v) else f'{v:.3g}'})" for c, v in zip(candidates, ev)]
    shown = np.nan_to_num(ev)
    ax.barh(names, shown, color=["C2" if v > 0 else "0.6" for v in shown])
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xscale("symlog", linthresh=10.0)
    ax.invert_yaxis()
    ax.set(xlabel="evidence: BIC gain / σ² (added when > 0)", title=title)


def write_report(diagnosis: Diagnosis, sim: Simulation, images: list[NDArray[np.float64]], out: str | Path) -> Path:
    """Writes one PNG per step of ``diagnosis`` (measured image, model, residual, the candidates'
    evidence) and the gap plot (cost and residual RMS against the noise floor) to ``out``, with a
    self-contained ``report.html``; returns the HTML path."""
    plt = pyplot()

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures: list[tuple[str, str]] = []
    stages = [
        (
            "model as given",
            diagnosis.models_initial,
            diagnosis.effects[0].candidates if diagnosis.effects else diagnosis.rejected,
        )
    ]
    for k, e in enumerate(diagnosis.effects):
        nxt = diagnosis.effects[k + 1].candidates if k + 1 < len(diagnosis.effects) else diagnosis.rejected
        stages.append((f"after adding {e.name}", e.models, nxt))
    ext = image_extent_mm(sim, images[0])
    lim = max(float(np.max(np.abs(images[0]))), 1e-12)
    u0, u1, v0, v1 = focal_box_mm(sim, images[:1])
    for k, (title, models, candidates) in enumerate(stages):
        residual = images[0] - models[0]
        fig = plt.figure(figsize=(15, 8.5), layout="constrained")
        top, bottom = fig.subfigures(2, 1, height_ratios=[1.15, 1.0])
        ax = top.subplots(1, 3)
        for a, img, name, vmax in (
            (ax[0], images[0], "measured", lim),
            (ax[1], models[0], "model", lim),
            (ax[2], residual, "residual", max(float(np.max(np.abs(residual))), 1e-12)),
        ):
            im = a.imshow(img.T, origin="lower", extent=ext, cmap="RdBu_r", vmin=-vmax, vmax=vmax)
            a.set(title=name, xlim=(u0, u1), ylim=(v0, v1), **axis_labels(sim))
            top.colorbar(im, ax=a, label="ARFI phase (rad)", shrink=0.9)
        rms = float(np.sqrt(np.mean(residual**2)))
        ax[2].set_title(f"residual: RMS {rms:.4f} rad\n(noise {diagnosis.noise_floor:.4f} rad)")
        top.suptitle(f"step {k}: {title}", fontsize="x-large")
        evidence_bars(
            bottom.subplots(), candidates, "next candidates" if k < len(stages) - 1 else "rejected candidates"
        )
        figures.append((f"step {k}: {title}", save_figure(fig, out / f"diagnose_step{k}.png")))
    fig, ax = plt.subplots(figsize=(6, 3.8))
    gap = [diagnosis.residual_rms_initial] + [e.residual_rms_after for e in diagnosis.effects]
    ax.plot(range(len(gap)), gap, "o-", label="residual RMS")
    ax.axhline(diagnosis.noise_floor, color="k", ls="--", label="noise floor")
    ax.set_xticks(range(len(gap)), ["model"] + [f"+{e.name}" for e in diagnosis.effects], rotation=20)
    ax.set(ylabel="rad", title="the gap shrinking")
    ax.legend()
    figures.append(("gap", save_figure(fig, out / "diagnose_gap.png")))
    rows = "".join(
        f"<tr><td>{k}</td><td>{html.escape(e.name)}</td><td>{html.escape(params_text(e.params))}</td>"
        f"<td>{e.cost_before:.4g}</td><td>{e.cost_after:.4g}</td><td>{e.evidence:.1f}</td>"
        f"<td>{e.residual_rms_after:.4f}</td><td>{html.escape(', '.join(e.equivalent) or '-')}</td></tr>"
        for k, e in enumerate(diagnosis.effects, 1)
    )
    imgs = figure_html(out, figures)
    verdict = (
        "no effect missing: the residual is consistent with the noise"
        if not diagnosis.effects
        else "effects added: " + ", ".join(diagnosis.names)
    )
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>arfi diagnose</title>
<style>body{{font-family:sans-serif;max-width:1300px;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #999;padding:3px 6px}}img{{max-width:100%}}</style></head>
<body><h1>Model discrepancy: {html.escape(verdict)}</h1>
<p>{len(images)} image(s), {diagnosis.n_pixels} pixels; noise floor {diagnosis.noise_floor:.4f} rad (image background).
Residual RMS {diagnosis.residual_rms_initial:.4f} → {diagnosis.residual_rms_final:.4f} rad; cost
{diagnosis.cost_initial:.4g} →
{diagnosis.cost_final:.4g}. An effect is added when its evidence, (J<sub>before</sub> − J<sub>after</sub>)/σ² − k·ln n,
is
positive; effects listed as equivalent explain the data as well (within 2).</p>
{_alternative(diagnosis)}
<table><tr><th>step</th><th>effect</th><th>parameters</th><th>cost before</th><th>cost after</th><th>evidence</th>
<th>residual RMS (rad)</th><th>equivalent</th></tr>{rows}</table>{imgs}</body></html>
"""
    path = out / "report.html"
    atomic_write_text(path, page)
    return path


def _alternative(d: Diagnosis) -> str:
    a = d.alternative
    if not a:
        return ""
    margin = d.total_evidence - a.total_evidence
    return (
        f"<p>Also fitted in full: {html.escape(', '.join(a.effects))} (total evidence {a.total_evidence:.1f}, "
        f"{margin:.1f} below the reported {d.total_evidence:.1f}"
        + ("; the data do not decide between them" if margin < 10 else "")
        + ").</p>"
    )


def params_text(params: dict[str, Any]) -> str:
    """An effect's fitted parameters as one line, ``name value, ...`` (4 significant digits)."""

    def fmt(v: Any) -> str:
        if isinstance(v, list):
            return "[" + ", ".join(fmt(x) for x in v) + "]"
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    return ", ".join(f"{k} {fmt(v)}" for k, v in params.items())
