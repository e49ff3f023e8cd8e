"""The Hybrid Angular Spectrum march of arfi, written again in plain NumPy (numpy.fft) for the
side-by-side benchmark (``bench_numpy_has.py``). It follows ``crates/has-core/src/physics/propagation``
step for step, so the two agree to rounding on the scenarios it covers.

The march carries the flux-normalised field ``psi = p·sqrt(Z_s/Z)`` (``Z = rho·c`` of the
pixel's medium, ``Z_s`` of the medium the source radiates from, half a step before plane 0).
Each step from plane n to n + 1:

1. at a change of medium (slab n - 1 into slab n), the interface:

   - ``"angular"`` (default): pixels are grouped by material pair (a, b); each pair reflects
     ``M_ab · IFFT(R_ab(kt) · FFT(psi))`` with the plane-wave coefficient
     ``R_ab = (rho_b·kz_a - rho_a·kz_b) / (rho_b·kz_a + rho_a·kz_b)``,
     ``kz = sqrt((omega/c + i·alpha)² - kt²)`` (``Im kz >= 0``); then
     ``psi <- (psi + reflected) · sqrt(Z_a/Z_b)`` on the pair's pixels. More than 8 pairs on a
     plane (or 64 in the plan) fall back to the pointwise form below;
   - ``"normal-incidence"``: ``psi <- psi · (1 + R) · sqrt((1 - R)/(1 + R))`` per pixel,
     ``R = (Z_b - Z_a)/(Z_a + Z_b)``;

2. ``Psi(kx, ky) <- Psi · exp(i·kz·dz + ᾱ·dz)``, ``kz = sqrt((k̄ + i·ᾱ)² - kx² - ky²)``,
   ``Im kz >= 0`` (for ``ᾱ = 0``: ``exp(i·kz·dz)``, evanescent ``exp(-sqrt(kt² - k̄²)·dz)``);

3. ``psi <- psi · exp(i·phi·dz - (beta + sigma)·dz)``, sigma the absorbing layer at the edges:

   - ``"oblique"`` screen (default) in a slab that is not uniform: with ``sin² θ`` of the line
     from the pixel (at the step's mid-height) to the focus, ``kt² = min(k²·sin² θ,
     0.97·min(k, k̄)²)``, ``phi = kz(k) - kz(k̄)``, ``beta = alpha·k/kz(k) - ᾱ·(k̄/kz(k̄) - 1)``;
   - ``"vertical"`` screen, or any uniform slab: ``phi = k - k̄``, ``beta = alpha``;

with ``k̄`` and ``ᾱ`` of each slab the ``|psi|``-weighted means of ``k`` and ``alpha`` over the
reference beam (after the slab's interface), each rounded to 1e-4 of the largest wavenumber.
Recorded values are pressures: on plane n, ``p = psi·sqrt(Z/Z_s)`` with ``Z`` of the slab the
beam crossed to reach it, taken before that plane's interface.

Covered: regions (cylinders and slabs) in a background, both interface models, both screens,
the sponge width of ``[grid]``; the default scenario (water, then a phantom cylinder whose top
face is one spectral water/phantom pair) uses the angular interface, the oblique screen (the
cylinder leaves the grid's corners in water, so its slabs are not uniform) and the
flux-normalised march.

Not covered (arfi has them, this copy does not): voxel maps and CTs, hence faces that lie
between planes (the phase of a face's true position, ``interface::face_phase``) and the treads'
coefficient of walls crossing the planes as staircases (``risers.rs``, ``interface::is_wall``),
which arfi applies only to the pointwise faces of such media (faces of regions lie on planes);
the reverberation between strongly reflecting interfaces (``Plan`` refuses a medium that would
have a reverberation zone), the reflections towards the source, and axes that are not the z axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

NP_PER_DB = math.log(10.0) / 20.0
MAX_SPECTRAL_PAIRS = 8  # interface::MAX_SPECTRAL_PAIRS
MAX_PLAN_PAIRS = 64  # interface::MAX_PLAN_PAIRS
ROUND_TRIP_THRESHOLD = 0.01  # propagation::ROUND_TRIP_THRESHOLD
MAX_OBLIQUITY_SIN2 = 0.97  # operators::MAX_OBLIQUITY_SIN2


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
        return cls(g.nx, g.ny, g.nz, g.dx_mm * 1e-3, g.dy_mm * 1e-3, g.dz_mm * 1e-3, g.z0_mm * 1e-3)

    def x(self) -> np.ndarray:
        return (np.arange(self.nx) - self.nx // 2) * self.dx

    def y(self) -> np.ndarray:
        return (np.arange(self.ny) - self.ny // 2) * self.dy

    def z(self, n: int) -> float:
        return self.z0 + n * self.dz


@dataclass
class Slice:
    """Sound speed (m/s), density (kg/m³) and attenuation (Np/m) on the (ny, nx) grid."""

    c: np.ndarray
    rho: np.ndarray
    alpha: np.ndarray

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Slice) and all(
            np.array_equal(u, v) for u, v in ((self.c, other.c), (self.rho, other.rho), (self.alpha, other.alpha))
        )

    def impedance(self) -> np.ndarray:
        return self.rho * self.c

    def is_uniform(self) -> bool:
        return bool(np.all(self.c == self.c.flat[0]) and np.all(self.alpha == self.alpha.flat[0]))


class Medium:
    """Materials, regions and march options of a resolved scenario (``arfi.Scenario.to_dict``)."""

    def __init__(self, scenario: dict, frequency: float):
        self.materials = {m["name"]: m for m in scenario["material"]}
        names = [m["name"] for m in scenario["material"]]
        default = "water" if "water" in names else names[0]
        self.background = scenario.get("medium", {}).get("background", default)
        self.regions = scenario.get("region", [])
        self.frequency = frequency
        grid = scenario.get("grid", {})
        self.interfaces = grid.get("interfaces", "angular")
        self.screen = grid.get("screen", "oblique")
        self.sponge_width = grid.get("sponge_width_mm", 10.0) * 1e-3
        self.focus = np.array(scenario["focus"]["position_mm"]) * 1e-3
        if grid.get("reflections", False):
            raise ValueError("reflections towards the source are not supported here")
        for r in self.regions:
            if r["shape"] not in ("cylinder", "slab"):
                raise ValueError(f"region shape {r['shape']!r} not supported here")
        if "ct" in scenario:
            raise ValueError("CTs are not supported here")

    def _props(self, name: str) -> tuple[float, float, float]:
        m = self.materials[name]
        alpha = m["attenuation_db_cm_mhz"] * (self.frequency / 1e6) ** m["attenuation_power"] * 100.0 * NP_PER_DB
        return m["sound_speed_m_s"], m["density_kg_m3"], alpha

    def min_sound_speed(self) -> float:
        return min(m["sound_speed_m_s"] for m in self.materials.values())

    def key(self, z: float) -> tuple[bool, ...]:
        """Which regions' z-ranges contain ``z`` (equal keys: equal slices)."""
        return tuple(r["z_min_mm"] * 1e-3 <= z <= r["z_max_mm"] * 1e-3 for r in self.regions)

    def slice(self, g: Grid, z: float) -> Slice:
        """The properties on the grid at height z; the last region containing a point wins."""
        x, y = np.meshgrid(g.x(), g.y())
        c, rho, a = (np.full((g.ny, g.nx), v) for v in self._props(self.background))
        for r in self.regions:
            inside = np.full(x.shape, r["z_min_mm"] * 1e-3 <= z <= r["z_max_mm"] * 1e-3)
            if r["shape"] == "cylinder":
                cx, cy = (v * 1e-3 for v in r.get("center_mm", [0.0, 0.0]))
                radius = r["radius_mm"] * 1e-3
                inside &= (x - cx) ** 2 + (y - cy) ** 2 <= radius * radius
            for arr, v in zip((c, rho, a), self._props(r["material"])):
                arr[inside] = v
        return Slice(c, rho, a)


