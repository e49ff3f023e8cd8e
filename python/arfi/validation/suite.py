"""The validation suite: the propagation on the grid each scenario chooses by default, against
exact solutions written independently of it (no shared grid, FFT or medium sampling).

The cases use the ITRUSST benchmark's source SC1 (500 kHz bowl, radius of curvature 64 mm,
aperture 64 mm; Aubry et al., JASA 152(2), 2022):

- ``water``: the bowl in water, against the Rayleigh integral (O'Neil's on the axis);
- ``bm3``: a 6.5 mm cortical plate 30 mm from the apex, and ``bm4``: the flat layered skull
  (skin, cortical, trabecular, cortical, then brain), against the angular spectrum carried
  through the layers by transfer matrices;
- ``bm3_solid``: BM3's plate as a solid (shear 1500 m/s), which the march carries with mode
  conversion at its faces, against the exact elastic plate;
- ``shell`` and ``bm5``: caps of cortical bone read from CTs (0.25 mm voxels), a shell about the
  focus (normal incidence) and an ITRUSST BM5-like cap of outer radius 75 mm (oblique incidence),
  against the spherical-harmonic expansion of the bowl through a spherical shell;
- ``tilt0``, ``tilt10``, ``tilt20``, ``tilt30``: BM3's plate read from a CT (0.25 mm voxels),
  untilted and turned by 10, 20 and 30 degrees about y, against the bowl's plane waves carried
  through the fluid plate at their own incidence; compared in 3-D (the focus moves aside); the
  untilted plate held to the suite's tolerances, the tilted ones to their own, looser ones (the
  march's measured accuracy on bone met obliquely);
- ``tilt0_shear1500`` to ``tilt30_shear1500``: the plates as solids (the CT's bone shear
  1500 m/s, which the march converts at the faces on its planes and at the tilted walls),
  against the bowl's plane waves through the exact elastic plate; tilted, held to their own
  tolerances too;
- ``cap_uniform``, ``cap_texture1``, ``cap_texture3``: a three-layer skull cap about the focus read
  from a CT, its diploë uniform or textured over 1 and 3 mm, against stored full-wave results
  (BabelViscoFDTD; :mod:`arfi.validation.fullwave_caps`): no exact solution holds random bone;
- ``head220``: the head phantom with the 256-element hemisphere at 220 kHz, against a stored
  full-wave result (:mod:`arfi.validation.fullwave_head`).

Each case is compared on the beam axis and in the focal plane: focal peak pressure, its
position, the axial profile from 10 mm before to 10 mm after the focus, and the focal plane's
correlation within 10 mm of the axis.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from arfi import _core
from arfi.io.files import atomic_write_text
from arfi.validation.fullwave_caps import FullWaveResult
from arfi.validation.textured_caps import CAPS

#: One case's result: against an exact solution, or a stored full-wave run (its ``engine``
#: names which); each pair of values is (simulated, reference).
CaseResult = _core.ValidationResult | FullWaveResult

#: The suite's tolerances: relative focal pressure, focal position (mm), axial profile
#: (relative to the exact peak) and the smallest focal-plane correlation. Half the spread of the
#: eleven codes of the ITRUSST benchmark (10 % and 1 mm). A tilted plate has its own (a result's
#: ``tolerances``).
TOLERANCES: dict[str, float] = dict(
    zip(
        ("focal_pressure", "focal_position_mm", "axial_profile", "focal_plane_correlation"),
        _core.validation_tolerances(),
    )
)

#: The cases, in the order they run.
CASES = (
    ("water", "bm3", "bm4", "bm3_solid", "shell", "bm5", "tilt0", "tilt10", "tilt20", "tilt30")
    + ("tilt0_shear1500", "tilt10_shear1500", "tilt20_shear1500", "tilt30_shear1500")
    + tuple(c.name for c in CAPS)
    + ("head220",)
)


def check_cases(cases: Sequence[str] | None, name: str = "cases") -> list[str]:
    """The cases asked for (all when None); ValueError naming ``name`` and an unknown case."""
    wanted = list(CASES if cases is None else cases)
    unknown = [c for c in wanted if c not in CASES]
    if unknown:
        raise ValueError(f"{name}: unknown {', '.join(unknown)}; the suite has {', '.join(CASES)}")
    return wanted


def run(cases: Sequence[str] | None = None, progress: Callable[[str], None] | None = None) -> list[CaseResult]:
    """Runs the named cases (all by default), each on its scenario's default grid, and returns
    their :class:`arfi._core.ValidationResult` (for the textured caps and the head a
    :class:`arfi.validation.fullwave_caps.FullWaveResult`). Raises ValueError naming an unknown case,
    or a missing stored reference before any case runs."""
    from arfi.validation.fullwave_caps import CALIBRATION, REFERENCE_PPW, compare, reference, references

    wanted = check_cases(cases)
    caps = [c.name for c in CAPS if c.name in wanted]
    stored = references() if caps else {}
    if caps:  # before any case runs: a missing reference is one line, not a lost run
        missing = [c for c in caps + [CALIBRATION] if REFERENCE_PPW not in stored.get(c, {})]
        if missing:
            raise ValueError(
                f"validate: no stored full-wave run of {', '.join(missing)} at {REFERENCE_PPW:g} points per wavelength "
                "(benches/fullwave/caps_fdtd.py makes them)"
            )
    from arfi.validation import fullwave_head

    # Read before any case runs: a missing reference is one line, not a lost run.
    head = fullwave_head.reference() if "head220" in wanted else None
    results: list[CaseResult] = []
    with tempfile.TemporaryDirectory(prefix="arfi-validate-") as tmp:
        for case in _core.validation_cases(tmp):
            if case.name in wanted:
                if progress is not None:
                    progress(case.name)
                results.append(case.run())
    for cap in CAPS:
        if cap.name in wanted:
            if progress is not None:
                progress(cap.name)
            results.append(compare(cap.name, reference(cap.name, stored)))
    if head is not None:
        if progress is not None:
            progress("head220")
        results.append(fullwave_head.compare(head))
    return results


def case_json(r: CaseResult) -> dict[str, Any]:
    """One result as ``arfi validate --json`` writes it."""
    return {
        "case": r.name,
        "description": r.description,
        "focal_pressure_rel": list(r.focal_pressure),
        "focal_pressure_error": r.focal_pressure_error,
        "focal_z_mm": list(r.focal_z_mm),
        "focal_position_error_mm": r.focal_position_error_mm,
        "axial_error": r.axial_error,
        "focal_plane_correlation": r.correlation,
        "step_mm": r.step_mm,
        "spacing_mm": r.spacing_mm,
        "seconds": r.seconds,
        "tolerances": _tolerances(r),
        "reference": r.engine,
        "passed": r.passed,
    }


def table(results: Sequence[CaseResult]) -> str:
    """The results as a Markdown table, with the suite's tolerances in its header (a case's own
    in brackets in its row, explained below the table)."""
    t = TOLERANCES
    lines = [
        f"| case | focal pressure, simulated / exact (p/p0) | error (tol ±{100 * t['focal_pressure']:.0f} %) | focal "
        f"depth, simulated / exact (mm) | error (tol ±{t['focal_position_mm']:.1f} mm) | axial profile (tol "
        f"{100 * t['axial_profile']:.0f} %) | focal-plane correlation (tol ≥ {t['focal_plane_correlation']}) | step "
        "(mm) | result |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in results:
        ps, pe = r.focal_pressure
        zs, ze = r.focal_z_mm
        o = _tolerances(r)
        own = o != t
        # The case's own tolerances, in brackets after each metric, where they are not the suite's.
        p_tol, z_tol, a_tol, c_tol = (
            (f" ({v})" if own else "")
            for v in (
                f"±{100 * o['focal_pressure']:.0f} %",
                f"±{o['focal_position_mm']:g} mm",
                f"{100 * o['axial_profile']:.0f} %",
                f"≥ {o['focal_plane_correlation']}",
            )
        )
        lines.append(
            f"| {r.name} | {ps:.3f} / {pe:.3f} | {100 * r.focal_pressure_error:+.1f} %{p_tol} | {zs:.2f} / {ze:.2f} | "
            f"{r.focal_position_error_mm:+.2f}{z_tol} | {100 * r.axial_error:.1f} %{a_tol} | "
            f"{r.correlation:.4f}{c_tol} | {r.step_mm:.3f} | {'pass' if r.passed else 'FAIL'} |"
        )
    if any(_tolerances(r) != t and r.engine == "exact" for r in results):
        lines += [
            "",
            "A tolerance in brackets is the case's own: a plate tilted against the march's planes is held to the "
            "march's measured accuracy there, not to the suite's (its focal position error is the 3-D distance between "
            "the peaks, negative when the simulated one lies short); as a solid (tiltN_shear*, against the exact "
            "elastic plate) its focal pressure is held to the ITRUSST spread, 10 %.",
        ]
    engines = sorted({r.engine for r in results} - {"exact"})
    if engines:
        lines += [
            "",
            "The cap_* and head rows have no exact solution: their reference (the second value) is a stored full-wave "
            f"result ({', '.join(engines)}, scaled by its error on the shell, for the head by its error measured from "
            "two voxel sizes), the uniform cap held to the spread of the ITRUSST benchmark's full-wave codes, the "
            "textured caps where the march is (it leaves out the loss to the wave a fine texture scatters), the head "
            "to that spread in focal pressure and its own in position and axial profile; their focal position error "
            "is the 3-D distance between the peaks.",
        ]
    return "\n".join(lines)


def _tolerances(r: CaseResult) -> dict[str, float]:
    """A result's tolerances, keyed as :data:`TOLERANCES`."""
    return dict(zip(TOLERANCES, r.tolerances))


