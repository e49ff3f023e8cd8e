"""Figures (PNG): MR-ARFI images with axes in mm on the scenario's MR plane and colour bars in
rad, the transducer's element map coloured by phase (as the paper's Figure 4c/4d), the beam over
the CT or the sound speed on orthogonal planes, and focal sections."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi._core import connected_region, image_noise_rad
from arfi.io.files import atomic_path


def pyplot() -> Any:
    """matplotlib.pyplot on the file-only Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path) -> str:
    """Writes ``fig`` as PNG (atomically), closes it and returns the file name."""
    plt = pyplot()
    if fig.get_layout_engine() is None:
        fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    plt.close(fig)
    return path.name


def image_extent_mm(sim: Any, image: NDArray[np.float64]) -> list[float]:
    """``imshow`` extent (mm) of an MR image shown as ``image.T`` with ``origin="lower"``: its u
    axis across, v axis up (the frame axes of the scenario's MR plane)."""
    a = sim.mr_affine_mm
    u, v = ("xyz".index(c) for c in sim.mr_plane)
    nu, nv = image.shape
    du, dv = a[u, u], a[v, v]
    return [a[u, 3] - du / 2, a[u, 3] + (nu - 0.5) * du, a[v, 3] - dv / 2, a[v, 3] + (nv - 0.5) * dv]


def axis_labels(sim: Any) -> dict[str, str]:
    """``xlabel``/``ylabel`` for images of the scenario's MR plane."""
    return {"xlabel": f"{sim.mr_plane[0]} (mm)", "ylabel": f"{sim.mr_plane[1]} (mm)"}


#: |p| below this fraction of the colour scale's top is not drawn over the medium.
BEAM_FLOOR = 0.02
#: |p| above this fraction of the colour scale's top is drawn opaque; below it the beam fades
#: (opacity ∝ √(|p| / this)), so that the converging beam stays visible in the brain without hiding
#: the anatomy where it is weak.
BEAM_OPAQUE = 0.3
#: The beam's colour map (0 to the focal scale).
BEAM_CMAP = "inferno"
#: The ground under cyclic phase maps, whose ends (or middle, shifted) are near white.
PHASE_GROUND = "0.55"


def beam_rgba(p: NDArray[np.float64], vmax: float) -> NDArray[np.float64]:
    """``p`` (≥ 0) as RGBA on ``BEAM_CMAP`` scaled 0..``vmax``: opaque above ``BEAM_OPAQUE`` of
    ``vmax``, fading below it, clear below ``BEAM_FLOOR``."""
    import matplotlib

    f = np.clip(np.nan_to_num(np.asarray(p, dtype=np.float64)) / max(vmax, np.finfo(float).tiny), 0.0, 1.0)
    rgba = np.array(matplotlib.colormaps[BEAM_CMAP](f), dtype=np.float64)
    rgba[..., 3] = np.where(f < BEAM_FLOOR, 0.0, np.sqrt(np.minimum(f / BEAM_OPAQUE, 1.0)))
    return rgba


def show_beam(ax: Any, p: NDArray[np.float64], vmax: float, extent: Sequence[float]) -> Any:
    """``p`` drawn over what ``ax`` shows (:func:`beam_rgba`); returns a mappable for its colour
    bar (``BEAM_CMAP``, 0..``vmax``)."""
    import matplotlib

    ax.imshow(beam_rgba(p, vmax), origin="lower", extent=extent, interpolation="nearest")
    return matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(0.0, vmax), BEAM_CMAP)


def mark_target(ax: Any, u: float, w: float) -> None:
    """The target as an open circle (12 pt across, larger than a focus of a few mm in the views
    drawn here) so that the focus inside it stays visible."""
    ax.plot(u, w, marker="o", ms=12, mfc="none", mec="c", mew=1.2, ls="none", label="target")


def show_image(
    fig: Any,
    ax: Any,
    sim: Any,
    image: NDArray[np.float64],
    title: str,
    signed: bool = False,
    limits: tuple[float, float] | None = None,
) -> None:
    """An MR-ARFI phase image (rad) on its plane, axes in mm, with a colour bar in rad;
    ``signed`` centres the colour map on zero (residuals); ``limits`` (rad) shares one colour
    scale between images."""
    lim = max(float(np.max(np.abs(image))), 1e-12)
    vmin, vmax = (-lim, lim) if signed else (None, None)
    if limits is not None:
        vmin, vmax = limits
    im = ax.imshow(
        image.T,
        origin="lower",
        extent=image_extent_mm(sim, image),
        cmap="RdBu_r" if signed else "viridis",
        vmin=vmin,
        vmax=vmax,
    )
    ax.set(title=title, **axis_labels(sim))
    fig.colorbar(im, ax=ax, label="ARFI phase (rad)")