def sponge(g: Grid, width: float = 10e-3, strength: float = 6.9) -> np.ndarray:
    """The absorbing layer sigma (Np/m): quadratic in the depth into the layer."""
    if width <= 0:
        return np.zeros((g.ny, g.nx))

    def depth(n: int, d: float) -> np.ndarray:
        i = np.arange(n)
        return np.maximum((width - np.minimum(i, n - 1 - i) * d) / width, 0.0)

    e = np.maximum(depth(g.nx, g.dx)[None, :], depth(g.ny, g.dy)[:, None])
    return 3.0 * strength / width * e * e


def wavenumbers(n: int, d: float) -> np.ndarray:
    return 2.0 * np.pi * np.fft.fftfreq(n, d)


def axial_wavenumber(k: complex | np.ndarray, kt2: np.ndarray) -> np.ndarray:
    """``sqrt(k² - kt²)``, the root with ``Im >= 0``."""
    kz = np.sqrt(k * k - kt2 + 0j)
    return np.where(kz.imag < 0, -kz, kz)


def reflection(omega: float, a: tuple[float, ...], b: tuple[float, ...], kt2: np.ndarray) -> np.ndarray:
    """Plane-wave pressure reflection coefficient from medium ``a`` into ``b``, each (c, rho, alpha)."""
    kza = axial_wavenumber(omega / a[0] + 1j * a[2], kt2)
    kzb = axial_wavenumber(omega / b[0] + 1j * b[2], kt2)
    num, den = b[1] * kza - a[1] * kzb, b[1] * kza + a[1] * kzb
    return np.where(den != 0, num / np.where(den != 0, den, 1), 0)