def figure(r: CaseResult, path: Path) -> str:
    """The case's axial profile and focal line, simulated over the reference (exact, or a stored
    full-wave result), as a PNG."""
    from arfi.reports.figures import pyplot, save_figure

    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.4))
    axis, line = r.axis, r.focal_line
    reference = r.engine
    a.plot(axis[:, 0], axis[:, 2], "k-", lw=1.5, label=reference)
    a.plot(axis[:, 0], axis[:, 1], "C1.", ms=4, label="arfi (default grid)")
    ze = r.focal_z_mm[1]
    a.axvspan(ze - 10, ze + 10, color="0.9", zorder=0)
    a.set(xlabel="z (mm)", ylabel="|p| / p0", title=f"{r.name}: along z through the reference focus")
    a.legend(fontsize=8)
    b.plot(line[:, 0], line[:, 2], "k-", lw=1.5, label=reference)
    b.plot(line[:, 0], line[:, 1], "C1.", ms=4, label="arfi")
    b.set(xlabel="x (mm)", ylabel="|p| / p0", title=f"{r.name}: focal plane, along x through the focus")
    return save_figure(fig, path)


def write_report(out: str | Path, results: Sequence[CaseResult]) -> Path:
    """``out/report.html`` (the table, then each case's figure), ``out/validation.md`` (the table)
    and ``out/validation.json``; returns the HTML's path."""
    from arfi.reports.html import figure_html, write_html

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md = table(results)
    atomic_write_text(out / "validation.md", md + "\n")
    atomic_write_text(
        out / "validation.json",
        json.dumps({"tolerances": TOLERANCES, "cases": [case_json(r) for r in results]}, indent=2) + "\n",
    )
    figures = [(f"{r.name}: {r.description}", figure(r, out / f"{r.name}.png")) for r in results]
    body = _markdown_table_html(md) + figure_html(out, figures)
    return write_html(out / "report.html", "arfi validate", body)


def _markdown_table_html(md: str) -> str:
    """The Markdown table of :func:`table` as HTML."""
    import html

    lines = md.splitlines()
    rows = [line.strip("|").split("|") for line in lines if line.startswith("|") and not line.startswith("| ---")]
    head = "<tr>" + "".join(f"<th>{html.escape(c.strip())}</th>" for c in rows[0]) + "</tr>"
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c.strip())}</td>" for c in r) + "</tr>" for r in rows[1:])
    notes = "".join(f"<p>{html.escape(line)}</p>" for line in lines if line and not line.startswith("|"))
    return f"<table>{head}{body}</table>{notes}"
