"""Self-contained HTML reports: one page per verb (``--report``), its values as a table and its
figures (:mod:`arfi.reports.figures`) embedded."""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi.io.files import atomic_write_text
from arfi.reports.figures import (
    element_map,
    element_values,
    focal_box_mm,
    mark_target,
    orthogonal_sections,
    pyplot,
    save_figure,
    section_figure,
    show_image,
)

STYLE = (
    "body{font-family:sans-serif;max-width:1300px;margin:auto}table{border-collapse:collapse}td,th{border:1px solid "
    "#999;padding:3px 6px}img{max-width:100%}"
)


def figure_html(out: Path, figures: Sequence[tuple[str, str]]) -> str:
    """``<figure>`` elements with the PNGs (``(caption, file name in out)``) embedded."""
    return "".join(
        f"<figure><img src='data:image/png;base64,{base64.b64encode((out / name).read_bytes()).decode()}' "
        f"alt='{html.escape(cap)}'><figcaption>{html.escape(cap)}</figcaption></figure>"
        for cap, name in figures
    )


def write_html(path: Path, title: str, body: str) -> Path:
    """One self-contained HTML page."""
    atomic_write_text(
        path,
        f'<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{STYLE}</style></head>\n<body><h1>{html.escape(title)}</h1>\n{body}</body></html>\n",
    )
    return path


def _text(v: Any) -> str:
    """A value as a person reads it: numbers to 4 significant digits, sequences as comma lists in
    parentheses, mappings as "key: value" pairs, absent values as a dash."""
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.4g}"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, dict):
        return "; ".join(f"{k}: " + (f"({_text(x)})" if isinstance(x, dict) else _text(x)) for k, x in v.items()) or "—"
    if isinstance(v, (list, tuple)):
        return "(" + ", ".join(_text(x) for x in v) + ")"
    return str(v)


def _cell(v: Any) -> str:
    return html.escape(_text(v))


def table_html(rows: dict[str, Any]) -> str:
    """A two-column table of named values."""
    return (
        "<table>"
        + "".join(f"<tr><th>{html.escape(k)}</th><td>{_cell(v)}</td></tr>" for k, v in rows.items())
        + "</table>"
    )


def rows_table_html(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    """A table with one row per dict and the given columns."""
    head = "<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in columns) + "</tr>\n"
    return (
        "<table>"
        + head
        + "\n".join("<tr>" + "".join(f"<td>{_cell(r[c])}</td>" for c in columns) + "</tr>" for r in rows)
        + "</table>"
    )


def _report_dir(out: str | Path) -> Path:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _verb_page(
    out: Path, verb: str, values: dict[str, Any], figures: Sequence[tuple[str, str]], warning: str | None = None
) -> Path:
    """``out/report.html`` for a verb: the ``warning`` in red if any, its values as a table, then
    its figures."""
    head = f"<p style='color:red'><b>{html.escape(warning)}</b></p>" if warning else ""
    return write_html(out / "report.html", f"arfi {verb}", head + table_html(values) + figure_html(out, figures))


def fit_report(
    out: str | Path,
    sim: Any,
    verb: str,
    measured: NDArray[np.float64],
    model: NDArray[np.float64],
    values: dict[str, Any],
    phases: ArrayLike | None = None,
    warning: str | None = None,
) -> Path:
    """Report of a fit (``calibrate``, ``estimate``, ``simulate``): the measured image, the model
    (one colour scale) and their residual, cropped to the focal spot (:func:`focal_box_mm`), and,
    with ``phases`` (rad, the estimated aberration), the element maps of the aberration and of its
    correction (paper Fig. 4c/4d). ``values`` go in a table; ``warning`` (e.g. an ambiguous or
    mismatched estimate) is written in red over the images and at the top of the page."""
    plt = pyplot()
    out = _report_dir(out)
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.8), layout="constrained")
    lo = min(float(measured.min()), float(model.min()), 0.0)
    hi = max(float(measured.max()), float(model.max()), 1e-12)
    show_image(fig, ax[0], sim, measured, "measured", limits=(lo, hi))
    show_image(fig, ax[1], sim, model, "model", limits=(lo, hi))
    residual = measured - model
    show_image(fig, ax[2], sim, residual, f"residual (RMS {float(np.sqrt(np.mean(residual**2))):.4f} rad)", signed=True)
    u0, u1, v0, v1 = focal_box_mm(sim, [measured, model])
    for a in ax:
        a.set(xlim=(u0, u1), ylim=(v0, v1))
    if warning:
        fig.suptitle(warning, color="red")
    figures = [
        (
            "measured, model and residual MR-ARFI images around the focal spot",
            save_figure(fig, out / f"{verb}_images.png"),
        )
    ]
    if phases is not None:
        fig, ax = plt.subplots(1, 2, figsize=(11, 4.6))
        element_map(fig, ax[0], sim, phases, "estimated aberration")
        element_map(fig, ax[1], sim, -np.asarray(phases), "correction (subtracted)")
        if warning:
            fig.suptitle(warning, color="red")
        figures.append(("element maps coloured by phase", save_figure(fig, out / f"{verb}_elements.png")))
    return _verb_page(out, verb, values, figures, warning)