class Spectral:
    """An angular interface: ``psi <- (psi + Σ_pairs M_ab·IFFT(R_ab·FFT(psi))) · sqrt(Z_a/Z_b)``."""

    def __init__(self, pairs: list[tuple[np.ndarray | None, np.ndarray]], scale: np.ndarray):
        self.pairs = pairs  # (mask of the pair's pixels or None for all, R_ab on the fft2 layout)
        self.scale = scale  # sqrt(Z_a/Z_b) on each pair's pixels, 1 elsewhere

    def cross(self, psi: np.ndarray) -> np.ndarray:
        spectrum = np.fft.fft2(psi)
        reflected = np.zeros_like(psi)
        for mask, r in self.pairs:
            wave = np.fft.ifft2(spectrum * r)
            reflected += wave if mask is None else np.where(mask, wave, 0)
        return (psi + reflected) * self.scale


class Pointwise:
    """A normal-incidence interface: ``psi <- psi·(1 + R)·sqrt((1 - R)/(1 + R))`` per pixel."""

    def __init__(self, r: np.ndarray):
        self.factor = np.where(r != 0, (1 + r) * np.sqrt((1 - r) / (1 + r)), 1.0)

    def cross(self, psi: np.ndarray) -> np.ndarray:
        return psi * self.factor


def interface(g: Grid, a: Slice, b: Slice, omega: float, model: str, shared: dict) -> tuple[object, float]:
    """The interface from slab ``a`` into ``b`` (as ``Interface::new`` for faces on a plane) and
    its strength (largest normal-incidence ``|R|``). ``shared``: the plan's spectral coefficients
    by material pair."""
    za, zb = a.impedance(), b.impedance()
    normal = (zb - za) / (za + zb)
    strength = float(np.max(np.abs(normal)))
    if model == "normal-incidence":
        return Pointwise(normal), strength
    pa = np.stack([a.c, a.rho, a.alpha], axis=-1).reshape(-1, 3)
    pb = np.stack([b.c, b.rho, b.alpha], axis=-1).reshape(-1, 3)
    differ = np.any(pa != pb, axis=1)
    changed = np.concatenate([pa, pb], axis=1)[differ]  # (c, rho, alpha) before and after, per pixel
    pairs, first, inverse = np.unique(changed, axis=0, return_index=True, return_inverse=True)
    new = sum(1 for p in pairs if tuple(p) not in shared)
    if len(pairs) > MAX_SPECTRAL_PAIRS or len(shared) + new > MAX_PLAN_PAIRS:
        return Pointwise(normal), strength
    kx, ky = wavenumbers(g.nx, g.dx)[None, :], wavenumbers(g.ny, g.dy)[:, None]
    kt2 = kx * kx + ky * ky
    labels = np.full(g.nx * g.ny, -1)
    labels[differ] = inverse.ravel()
    scale = np.ones(g.nx * g.ny)
    out = []
    for p in np.argsort(first):  # in order of each pair's first pixel, as arfi sums them
        key = tuple(pairs[p])
        if key not in shared:
            shared[key] = reflection(omega, key[:3], key[3:], kt2)
        mask = labels == p
        scale[mask] = math.sqrt((key[1] * key[0]) / (key[4] * key[3]))
        out.append((None if mask.all() else mask.reshape(g.ny, g.nx), shared[key]))
    return Spectral(out, scale.reshape(g.ny, g.nx)), strength


def propagator(g: Grid, k: float, alpha: float) -> np.ndarray:
    kx, ky = wavenumbers(g.nx, g.dx)[None, :], wavenumbers(g.ny, g.dy)[:, None]
    kt2 = kx * kx + ky * ky
    if alpha == 0.0:
        kz2 = k * k - kt2
        return np.where(kz2 >= 0, np.exp(1j * np.sqrt(np.abs(kz2)) * g.dz), np.exp(-np.sqrt(np.abs(kz2)) * g.dz))
    return np.exp(1j * axial_wavenumber(k + 1j * alpha, kt2) * g.dz + alpha * g.dz)


def screen(
    g: Grid, s: Slice, sigma: np.ndarray, omega: float, k_mean: float, a_mean: float, sin2: np.ndarray | None
) -> np.ndarray:
    k = omega / s.c
    if sin2 is None:
        phase, absorption = k - k_mean, s.alpha
    else:
        kt2 = np.minimum(k * k * sin2, MAX_OBLIQUITY_SIN2 * np.minimum(k, k_mean) ** 2)
        kz, kz_mean = np.sqrt(k * k - kt2), np.sqrt(k_mean * k_mean - kt2)
        phase, absorption = kz - kz_mean, s.alpha * k / kz - a_mean * (k_mean / kz_mean - 1.0)
    return np.exp(-(absorption + sigma) * g.dz) * np.exp(1j * phase * g.dz)


