#!/usr/bin/env python3
"""Curved sources and bone plates: arfi against a NumPy direct Rayleigh sum, side by side.

``--case bowl`` (the acceptance case): an 85 mm bowl (aperture 80 mm, 550 kHz) in lossless water.
arfi projects the bowl onto its source plane once per scenario (the Rayleigh integral on a radial
line, the bowl being symmetric about its axis, interpolated onto the pixels) and marches it. The
NumPy reference is the obvious algorithm: the same Rayleigh integral,
``p = -(i·k/2π)·p_face·Σ exp(i·k·R)/R·dA``, summed directly over 0.5 mm surface patches at every
pixel of the same source plane (vectorised in blocks of pixels). Printed: both times, their
ratio, and their agreement (|p| correlation and peak ratio on the plane), then ``arfi field`` end
to end (simulation built, focal plane and axis marched) against the NumPy sum taken directly to
the focal plane and the axis (what a user without HAS would do).

``--case elements``: the same bowl as 256 flat disc elements (5 mm, facing the centre of
curvature; the sunflower layout of ``kind = "bowl"`` with ``elements``): arfi sums every
element's quadrature points at every pixel in single precision (no symmetry to use); NumPy sums
the same discs in 0.5 mm patches. Printed as for ``bowl``.

``--case plate``: ``arfi field`` end to end for a 500 kHz F-number-1 bowl (R 64 mm) through a
6.5 mm cortical plate on a 0.375 mm grid (target: 5 s on 2 cores, 1 GiB), with its peak memory
(run each case in its own process: the peak is the process's).

Usage::

    python benches/bench_curved_source.py --case bowl [--patch-mm 0.5] [--json FILE]
    python benches/bench_curved_source.py --case elements [--patch-mm 0.5] [--json FILE]
    python benches/bench_curved_source.py --case plate [--json FILE]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import resource
import time
from typing import Any

import numpy as np

import arfi

BOWL = """
frequency_hz = 550000.0
[transducer]
kind = "bowl"
radius_of_curvature_mm = 85.0
aperture_diameter_mm = 80.0
[focus]
position_mm = [0.0, 0.0, 85.0]
[medium]
background = "water"
[[material]]
name = "water"
sound_speed_m_s = 1500.0
density_kg_m3 = 1000.0
attenuation_db_cm_mhz = 0.0
"""

PLATE = """
frequency_hz = 500000.0
[transducer]
kind = "bowl"
radius_of_curvature_mm = 64.0
aperture_diameter_mm = 64.0
[focus]
position_mm = [0.0, 0.0, 64.0]
[grid]
spacing_mm = 0.375
[medium]
background = "water"
[[material]]
name = "water"
sound_speed_m_s = 1500.0
density_kg_m3 = 1000.0
attenuation_db_cm_mhz = 0.0
[[material]]
name = "cortical"
sound_speed_m_s = 2800.0
density_kg_m3 = 1850.0
attenuation_db_cm_mhz = 4.0
[[region]]
material = "cortical"
shape = "slab"
z_min_mm = 30.0
z_max_mm = 36.5
"""


def cap_patches(radius: float, aperture: float, patch: float) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint patches of a spherical cap (apex at the origin, centre at (0, 0, R)), about
    ``patch`` wide: rings of equal polar-angle step, each cut into equal azimuthal pieces.
    Returns positions (n, 3) and areas (n), metres."""
    theta_max = np.arcsin(0.5 * aperture / radius)
    rings = int(np.ceil(radius * theta_max / patch))
    pos, area = [], []
    for k in range(rings):
        t0, t1 = k * theta_max / rings, (k + 1) * theta_max / rings
        t = 0.5 * (t0 + t1)
        n_phi = max(1, int(np.ceil(2 * np.pi * radius * np.sin(t) / patch)))
        phi = 2 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
        pos.append(
            np.stack(
                [
                    radius * np.sin(t) * np.cos(phi),
                    radius * np.sin(t) * np.sin(phi),
                    np.full(n_phi, radius * (1 - np.cos(t))),
                ],
                axis=1,
            )
        )
        area.append(np.full(n_phi, 2 * np.pi * radius**2 * (np.cos(t0) - np.cos(t1)) / n_phi))
    return np.concatenate(pos), np.concatenate(area)


