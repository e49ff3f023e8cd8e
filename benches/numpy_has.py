"""The Hybrid Angular Spectrum march of arfi, written again in plain NumPy (numpy.fft) for the
side-by-side benchmark (``bench_numpy_has.py``). It follows ``crates/has-core/src/physics/propagation`` step
for step, so the two must agree to rounding:

1. at a change of medium, ``p <- p · T`` with ``T = 2·Z2 / (Z1 + Z2)`` per pixel;
2. ``P(kx, ky) <- P · exp(i·kz·dz)``, ``kz = sqrt(k̄² - kx² - ky²)`` (evanescent:
   ``exp(-sqrt(kx² + ky² - k̄²)·dz)``);
3. ``p <- p · exp(i·(k - k̄)·dz - (alpha + sigma)·dz)``, sigma the absorbing layer at the edges;

with ``k̄`` of each slab the ``|p|``-weighted mean of ``k`` over the reference beam, rounded to
1e-4 of the largest wavenumber. Regions: cylinders and slabs (no voxel maps); no reflections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

NP_PER_DB = math.log(10.0) / 20.0


@dataclass
class Grid:
    nx: int
    ny: int
    nz: int
    dx: float
    dy: float
    dz: float
    z0: float

    @classmethod
    def from_simulation(cls, sim) -> Grid:
        g = sim._core.grid
        return cls(g["nx"], g["ny"], g["nz"], g["dx_mm"] * 1e-3, g["dy_mm"] * 1e-3, g["dz_mm"] * 1e-3, g["z0_mm"] * 1e-3)

    def x(self) -> np.ndarray:
        return (np.arange(self.nx) - self.nx // 2) * self.dx

    def y(self) -> np.ndarray:
        return (np.arange(self.ny) - self.ny // 2) * self.dy

    def z(self, n: int) -> float:
        return self.z0 + n * self.dz


class Medium:
    """Materials and regions of a resolved scenario (``arfi._core.scenario_json``)."""

    def __init__(self, scenario: dict, frequency: float):
        self.materials = {m["name"]: m for m in scenario["material"]}
        self.background = scenario["medium"]["background"]
        self.regions = scenario.get("region", [])
        self.frequency = frequency

    def _props(self, name: str) -> tuple[float, float, float]:
        m = self.materials[name]
        alpha = m["attenuation_db_cm_mhz"] * (self.frequency / 1e6) ** m["attenuation_power"] * 100.0 * NP_PER_DB
        return m["sound_speed_m_s"], m["density_kg_m3"], alpha

    def min_sound_speed(self) -> float:
        return min(m["sound_speed_m_s"] for m in self.materials.values())

    def key(self, z: float) -> tuple[bool, ...]:
        """Which regions' z-ranges contain ``z`` (equal keys: equal slices)."""
        return tuple(r["z_min_mm"] * 1e-3 <= z <= r["z_max_mm"] * 1e-3 for r in self.regions)

    def slice(self, g: Grid, z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sound speed, density and attenuation (Np/m) on the (ny, nx) grid at height z; the last
        region containing a point wins."""
        x, y = np.meshgrid(g.x(), g.y())
        c, rho, a = (np.full((g.ny, g.nx), v) for v in self._props(self.background))
        for r in self.regions:
            inside = np.full(x.shape, r["z_min_mm"] * 1e-3 <= z <= r["z_max_mm"] * 1e-3)
            if r["shape"] == "cylinder":
                cx, cy = (v * 1e-3 for v in r.get("center_mm", [0.0, 0.0]))
                radius = r["radius_mm"] * 1e-3
                inside &= (x - cx) ** 2 + (y - cy) ** 2 <= radius * radius
            elif r["shape"] != "slab":
                raise ValueError(f"region shape {r['shape']!r} not supported here")
            for arr, v in zip((c, rho, a), self._props(r["material"])):
                arr[inside] = v
        return c, rho, a


def sponge(g: Grid, width: float = 10e-3, strength: float = 6.9) -> np.ndarray:
    """The absorbing layer sigma (Np/m): quadratic in the depth into the layer."""
    def depth(n: int, d: float) -> np.ndarray:
        i = np.arange(n)
        return np.maximum((width - np.minimum(i, n - 1 - i) * d) / width, 0.0)

    e = np.maximum(depth(g.nx, g.dx)[None, :], depth(g.ny, g.dy)[:, None])
    return 3.0 * strength / width * e * e


def wavenumbers(n: int, d: float) -> np.ndarray:
    return 2.0 * np.pi * np.fft.fftfreq(n, d)


@dataclass
class Step:
    transmission: np.ndarray | None
    propagator: np.ndarray
    screen: np.ndarray


class Plan:
    """Per-step operators, fixed by marching the reference beam (as ``HasPlan::build``)."""

    def __init__(self, g: Grid, medium: Medium, reference: np.ndarray):
        omega = 2.0 * np.pi * medium.frequency
        sigma = sponge(g)
        kx, ky = wavenumbers(g.nx, g.dx)[None, :], wavenumbers(g.ny, g.dy)[:, None]
        k_perp2 = kx * kx + ky * ky
        quantum = omega / medium.min_sound_speed() * 1e-4
        field = reference.copy()
        prev = medium.slice(g, g.z0 - 0.5 * g.dz)
        props, prev_key, slab = None, None, -1
        propagators: dict[float, np.ndarray] = {}
        screens: dict[tuple[int, float], np.ndarray] = {}
        self.steps: list[Step] = []
        self.grid = g
        for n in range(g.nz - 1):
            z = g.z(n) + 0.5 * g.dz
            key = medium.key(z)
            if props is None or key != prev_key:
                new = medium.slice(g, z)
                if props is None or any(not np.array_equal(u, v) for u, v in zip(new, props)):
                    props, slab = new, slab + 1
            prev_key = key
            c, rho, alpha = props
            changed = any(not np.array_equal(u, v) for u, v in zip(props, prev))
            transmission = 2.0 * rho * c / (prev[1] * prev[0] + rho * c) if changed else None
            w = np.abs(field)
            k_mean = float(np.sum(w * omega / c) / np.sum(w)) if np.sum(w) > 0 else float(np.mean(omega / c))
            k_mean = math.floor(k_mean / quantum + 0.5) * quantum  # Rust's f64::round for k > 0
            if k_mean not in propagators:
                kz2 = k_mean * k_mean - k_perp2
                propagators[k_mean] = np.where(kz2 >= 0, np.exp(1j * np.sqrt(np.abs(kz2)) * g.dz),
                                               np.exp(-np.sqrt(np.abs(kz2)) * g.dz))
            skey = (slab, k_mean)
            if skey not in screens:
                screens[skey] = np.exp(-(alpha + sigma) * g.dz) * np.exp(1j * (omega / c - k_mean) * g.dz)
            step = Step(transmission, propagators[k_mean], screens[skey])
            field = apply(step, field)
            self.steps.append(step)
            prev = props

    def march(self, source: np.ndarray, plane: int) -> tuple[np.ndarray, np.ndarray]:
        """The field on ``plane`` and the on-axis samples of every plane (to the last)."""
        g = self.grid
        field, axis, kept = source.copy(), [source[g.ny // 2, g.nx // 2]], source if plane == 0 else None
        for n, step in enumerate(self.steps, start=1):
            field = apply(step, field)
            axis.append(field[g.ny // 2, g.nx // 2])
            if n == plane:
                kept = field.copy()
        return kept, np.array(axis)


def apply(step: Step, field: np.ndarray) -> np.ndarray:
    if step.transmission is not None:
        field = field * step.transmission
    return np.fft.ifft2(np.fft.fft2(field) * step.propagator) * step.screen