def obliquity(g: Grid, z: float, toward: np.ndarray) -> np.ndarray:
    """``sin² θ`` of the line from each pixel at height z to the point ``toward``."""
    rho2 = (g.x()[None, :] - toward[0]) ** 2 + (g.y()[:, None] - toward[1]) ** 2
    return np.where(rho2 > 0, rho2 / (rho2 + (z - toward[2]) ** 2), 0.0)


def rounded(v: float, quantum: float) -> float:
    return math.floor(v / quantum + 0.5) * quantum  # Rust's f64::round for v >= 0


@dataclass
class Step:
    interface: Spectral | Pointwise | None
    propagator: np.ndarray
    screen: np.ndarray
    to_pressure: np.ndarray  # sqrt(Z/Z_s) of the slab after the step: psi -> p on plane n + 1


class Plan:
    """Per-step operators, fixed by marching the reference beam (as ``HasPlan::build``)."""

    def __init__(self, g: Grid, medium: Medium, reference: np.ndarray):
        omega = 2.0 * np.pi * medium.frequency
        sigma = sponge(g, medium.sponge_width)
        quantum = omega / medium.min_sound_speed() * 1e-4
        source = medium.slice(g, g.z0 - 0.5 * g.dz)
        psi = reference.copy()  # the source medium's psi is its pressure
        prev, prev_key, slab = source, None, -1
        props: Slice | None = None
        propagators: dict[tuple[float, float], np.ndarray] = {}
        screens: dict[tuple[int, float], np.ndarray] = {}
        shared: dict = {}
        strengths: list[float] = []
        self.steps: list[Step] = []
        self.grid = g
        for n in range(g.nz - 1):
            z = g.z(n) + 0.5 * g.dz
            key = medium.key(z)
            if props is None or key != prev_key:
                new = medium.slice(g, z)
                if props is None or new != props:
                    props, slab = new, slab + 1
            prev_key = key
            crossing = None
            if props != prev:
                crossing, strength = interface(g, prev, props, omega, medium.interfaces, shared)
                strengths.append(strength)
                psi = crossing.cross(psi)
            w = np.abs(psi)
            if np.sum(w) > 0:
                k_mean, a_mean = np.sum(w * omega / props.c) / np.sum(w), np.sum(w * props.alpha) / np.sum(w)
            else:
                k_mean, a_mean = np.mean(omega / props.c), np.mean(props.alpha)
            k_mean, a_mean = rounded(float(k_mean), quantum), rounded(float(a_mean), quantum)
            if (k_mean, a_mean) not in propagators:
                propagators[k_mean, a_mean] = propagator(g, k_mean, a_mean)
            if medium.screen == "oblique" and not props.is_uniform():
                step_screen = screen(g, props, sigma, omega, k_mean, a_mean, obliquity(g, z, medium.focus))
            else:
                if (slab, k_mean) not in screens:
                    screens[slab, k_mean] = screen(g, props, sigma, omega, k_mean, a_mean, None)
                step_screen = screens[slab, k_mean]
            to_pressure = np.sqrt(props.impedance() / source.impedance())
            step = Step(crossing, propagators[k_mean, a_mean], step_screen, to_pressure)
            psi = np.fft.ifft2(np.fft.fft2(psi) * step.propagator) * step.screen  # crossed above
            self.steps.append(step)
            prev = props
        strongest = max(strengths, default=0.0)
        strong = [s for s in strengths if s > 0 and s * strongest >= ROUND_TRIP_THRESHOLD]
        if medium.interfaces == "angular" and len(strong) > 1:
            raise NotImplementedError("a reverberating layer (arfi adds its round trips; this copy does not)")

    def march(self, source: np.ndarray, plane: int) -> tuple[np.ndarray, np.ndarray]:
        """The pressure on ``plane`` and on the axis (the pixel nx/2, ny/2) of every plane."""
        g = self.grid
        centre = (g.ny // 2, g.nx // 2)
        psi, axis, kept = source.copy(), [source[centre]], source if plane == 0 else None
        for n, step in enumerate(self.steps, start=1):
            psi = apply(step, psi)
            axis.append(psi[centre] * step.to_pressure[centre])
            if n == plane:
                kept = psi * step.to_pressure
        return kept, np.array(axis)


def apply(step: Step, psi: np.ndarray) -> np.ndarray:
    if step.interface is not None:
        psi = step.interface.cross(psi)
    return np.fft.ifft2(np.fft.fft2(psi) * step.propagator) * step.screen