def disc_patches(centres: np.ndarray, radius: float, diameter: float, patch: float) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint patches (about ``patch`` wide, the disc's area shared equally) of flat discs of
    ``diameter`` centred at ``centres`` (n, 3) and facing the centre of curvature (0, 0, radius)."""
    m = int(np.ceil(diameter / patch))
    s = -0.5 * diameter + (np.arange(m) + 0.5) * diameter / m
    uu, vv = np.meshgrid(s, s)
    inside = uu**2 + vv**2 <= 0.25 * diameter**2
    uu, vv = uu[inside], vv[inside]
    pos = []
    for c in centres:
        n = np.array([0.0, 0.0, radius]) - c
        n /= np.linalg.norm(n)
        ey = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        u = np.cross(ey, n)
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        pos.append(c + uu[:, None] * u + vv[:, None] * v)
    area = np.pi * diameter**2 / 4 / len(uu)
    return np.concatenate(pos), np.full(len(uu) * len(centres), area)


def rayleigh(
    targets: np.ndarray, pos: np.ndarray, area: np.ndarray, k: float, p_face: float, block: int = 256
) -> np.ndarray:
    """Direct Rayleigh sum at ``targets`` (n, 3), in blocks of targets."""
    out = np.empty(len(targets), dtype=np.complex128)
    for s in range(0, len(targets), block):
        d = targets[s : s + block, None, :] - pos[None, :, :]
        r = np.sqrt(np.einsum("tpk,tpk->tp", d, d))
        out[s : s + block] = (np.exp(1j * k * r) / r) @ area
    return -1j * k / (2 * np.pi) * p_face * out


def timed(f: Any) -> tuple[float, Any]:
    t = time.perf_counter()
    v = f()
    return time.perf_counter() - t, v


ELEMENTS = BOWL.replace(
    "aperture_diameter_mm = 80.0", "aperture_diameter_mm = 80.0\nelements = 256\nelement_size_mm = 5.0"
)


def bowl(patch_mm: float, elements: bool) -> dict[str, Any]:
    sim_s, sim = timed(lambda: arfi.Simulation(arfi.Scenario.from_toml(ELEMENTS if elements else BOWL)))
    field_s, field = timed(sim.field)
    plane = sim.source_field()
    g = sim.grid
    k = 2 * np.pi * sim.scenario.to_dict()["frequency_hz"] / 1500.0
    x = (np.arange(g.nx) - g.nx // 2) * g.dx_mm * 1e-3
    y = (np.arange(g.ny) - g.ny // 2) * g.dy_mm * 1e-3
    xx, yy = np.meshgrid(x, y)
    p_face = float(field.surface_pressure_pa)
    if elements:
        pos, area = disc_patches(sim.element_positions_mm * 1e-3, 85e-3, 5e-3, patch_mm * 1e-3)
    else:
        pos, area = cap_patches(85e-3, 80e-3, patch_mm * 1e-3)
    source_targets = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, g.z0_mm * 1e-3)], axis=1)
    numpy_source_s, numpy_plane = timed(lambda: rayleigh(source_targets, pos, area, k, p_face).reshape(xx.shape))
    a, b = np.abs(plane).ravel(), np.abs(numpy_plane).ravel()
    focal_targets = np.concatenate(
        [
            np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, field.z_mm * 1e-3)], axis=1),
            np.stack([np.zeros_like(field.axis_z_mm), np.zeros_like(field.axis_z_mm), field.axis_z_mm * 1e-3], axis=1),
        ]
    )
    numpy_focal_s, numpy_focal = timed(lambda: rayleigh(focal_targets, pos, area, k, p_face))
    nf = np.abs(numpy_focal[: xx.size])
    return {
        "case": "85 mm bowl, aperture 80 mm, 550 kHz, lossless water"
        + (", 256 disc elements of 5 mm" if elements else ""),
        "grid": f"{g.nx} x {g.ny} x {g.nz}, dx {g.dx_mm:.3f} mm",
        "patches": len(pos),
        "patch_mm": patch_mm,
        "arfi_simulation_s": sim_s,
        "arfi_field_s": field_s,
        "numpy_source_plane_s": numpy_source_s,
        "source_plane_correlation": float(np.corrcoef(a, b)[0, 1]),
        "source_plane_peak_ratio": float(a.max() / b.max()),
        "numpy_focal_plane_and_axis_s": numpy_focal_s,
        "focal_plane_correlation": float(np.corrcoef(np.abs(field.pressure).ravel(), nf)[0, 1]),
        "focal_peak_ratio": float(np.abs(field.pressure).max() / nf.max()),
    }


def plate() -> dict[str, Any]:
    t = time.perf_counter()
    sim = arfi.Simulation(arfi.Scenario.from_toml(PLATE))
    f = sim.field()
    seconds = time.perf_counter() - t
    g = sim.grid
    return {
        "case": "500 kHz bowl R 64 mm, aperture 64 mm, through a 6.5 mm cortical plate at 30 mm",
        "grid": f"{g.nx} x {g.ny} x {g.nz}, dx {g.dx_mm:.3f} mm",
        "propagation": sim.propagation_summary(),
        "arfi_field_end_to_end_s": seconds,
        "peak_memory_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "focal_peak_mpa": float(np.abs(f.pressure).max() / 1e6),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", choices=["bowl", "elements", "plate"], required=True)
    ap.add_argument("--patch-mm", type=float, default=0.5, dest="patch_mm")
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args()
    r = plate() if args.case == "plate" else bowl(args.patch_mm, args.case == "elements")
    r.update(date=_dt.date.today().isoformat(), machine=f"{platform.machine()}, {os.cpu_count()} cores")
    for key, value in r.items():
        print(f"{key:32s} {value:.4g}" if isinstance(value, float) else f"{key:32s} {value}")
    if args.case != "plate":
        print(
            f"{'projection: NumPy / arfi (upper bound: arfi simulation includes one march)':32s} "
            f"{r['numpy_source_plane_s'] / r['arfi_simulation_s']:.1f}x"
        )
        print(
            f"{'field: NumPy to focal plane + axis / arfi simulation + field':32s} "
            f"{r['numpy_focal_plane_and_axis_s'] / (r['arfi_simulation_s'] + r['arfi_field_s']):.1f}x"
        )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(r, fh, indent=2)


if __name__ == "__main__":
    main()