def focal_box_mm(
    sim: Any, images: Sequence[NDArray[np.float64]], margin_mm: float = 5.0, least_mm: float = 20.0
) -> list[float]:
    """``[u0, u1, v0, v1]`` (mm) around the focal spot of ``images`` (on the scenario's MR plane):
    the pixels above 10 % of the largest |value| and 5 noise deviations (each image's noise from
    its background, :func:`arfi._core.image_noise_rad`), with ``margin_mm`` around them, widened
    to ``least_mm`` where the image allows."""
    extent = image_extent_mm(sim, images[0])
    nu, nv = images[0].shape
    du, dv = (extent[1] - extent[0]) / nu, (extent[3] - extent[2]) / nv
    hot = np.zeros((nu, nv), dtype=bool)
    peak = max(float(np.nanmax(np.abs(im))) for im in images)
    for im in images:
        hot |= np.abs(im) > max(0.1 * peak, 5.0 * image_noise_rad(np.ascontiguousarray(im, dtype=np.float64)))
    iu, iv = np.nonzero(hot) if hot.any() else (np.array([nu // 2]), np.array([nv // 2]))
    box = []
    for lo, d, idx, (a, b) in ((extent[0], du, iu, extent[:2]), (extent[2], dv, iv, extent[2:])):
        c0, c1 = lo + idx.min() * d - margin_mm, lo + (idx.max() + 1) * d + margin_mm
        grow = max(0.0, least_mm - (c1 - c0)) / 2
        box += [max(a, c0 - grow), min(b, c1 + grow)]
    return box


def element_map(fig: Any, ax: Any, sim: Any, phases: ArrayLike, title: str) -> None:
    """The transducer's elements (x, y in mm) coloured by phase (rad, wrapped to [-π, π], a cyclic
    colour map on a grey ground); ``phases`` per element or per group."""
    per_element = np.asarray(sim.element_phases(np.asarray(phases, dtype=np.float64)))
    # The cyclic map is near white at 0 rad: a grey ground keeps those elements visible.
    ax.set_facecolor(PHASE_GROUND)
    element_values(
        fig,
        ax,
        sim,
        np.angle(np.exp(1j * per_element)),
        title,
        "phase (rad)",
        cmap="twilight_shifted",
        vmin=-np.pi,
        vmax=np.pi,
    )


def element_values(fig: Any, ax: Any, sim: Any, values: NDArray[np.float64], title: str, label: str, **kw: Any) -> None:
    """The transducer's elements (x, y in mm) coloured by one value each (colour bar ``label``;
    ``kw``: colour map and limits)."""
    pos = sim.element_positions_mm
    sc = ax.scatter(pos[:, 0], pos[:, 1], c=values, s=9 if len(values) > 300 else 30, marker="s", **kw)
    ax.set(title=title, xlabel="x (mm)", ylabel="y (mm)", aspect="equal")
    fig.colorbar(sc, ax=ax, label=label)


def show_section(ax: Any, section: Any, drive: int, title: str, vmax_pa: float, columns: slice) -> tuple[Any, Any]:
    """One drive's |p| on an x–z section (MPa, fading below 30 % of ``vmax_pa``: :func:`beam_rgba`) over the
    sound speed (grey, m/s), x across (the ``columns`` shown) and z up from the source plane, in
    mm. Returns the two images (for colour bars)."""
    x, z = section.x_mm[columns], section.z_mm
    dx, dz = x[1] - x[0], z[1] - z[0]
    extent = [x[0] - dx / 2, x[-1] + dx / 2, z[0] - dz / 2, z[-1] + dz / 2]
    c = section.sound_speed_m_s[:, columns]
    bg = ax.imshow(c, origin="lower", extent=extent, cmap="Greys", vmin=1300.0, vmax=max(3000.0, float(c.max())))
    p = np.abs(section.pressure[drive][:, columns]) / 1e6
    im = show_beam(ax, p, vmax_pa / 1e6, extent)
    ax.set(title=title, xlabel="x (mm)", ylabel="z (mm)", xlim=extent[:2], ylim=extent[2:])
    return bg, im


def section_figure(section: Any, titles: Sequence[str], target_mm: Sequence[float]) -> Any:
    """A row of x–z sections, one per drive, on one pressure scale: that of the focal region
    (the largest |p| within 15 mm of the target's (x, z); the field in the water, scalp or skull,
    often stronger, is drawn saturated), cropped across to where the medium differs from the
    source plane's or the beam exceeds 10 % of its peak (10 mm margin); the target circled."""
    plt = pyplot()
    p = np.abs(section.pressure).max(axis=(0, 1))
    c = section.sound_speed_m_s
    busy = np.flatnonzero((p > 0.1 * p.max()) | np.any(np.abs(c - c[:1]) > 1.0, axis=0))
    margin = int(round(10.0 / (section.x_mm[1] - section.x_mm[0])))
    columns = slice(max(busy[0] - margin, 0), min(busy[-1] + margin + 1, c.shape[1]))
    fig, ax = plt.subplots(1, len(titles), figsize=(5.0 * len(titles) + 1.8, 4.6), squeeze=False, layout="constrained")
    near = np.hypot(section.x_mm[None, :] - target_mm[0], section.z_mm[:, None] - target_mm[2]) <= 15.0
    vmax = float(np.abs(section.pressure[:, near]).max()) if near.any() else float(np.abs(section.pressure).max())
    for k, t in enumerate(titles):
        bg, im = show_section(ax[0][k], section, k, t, vmax, columns)
        mark_target(ax[0][k], target_mm[0], target_mm[2])
    fig.colorbar(im, ax=ax[0].tolist(), label="|p| (MPa)", shrink=0.8, extend="max")
    fig.colorbar(bg, ax=ax[0].tolist(), label="sound speed (m/s)", shrink=0.8)
    return fig


def orthogonal_sections(sim: Any, field: Any) -> Any:
    """|p| (MPa) of ``field``'s beam on the three grid planes through the target (x–z, y–z, x–y,
    in mm), from the field's own march (``sim.field(..., volume=True)``): over the CT in HU
    (grey) with a ``[ct]``, else over the sound speed; the colour scale set by the focal peak
    (hotter places, a scalp or a skull, saturate), fading below 30 % of it (:func:`beam_rgba`), with
    its -6 dB lobe contoured (cyan) and the target circled. The top row shows the whole grid, the bottom row the
    same planes around the target (at least 10 mm each way, three -6 dB widths across and 1.5
    along the beam). The whole grid's |p| is a view of the field's own memory (no copy)."""
    plt = pyplot()
    volume = field.pressure_volume()
    p, a = volume.pressure_pa / 1e6, volume.affine_mm
    axes = [a[n, 3] + a[n, n] * np.arange(p.shape[2 - n]) for n in range(3)]  # x, y, z (mm)
    t = field.target_mm
    i, j, k = (int(np.argmin(np.abs(axes[n] - t[n]))) for n in range(3))
    metrics = field.focal_metrics
    peak = (metrics.focal_peak_pa or float(volume.pressure_pa.max())) / 1e6
    along, across = metrics.fwhm_6db_mm or (20.0, 5.0)
    reach = {"x": max(10.0, 3.0 * across), "y": max(10.0, 3.0 * across), "z": max(10.0, 1.5 * along)}
    sections = [
        ("x", "z", p[:, j, :], (axes[0], axes[1][j], axes[2])),
        ("y", "z", p[:, :, i], (axes[0][i], axes[1], axes[2])),
        ("x", "y", p[k], (axes[0], axes[1], axes[2][k])),
    ]
    fig, ax = plt.subplots(2, 3, figsize=(17, 10), layout="constrained")
    background = "hu" if sim.has_ct else "sound_speed_m_s"
    hu = background == "hu"
    for n, (u, w, plane, (xs, ys, zs)) in enumerate(sections):
        grid = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1)  # one axis of length 1
        medium = (
            sim.properties_at(grid.reshape(-1, 3))[background].reshape(grid.shape[:3]).squeeze().T
        )  # (w, u) as plane
        uu, ww = axes["xyz".index(u)], axes["xyz".index(w)]
        du, dw = uu[1] - uu[0], ww[1] - ww[0]
        extent = [uu[0] - du / 2, uu[-1] + du / 2, ww[0] - dw / 2, ww[-1] + dw / 2]
        start = tuple(int(np.argmin(np.abs(axis - t["xyz".index(c)]))) for axis, c in ((ww, w), (uu, u)))
        focal = np.where(
            connected_region(np.ascontiguousarray(plane, dtype=np.float64), list(start), peak / 2), plane, 0.0
        )
        at = next(c for c in "xyz" if c not in (u, w))
        for row in (0, 1):
            axis = ax[row][n]
            bg = axis.imshow(
                np.nan_to_num(medium, nan=-1000.0) if hu else medium,
                origin="lower",
                extent=extent,
                cmap="gray",
                vmin=-200.0 if hu else 1300.0,
                vmax=2000.0 if hu else max(3000.0, float(np.nanmax(medium))),
            )
            im = show_beam(axis, plane, peak, extent)
            axis.contour(uu, ww, focal, levels=[peak / 2], colors="c", linewidths=0.8)
            mark_target(axis, t["xyz".index(u)], t["xyz".index(w)])
            axis.set(xlabel=f"{u} (mm)", ylabel=f"{w} (mm)", aspect="equal", xlim=extent[:2], ylim=extent[2:])
        ax[0][n].set_title(f"{u}–{w} plane through the target ({at} = {t['xyz'.index(at)]:.1f} mm)")
        ax[1][n].set(
            title="around the target",
            xlim=(t["xyz".index(u)] - reach[u], t["xyz".index(u)] + reach[u]),
            ylim=(t["xyz".index(w)] - reach[w], t["xyz".index(w)] + reach[w]),
        )
    fig.colorbar(im, ax=ax.ravel().tolist(), label="pressure amplitude (MPa)", shrink=0.6, extend="max")
    fig.colorbar(bg, ax=ax.ravel().tolist(), label="CT (HU)" if hu else "sound speed (m/s)", shrink=0.6)
    return fig