def image_report(
    out: str | Path,
    sim: Any,
    verb: str,
    image: NDArray[np.float64],
    values: dict[str, Any],
    phases: ArrayLike | None = None,
) -> Path:
    """Report of a simulated image, with the element map of the phases added to the steering."""
    plt = pyplot()
    out = _report_dir(out)
    fig, ax = plt.subplots(
        1, 2 if phases is not None else 1, figsize=(11 if phases is not None else 6, 4.4), squeeze=False
    )
    show_image(fig, ax[0][0], sim, image, "MR-ARFI image")
    if phases is not None:
        element_map(fig, ax[0][1], sim, phases, "phases added to the steering")
    return _verb_page(out, verb, values, [("simulated image", save_figure(fig, out / f"{verb}.png"))])


def field_report(
    out: str | Path, sim: Any, field: Any, values: dict[str, Any], phases: ArrayLike | None = None
) -> Path:
    """Report of a simulated field made with ``volume=True``: |p| (MPa) on the plane around the
    target (circled), axes in mm, its colour scale set by the focal peak near the target (hotter
    places saturate); |p| along
    the beam's axis (the line from the array's centre through the target) with the target's depth
    marked; with ``phases``, the element map of the phases added to the steering; the beam on the
    three planes through the target over the CT or the sound speed (:func:`orthogonal_sections`)."""
    plt = pyplot()
    out = _report_dir(out)
    focus = field.focus()
    fig, ax = plt.subplots(1, 3 if phases is not None else 2, figsize=(17 if phases is not None else 11, 4.4))
    x, y = field.x_mm, field.y_mm
    dx, dy = x[1] - x[0], y[1] - y[0]
    im = ax[0].imshow(
        np.abs(field.pressure) / 1e6,
        origin="lower",
        cmap="inferno",
        vmin=0.0,
        vmax=focus.plane_peak_pa / 1e6,
        extent=[x[0] - dx / 2, x[-1] + dx / 2, y[0] - dy / 2, y[-1] + dy / 2],
    )
    # Around the target: the whole plane is in the sections below, and a hotter ring of water or
    # skull far from it would draw the eye away from the focus.
    t = field.target_mm
    across = (focus.focal_metrics.fwhm_6db_mm or (20.0, 5.0))[1]
    reach = max(10.0, 3.0 * across)
    mark_target(ax[0], t[0], t[1])
    ax[0].set(
        title=f"|p| on the plane z = {field.z_mm:.1f} mm around the target (o)",
        xlabel="x (mm)",
        ylabel="y (mm)",
    )
    # Around the target where it lies on the plane's grid; the whole plane where it does not.
    for lim, axis, c in ((ax[0].set_xlim, x, t[0]), (ax[0].set_ylim, y, t[1])):
        lo, hi = max(axis[0], c - reach), min(axis[-1], c + reach)
        if lo < hi:
            lim(lo, hi)
    fig.colorbar(im, ax=ax[0], label="pressure amplitude (MPa)", extend="max")
    ax[1].plot(field.axis_z_mm, np.abs(field.axis_pressure) / 1e6)
    ax[1].axvline(field.target_mm[2], color="0.5", ls="--", lw=0.8)
    ax[1].set(
        title=f"|p| on the line from the array's centre to ({t[0]:.0f}, {t[1]:.0f}, {t[2]:.0f}) mm (--: target)",
        xlabel="z (mm)",
        ylabel="pressure amplitude (MPa)",
    )
    if phases is not None:
        element_map(fig, ax[2], sim, phases, "phases added to the steering")
    figures = [("pressure amplitude", save_figure(fig, out / "field.png"))]
    figures.append(
        (
            "the beam on the three planes through the target (cyan: -6 dB of the focal peak)",
            save_figure(orthogonal_sections(sim, field), out / "field_sections.png"),
        )
    )
    return _verb_page(out, "field", values, figures)


def predict_report(
    out: str | Path, prediction: Any, values: dict[str, Any], section: Any, labels: dict[str, str]
) -> Path:
    """Report of a CT-based prediction made with ``keep_simulation=True``: the beam through the
    skull on the x–z section through the target for each drive it compares (``section`` from
    ``arfi.analysis.prediction.compared_section``: uncorrected, straight-ray CT steering, corrected, in the
    order and with the names of ``labels``, ``arfi.analysis.prediction.drive_labels(scenario)``); the
    element maps of the predicted phase and of the transmission."""
    sim = prediction.kept_simulation()
    plt = pyplot()
    out = _report_dir(out)
    best = prediction.optimal_pa
    pressures = {
        "uncorrected": prediction.uncorrected_pa,
        "ray_steering": prediction.ray_steering_pa,
        "corrected": prediction.corrected_pa,
    }
    fig = section_figure(
        section,
        [f"{label}: {pressures[name] / best:.2f} of the best focus" for name, label in labels.items()],
        prediction.target_mm,
    )
    figures = [
        (
            f"the beam through the skull on the section y = {section.y_mm:.1f} mm",
            save_figure(fig, out / "predict_section.png"),
        )
    ]
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8))
    element_map(fig, ax[0], sim, prediction.phases_rad, "predicted aberration (subtract to correct)")
    element_values(
        fig,
        ax[1],
        sim,
        prediction.transmission,
        "transmission through the skull",
        "|h skull| / |h reference|",
        cmap="viridis",
        vmin=0.0,
    )
    figures.append(("element maps of the prediction", save_figure(fig, out / "predict_elements.png")))
    return _verb_page(out, "predict", values, figures)
