"""A second opinion from an engine this project did not write: the scenario's beam computed by
BabelViscoFDTD (S. Pichardo's viscoelastic staggered-grid FDTD, OpenMP on the CPU; install with
``pip install 'arfi[fullwave]'``) and read back exactly as the march's field is (the same focal
metrics, hottest places and output files: :meth:`Simulation.field_from_volume`).

What the engine is given, and why:

- **The march's own source plane** (the elements' Rayleigh integral on the plane z0 in water),
  so that the two engines differ only in how they carry it through the medium. It enters as a
  pressure (stress) source added on that plane every time step. A sheet adding ``q`` (Pa/s) to
  the pressure radiates ``p̂ = q̂·k/(2·c·kz)`` each way in the plane-wave basis, so adding
  ``S(kx, ky) = 2·c·(Δt/h)·(kz/k)·P(kx, ky)`` per step gives the forward wave ``P`` on the
  plane; the backward wave leaves through the absorbing layer behind it.
- **The medium** at every voxel centre as the march samples it
  (:meth:`Simulation.properties_at`: density, compressional speed and attenuation at the
  frequency; shear speed and attenuation where the scenario gives bone a shear wave), grouped
  into at most :data:`MAX_MATERIALS` materials.
- **Cubic voxels** ``h`` of ``λ_min / points_per_wavelength`` (``λ_min`` the shortest
  wavelength present, compressional or shear), made a divisor of the march's lateral step when
  that takes less than 10 % off (the march's samples are then voxels). The engine is second
  order: at 6 points per wavelength a cortical cap's focal pressure comes out about 9 % high,
  hence the default of 8.
- **The box**: the march's grid cut laterally to the square about its axis that holds all but
  :data:`BOX_OUTSIDE` of every plane's power in the march's field, a wavelength wider; along z from the source plane to
  the
  grid's last plane; an absorbing layer of ``pml_cells`` around it (water: the engine makes it
  so). Outside the box the field is reported as zero.
- **A continuous drive** with a three-period raised-cosine onset, the time step made a whole
  fraction of the period; the run lasts the onset, the slowest wave's time along the box's
  longest source-to-point line and eight periods more, then two windows of ``record_periods``
  periods each: ``|p| = √2·RMS`` over both (everywhere, trilinear between voxels) and the phase
  from a DFT over the last (the plane and the axis, four-point Lagrange between voxels).
  ``steady_change`` is the relative change of the focal amplitude between the two windows: the
  run had reached its steady state when it is small.

The engine's "pressure" is ``ρ·c_p²`` times the velocity's divergence: the pressure in fluids
(water, soft tissue), not the mean stress inside a solid.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import multiprocessing
import os
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any

import numpy as np
from numpy.typing import NDArray

ENGINE = "BabelViscoFDTD"
#: The release the stored references and the timing below were made with.
ENGINE_VERSION = "1.2.7"
#: Wall time per voxel and time step, single precision, OpenMP on 2 cores (measured); the
#: estimate printed before a run scales it by the cores present.
NS_PER_VOXEL_STEP_2_CORES = 80.0
#: The engine's memory per voxel (bytes): its fields, memory variables, material maps and the
#: RMS map, single precision (measured peak resident size over voxels, with margin).
BYTES_PER_VOXEL = 260
#: The box leaves out at most this fraction of any plane's power (in the march's field).
BOX_OUTSIDE = 2e-3
#: Phases of the drive are quantised to this many source functions (at most 2.8° off).
PHASE_BINS = 64
#: Materials the medium is grouped into (the engine tabulates each).
MAX_MATERIALS = 4096

Progress = Callable[[str], None]


@dataclasses.dataclass(frozen=True)
class FdtdOptions:
    """How the full-wave run is made: ``points_per_wavelength`` (of the shortest wavelength
    present), ``pml_cells`` (absorbing layer), ``record_periods`` (each of the two windows)."""

    points_per_wavelength: float = 8.0
    pml_cells: int = 12
    record_periods: int = 4

    def __post_init__(self) -> None:
        if not (math.isfinite(self.points_per_wavelength) and 4.0 <= self.points_per_wavelength <= 30.0):
            raise ValueError(f"points_per_wavelength: must lie within 4 to 30, got {self.points_per_wavelength}")
        if not 6 <= self.pml_cells <= 40:
            raise ValueError(f"pml_cells: must lie within 6 to 40, got {self.pml_cells}")
        if not 1 <= self.record_periods <= 50:
            raise ValueError(f"record_periods: must lie within 1 to 50, got {self.record_periods}")


def engine_available() -> bool:
    """Whether BabelViscoFDTD is installed (the ``fullwave`` extra)."""
    return importlib.util.find_spec("BabelViscoFDTD") is not None


def require_engine() -> None:
    """Raises ValueError (one line) when the ``fullwave`` extra is not installed."""
    if not engine_available():
        raise ValueError(
            "--engine fdtd: needs the full-wave engine, which is not installed: pip install 'arfi[fullwave]' "
            f"(BabelViscoFDTD {ENGINE_VERSION})"
        )


@dataclasses.dataclass(frozen=True)
class FdtdPlan:
    """The run before it starts: voxel ``h_m``, the march's columns, rows (inclusive ranges) the
    box covers, the engine's array ``shape`` (x, y, z, absorbing layer included), node (0, 0, 0)
    at ``origin_m``, the source plane's z index ``k_source``, time step ``dt_s`` (``steps_per_period``
    a period), ``settle_periods`` before the two windows, the memory and the time it will take."""

    h_m: float
    cols: tuple[int, int]
    rows: tuple[int, int]
    shape: tuple[int, int, int]
    origin_m: tuple[float, float, float]
    k_source: int
    dt_s: float
    steps_per_period: int
    settle_periods: int
    record_periods: int
    pml_cells: int
    frequency_hz: float

    @property
    def voxels(self) -> int:
        return int(np.prod(self.shape))

    @property
    def steps(self) -> int:
        return self.steps_per_period * (self.settle_periods + 2 * self.record_periods)

    @property
    def memory_bytes(self) -> int:
        return self.voxels * BYTES_PER_VOXEL

    @property
    def seconds(self) -> float:
        """The run's expected wall time: :data:`NS_PER_VOXEL_STEP_2_CORES` scaled by the cores."""
        cores = max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
        return self.voxels * self.steps * NS_PER_VOXEL_STEP_2_CORES * 1e-9 * 2.0 / cores

    def describe(self) -> str:
        nx, ny, nz = self.shape
        return (
            f"{ENGINE} {ENGINE_VERSION}: {nx} x {ny} x {nz} voxels of {self.h_m * 1e3:.3f} mm ({self.voxels / 1e6:.1f} "
            f"M, about {self.memory_bytes / 2**30:.1f} GiB), {self.steps} steps of {self.dt_s * 1e9:.1f} ns "
            f"({self.settle_periods} periods to settle, 2 x {self.record_periods} recorded); about "
            f"{_duration(self.seconds)}"
        )

    def fractional(self, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points (m, (n, 3)) in node units: node (i, j, k) at (i, j, k)."""
        return (points_m - np.array(self.origin_m)) / self.h_m

    def node_x(self, i: NDArray[Any] | int) -> Any:
        return self.origin_m[0] + np.asarray(i) * self.h_m

    def node_y(self, j: NDArray[Any] | int) -> Any:
        return self.origin_m[1] + np.asarray(j) * self.h_m

    def node_z(self, k: NDArray[Any] | int) -> Any:
        return self.origin_m[2] + np.asarray(k) * self.h_m


def _duration(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min" if s < 7200 else f"{s / 3600:.1f} h"


def available_memory_bytes() -> int | None:
    """``MemAvailable`` of /proc/meminfo (None where there is none)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _grid_axes(march: Any) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The march's sample positions (m) along x, y and z (from its field)."""
    return (np.asarray(march.x_mm) * 1e-3, np.asarray(march.y_mm) * 1e-3, np.asarray(march.axis_z_mm) * 1e-3)


def _medium(sim: Any, points_m: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
    """The medium at points (m, shape (n, 3)), in chunks: density, compressional speed,
    attenuation (Np/m) and, where given, shear speed and attenuation (0 for a fluid)."""
    keys = ("density_kg_m3", "sound_speed_m_s", "attenuation_np_m", "shear_sound_speed_m_s", "shear_attenuation_np_m")
    out = {k: np.zeros(len(points_m)) for k in keys}
    for a in range(0, len(points_m), 1 << 20):
        props = sim.properties_at(points_m[a : a + (1 << 20)] * 1e3)
        for k in keys:
            if k in props:
                out[k][a : a + (1 << 20)] = props[k]
    return out


def _lateral_box(magnitude: NDArray[np.float32]) -> tuple[tuple[int, int], tuple[int, int]]:
    """The columns and rows (inclusive) of the smallest box about the grid's centre holding all
    but :data:`BOX_OUTSIDE` of every plane's power (|p|², (nz, ny, nx)): what leaves it is the
    wide-angle edge waves near the source, travelling away from everything."""
    power = magnitude.astype(np.float64) ** 2
    total = power.sum(axis=(1, 2))
    nz, ny, nx = power.shape
    ci, cj = (nx - 1) / 2, (ny - 1) / 2
    for half in range(1, max(nx, ny)):
        i0, i1 = max(0, math.floor(ci - half)), min(nx - 1, math.ceil(ci + half))
        j0, j1 = max(0, math.floor(cj - half)), min(ny - 1, math.ceil(cj + half))
        inside = power[:, j0 : j1 + 1, i0 : i1 + 1].sum(axis=(1, 2))
        if (total - inside <= BOX_OUTSIDE * total).all():
            return (i0, i1), (j0, j1)
    return (0, nx - 1), (0, ny - 1)


def plan(sim: Any, march: Any, options: FdtdOptions | None = None) -> FdtdPlan:
    """The run for ``sim``'s beam whose marched field is ``march`` (made with ``volume=True``: its
    ``|p|`` bounds the box). Cheap: no engine call."""
    options = options or FdtdOptions()
    f0 = sim.frequency_hz
    x, y, z = _grid_axes(march)
    march_magnitude = march.pressure_volume().pressure_pa
    dx, dy = float(x[1] - x[0]), float(y[1] - y[0])
    # The shortest wavelength along the march's axis and over the box's medium: sampled coarsely.
    ii, jj = _lateral_box(march_magnitude)
    probe = np.stack(
        np.meshgrid(x[ii[0] : ii[1] + 1 : 4], y[jj[0] : jj[1] + 1 : 4], z[::4], indexing="ij"), -1
    ).reshape(-1, 3)
    m = _medium(sim, probe)
    speeds = np.concatenate([m["sound_speed_m_s"], m["shear_sound_speed_m_s"][m["shear_sound_speed_m_s"] > 0]])
    c_min, c_max = float(speeds.min()), float(m["sound_speed_m_s"].max())
    wavelength = c_min / f0
    h = wavelength / options.points_per_wavelength
    n = max(1, math.ceil(min(dx, dy) / h))
    if min(dx, dy) / n >= 0.9 * h:  # the march's samples on voxels, when that costs little
        h = min(dx, dy) / n
    reach = wavelength
    cols = (
        max(0, int(np.searchsorted(x, x[ii[0]] - reach))),
        min(len(x) - 1, int(np.searchsorted(x, x[ii[1]] + reach))),
    )
    rows = (
        max(0, int(np.searchsorted(y, y[jj[0]] - reach))),
        min(len(y) - 1, int(np.searchsorted(y, y[jj[1]] + reach))),
    )
    edge = options.pml_cells + 2
    n_in = [
        math.ceil((x[cols[1]] - x[cols[0]]) / h - 1e-9) + 1,
        math.ceil((y[rows[1]] - y[rows[0]]) / h - 1e-9) + 1,
        math.ceil((z[-1] - z[0]) / h - 1e-9) + 3,
    ]
    shape = (n_in[0] + 2 * edge, n_in[1] + 2 * edge, n_in[2] + 2 * edge)
    origin = (float(x[cols[0]] - edge * h), float(y[rows[0]] - edge * h), float(z[0] - edge * h))
    # The time step: a whole fraction of the period within the engine's stability bound.
    period = 1.0 / f0
    dt_limit = 0.99 * h * 6.0 / 7.0 / (c_max * math.sqrt(3.0)) * 0.95  # Babel's bound (Bohlen 2002), less for loss
    steps_per_period = math.ceil(period / dt_limit)
    lengths = np.array(n_in, float) * h
    crossing = math.hypot(lengths[2], 0.5 * math.hypot(lengths[0], lengths[1])) / c_min
    settle = 3 + math.ceil(crossing / period) + 8
    return FdtdPlan(
        h_m=h,
        cols=cols,
        rows=rows,
        shape=shape,
        origin_m=origin,
        k_source=edge,
        dt_s=period / steps_per_period,
        steps_per_period=steps_per_period,
        settle_periods=settle,
        record_periods=options.record_periods,
        pml_cells=options.pml_cells,
        frequency_hz=f0,
    )


def check_memory(p: FdtdPlan) -> None:
    """Raises ValueError (one line) when the run would not fit in the memory available."""
    avail = available_memory_bytes()
    if avail is not None and p.memory_bytes > 0.8 * avail:
        nx, ny, nz = p.shape
        raise ValueError(
            f"--engine fdtd: {nx} x {ny} x {nz} voxels need about {p.memory_bytes / 2**30:.1f} GiB, more than the "
            f"{avail / 2**30:.1f} GiB available: use fewer points per wavelength or a smaller grid"
        )


def _materials(sim: Any, p: FdtdPlan, background: dict[str, float]) -> tuple[NDArray[np.uint32], NDArray[np.float64]]:
    """The engine's material map (x, y, z) and its table (density, c_p, c_s, alpha_p, alpha_s in
    SI units): every voxel's medium rounded to 1 m/s, 1 kg/m³ and 0.1 Np/m (coarser while more
    than :data:`MAX_MATERIALS` remain). Material 0, which the engine puts in its absorbing layer,
    is the water at the source plane."""
    nx, ny, nz = p.shape
    xs, ys = p.node_x(np.arange(nx)), p.node_y(np.arange(ny))
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    cols = ("density_kg_m3", "sound_speed_m_s", "shear_sound_speed_m_s", "attenuation_np_m", "shear_attenuation_np_m")
    values = np.empty((nx, ny, nz, 5), np.float32)
    for k in range(nz):
        pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, p.node_z(k))], -1)
        m = _medium(sim, pts)
        for c, key in enumerate(cols):
            values[:, :, k, c] = m[key].reshape(nx, ny)
    flat = values.reshape(-1, 5)
    quanta = np.array([1.0, 1.0, 1.0, 0.1, 0.1])
    while True:
        codes = np.round(flat / quanta).astype(np.int64)
        table, index = np.unique(codes, axis=0, return_inverse=True)
        if len(table) <= MAX_MATERIALS:
            break
        quanta *= 2.0
    water = np.array([background[c] for c in cols])
    props = np.vstack([water, table * quanta])
    return (index.reshape(nx, ny, nz) + 1).astype(np.uint32), props


def _lagrange(t: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Four-point Lagrange interpolation at fractional node positions ``t``: the first node of
    each stencil and its four weights (exact for cubics; for a wave of k·h = π/4, 1e-2)."""
    base = np.floor(t).astype(np.int64) - 1
    u = t - (base + 1)
    near = np.abs(u) < 1e-9  # on a node: that node alone
    w = np.stack(
        [
            -u * (u - 1) * (u - 2) / 6,
            (u + 1) * (u - 1) * (u - 2) / 2,
            -(u + 1) * u * (u - 2) / 2,
            (u + 1) * u * (u - 1) / 6,
        ],
        -1,
    )
    w[near] = [0.0, 1.0, 0.0, 0.0]
    return base, w


@dataclasses.dataclass(frozen=True)
class _Stencils:
    """Points read from the engine's nodes: per point 4 x 4 x 4 node indices and weights."""

    nodes: NDArray[np.int64]  # (n, 64, 3)
    weights: NDArray[np.float64]  # (n, 64)


def _stencils(p: FdtdPlan, points_m: NDArray[np.float64]) -> _Stencils:
    f = p.fractional(points_m)
    (bx, wx), (by, wy), (bz, wz) = _lagrange(f[:, 0]), _lagrange(f[:, 1]), _lagrange(f[:, 2])
    o = np.arange(4)
    ii = (bx[:, None, None, None] + o[None, :, None, None]) + 0 * o[None, None, :, None] + 0 * o[None, None, None, :]
    jj = 0 * o[None, :, None, None] + (by[:, None, None, None] + o[None, None, :, None]) + 0 * o[None, None, None, :]
    kk = 0 * o[None, :, None, None] + 0 * o[None, None, :, None] + (bz[:, None, None, None] + o[None, None, None, :])
    w = wx[:, :, None, None] * wy[:, None, :, None] * wz[:, None, None, :]
    nodes = np.stack([ii, jj, kk], -1).reshape(len(points_m), 64, 3)
    return _Stencils(nodes=nodes, weights=w.reshape(len(points_m), 64))


def _source(
    sim: Any, march: Any, p: FdtdPlan, phases: NDArray[np.float64] | None, c_source: float
) -> NDArray[np.complex128]:
    """The stress added per step on the source plane's interior nodes, (nx, ny) of the box:
    ``2·c·(Δt/h)·(kz/k)·P`` with P the march's source plane (its band-limited series evaluated at
    the engine's nodes)."""
    x, y, _ = _grid_axes(march)
    p0 = sim.source_field(phases)
    ny_m, nx_m = p0.shape
    a = np.fft.fft2(p0) / (nx_m * ny_m)
    kx = 2 * np.pi * np.fft.fftfreq(nx_m, x[1] - x[0])
    ky = 2 * np.pi * np.fft.fftfreq(ny_m, y[1] - y[0])
    if nx_m % 2 == 0:
        a[:, nx_m // 2] = 0.0
    if ny_m % 2 == 0:
        a[ny_m // 2, :] = 0.0
    k = 2 * np.pi * p.frequency_hz / c_source
    kz = np.sqrt((k**2 - kx[None, :] ** 2 - ky[:, None] ** 2).astype(complex))
    f = a * kz / k
    nx, ny, _ = p.shape
    xn, yn = p.node_x(np.arange(nx)), p.node_y(np.arange(ny))
    ex = np.exp(1j * np.outer(xn - x[0], kx))  # (nx, nx_m)
    ey = np.exp(1j * np.outer(yn - y[0], ky))  # (ny, ny_m)
    s = ex @ f.T @ ey.T  # (nx, ny)
    inside = np.zeros((nx, ny), bool)
    e = p.pml_cells + 2
    inside[e : nx - e, e : ny - e] = True
    scaled: NDArray[np.complex128] = np.where(inside, s, 0.0).astype(np.complex128) * (2 * c_source * p.dt_s / p.h_m)
    return scaled


def _babel() -> Any:
    """BabelViscoFDTD's propagation model; its CPU module imports its compiled extension by a
    top-level name, so the package's folder goes on sys.path first."""
    spec = importlib.util.find_spec("BabelViscoFDTD")
    if spec is None or spec.origin is None:
        require_engine()
    folder = os.path.dirname(spec.origin)  # type: ignore[union-attr, arg-type]
    if folder not in sys.path:
        sys.path.insert(0, folder)
    with _quiet():  # it says which of its backends loaded
        from BabelViscoFDTD.PropagationModel import PropagationModel  # type: ignore[import-untyped,import-not-found,unused-ignore]

    return PropagationModel()


def engine_time_step(material_map: NDArray[np.uint32], props: NDArray[np.float64], p: FdtdPlan) -> float:
    """The engine's own stability limit on the time step (s) for this medium."""
    model = _babel()
    src = np.zeros(material_map.shape, np.uint32)
    with _quiet():
        _, dt = model.StaggeredFDTD_3D_with_relaxation(
            material_map,
            props,
            p.frequency_hz,
            src,
            np.zeros((1, 4), np.float32),
            p.h_m,
            10 * p.dt_s,
            src,
            Ox=np.ones(material_map.shape, np.float32),
            TypeSource=2,
            CheckOnlyParams=True,
            USE_SINGLE=True,
            COMPUTING_BACKEND=0,
        )
    return float(dt)


class _quiet:
    """Sends the engine's prints (Python's and its C code's) to /dev/null."""

    def __enter__(self) -> None:
        sys.stdout.flush()
        self.saved = os.dup(1)
        self.null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self.null, 1)

    def __exit__(self, *exc: object) -> None:
        sys.stdout.flush()
        os.dup2(self.saved, 1)
        os.close(self.saved)
        os.close(self.null)


def _engine_run(job: dict[str, Any]) -> dict[str, Any]:
    """Runs the engine on ``job``'s arrays (in a child process, so that the parent can report
    progress while it runs): the sensors' pressure over time, its times and the RMS map."""
    model = _babel()
    with _quiet():
        out = model.StaggeredFDTD_3D_with_relaxation(
            job["material_map"],
            job["props"],
            job["frequency_hz"],
            job["source_map"],
            job["source_functions"],
            job["h_m"],
            job["duration_s"],
            job["sensor_map"],
            Ox=job["weights"],
            NDelta=job["pml_cells"],
            DT=job["dt_s"],
            TypeSource=2,
            USE_SINGLE=True,
            COMPUTING_BACKEND=0,
            SelRMSorPeak=1,
            SelMapsRMSPeakList=["Pressure"],
            SelMapsSensorsList=["Pressure"],
            SensorSubSampling=job["sub"],
            SensorStart=job["sensor_start"],
            SILENT=1,
        )
    sensors, rms = out[0], out[2]
    return {
        "pressure": np.asarray(sensors["Pressure"], np.float64),
        "time": np.asarray(sensors["time"], np.float64),
        "rms": np.asarray(rms["Pressure"], np.float32),
    }


def _sub_sampling(steps_per_period: int) -> int:
    """The largest divisor of the period's steps that keeps at least 8 samples a period."""
    return max(d for d in range(1, steps_per_period + 1) if steps_per_period % d == 0 and steps_per_period // d >= 8)


@dataclasses.dataclass(frozen=True)
class FdtdResult:
    """What the engine gives back on the march's grid: the complex ``plane`` (ny, nx) at ``z_mm``,
    the complex ``axis`` (one per march plane), ``magnitude`` (|p|, (nz, ny, nx)), the relative
    change of the focal amplitude between the two recorded windows (``steady_change``), the plan
    and the wall time."""

    plane: NDArray[np.complex128]
    z_mm: float
    axis: NDArray[np.complex128]
    magnitude: NDArray[np.float32]
    steady_change: float
    plan: FdtdPlan
    seconds: float
    materials: int


def run(
    sim: Any,
    march: Any,
    phases: NDArray[np.float64] | None,
    options: FdtdOptions | None = None,
    progress: Progress | None = None,
) -> FdtdResult:
    """The beam of ``sim`` driven with ``phases`` (added per element, as ``Simulation.field``'s)
    computed by the full-wave engine; ``march`` is the march's field of the same drive with its
    volume (it bounds the box and gives the plane's z). ``progress`` receives one-line messages:
    the plan and its estimate before the engine starts, then the elapsed time every 30 s."""
    require_engine()
    say = progress or (lambda _m: None)
    t0 = time.perf_counter()
    p = plan(sim, march, options)
    check_memory(p)
    centre = np.array([[0.0, 0.0, march.axis_z_mm[0]]])
    b = _medium(sim, centre * 1e-3)
    background = {k: float(v[0]) for k, v in b.items()}
    say(f"fdtd: sampling the medium on {p.shape[0]} x {p.shape[1]} x {p.shape[2]} voxels")
    material_map, props = _materials(sim, p, background)
    dt = engine_time_step(material_map, props, p)
    if dt < p.dt_s:
        steps = math.ceil(1.0 / (p.frequency_hz * dt))
        p = dataclasses.replace(p, steps_per_period=steps, dt_s=1.0 / (p.frequency_hz * steps))
    say(f"fdtd: {p.describe()}")
    s = _source(sim, march, p, phases, background["sound_speed_m_s"])
    amp = np.abs(s)
    keep = amp > 1e-7 * amp.max()
    bins = (np.round(np.angle(s) / (2 * np.pi / PHASE_BINS)).astype(np.int64) % PHASE_BINS) + 1
    source_map = np.zeros(p.shape, np.uint32)
    weights = np.zeros(p.shape, np.float32)
    source_map[:, :, p.k_source] = np.where(keep, bins, 0)
    weights[:, :, p.k_source] = np.where(keep, amp, 0.0)
    n_t = p.steps
    t = np.arange(n_t) * p.dt_s
    w = 2 * np.pi * p.frequency_hz
    onset = np.where(t < 3.0 / p.frequency_hz, 0.5 * (1 - np.cos(np.pi * t * p.frequency_hz / 3.0)), 1.0)
    phi = 2 * np.pi * np.arange(PHASE_BINS) / PHASE_BINS
    # Babel adds the value to the normal stresses, and p = -σ: the value is -Re{S e^{-iωt}}.
    functions = (-onset[None, :] * np.cos(w * t[None, :] - phi[:, None])).astype(np.float32)
    # The points read: the march's plane nearest z within the box, and the axis.
    x, y, z = _grid_axes(march)
    c0, c1 = p.cols
    r0, r1 = p.rows
    zp = float(march.z_mm) * 1e-3
    X, Y = np.meshgrid(x[c0 : c1 + 1], y[r0 : r1 + 1], indexing="xy")
    plane_pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, zp)], -1)
    ax = np.stack([np.asarray(march.axis_x_mm) * 1e-3, np.asarray(march.axis_y_mm) * 1e-3, z], -1)
    inside = _inside(p, ax)
    st = _stencils(p, np.vstack([plane_pts, ax[inside]]))
    shape = np.array(p.shape)
    flat = np.ravel_multi_index(tuple(st.nodes.reshape(-1, 3).T), p.shape, order="F").reshape(st.weights.shape)
    used = np.unique(flat[st.weights != 0])
    sensor_map = np.zeros(p.shape, np.uint32)
    sensor_map[np.unravel_index(used, p.shape, order="F")] = 1  # the engine orders its sensors so
    assert (st.nodes >= 0).all() and (st.nodes < shape).all()
    sub = _sub_sampling(p.steps_per_period)
    job = dict(
        material_map=material_map,
        props=props,
        frequency_hz=p.frequency_hz,
        source_map=source_map,
        source_functions=functions,
        h_m=p.h_m,
        duration_s=(n_t - 0.5) * p.dt_s,
        sensor_map=sensor_map,
        weights=weights,
        pml_cells=p.pml_cells,
        dt_s=p.dt_s,
        sub=sub,
        sensor_start=p.settle_periods * p.steps_per_period // sub,
    )
    out = _run_child(job, p, say)
    # The complex amplitude per sensor over each window: P = (2/N)·Σ p(t)·e^{iωt}.
    per = p.record_periods * p.steps_per_period // sub
    ts, ps = out["time"], -out["pressure"]  # the engine's "Pressure" integrates +ρc²·div v: it is -p
    phasor = np.exp(1j * w * ts)
    first = 2.0 / per * (ps[:, :per] @ phasor[:per])
    second = 2.0 / per * (ps[:, per : 2 * per] @ phasor[per : 2 * per])
    row = np.searchsorted(used, flat)
    row = np.minimum(row, len(used) - 1)
    values = np.where(st.weights != 0, second[row], 0.0)
    read = (values * st.weights).sum(axis=1)
    read_first = (np.where(st.weights != 0, first[row], 0.0) * st.weights).sum(axis=1)
    n_plane = len(plane_pts)
    i_peak = int(np.argmax(np.abs(read)))
    steady = float(abs(abs(read[i_peak]) - abs(read_first[i_peak])) / max(abs(read[i_peak]), 1e-30))
    # |p| from the RMS (smooth on the voxel's scale: trilinear), the phase from the DFT read by
    # Lagrange interpolation, whose amplitude is 2.6 % low between nodes at 6 points a wavelength.
    rms = np.sqrt(2.0) * out["rms"]
    magnitude = _magnitude_on_march(p, rms, x, y, z)
    plane = np.zeros((len(y), len(x)), complex)
    box = magnitude[int(np.argmin(np.abs(z - zp))), r0 : r1 + 1, c0 : c1 + 1]
    plane[r0 : r1 + 1, c0 : c1 + 1] = box * np.exp(1j * np.angle(read[:n_plane].reshape(r1 - r0 + 1, c1 - c0 + 1)))
    axis = np.zeros(len(z), complex)
    axis[inside] = _trilinear(p, rms, ax[inside]) * np.exp(1j * np.angle(read[n_plane:]))
    return FdtdResult(
        plane=plane,
        z_mm=zp * 1e3,
        axis=axis,
        magnitude=magnitude,
        steady_change=steady,
        plan=p,
        seconds=time.perf_counter() - t0,
        materials=len(props),
    )


def _inside(p: FdtdPlan, pts: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Points whose four-point stencil lies on the engine's nodes (the box and the two voxels
    beyond it)."""
    f = p.fractional(pts)
    inside: NDArray[np.bool_] = np.all((f >= 1) & (f <= np.array(p.shape) - 3), axis=1)
    return inside


def _run_child(job: dict[str, Any], p: FdtdPlan, say: Progress) -> dict[str, Any]:
    """The engine in a child process, the elapsed time said every 30 s while it runs. Forked where
    the platform can (the child needs nothing of the parent's threads, and a script calling this
    need not guard its main module); spawned elsewhere."""
    start = time.perf_counter()
    context = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
        future = pool.submit(_engine_run, job)
        while True:
            try:
                return future.result(timeout=30.0)
            except FutureTimeout:
                say(f"fdtd: {_duration(time.perf_counter() - start)} of about {_duration(p.seconds)}")


def _trilinear(p: FdtdPlan, values: NDArray[np.float32], pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """``values`` on the engine's nodes (x, y, z) at points (m, (n, 3)), trilinearly."""
    f = p.fractional(pts)
    i = np.clip(np.floor(f).astype(np.int64), 0, np.array(p.shape) - 2)
    u = f - i
    out = np.zeros(len(pts))
    for corner in np.ndindex(2, 2, 2):
        c = np.array(corner)
        w = np.prod(np.where(c == 1, u, 1 - u), axis=1)
        out += w * values[i[:, 0] + c[0], i[:, 1] + c[1], i[:, 2] + c[2]]
    return out


def _magnitude_on_march(
    p: FdtdPlan, mag: NDArray[np.float32], x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64]
) -> NDArray[np.float32]:
    """|p| at the march's samples (nz, ny, nx), trilinear between the engine's nodes (the
    envelope is smooth on the voxel's scale); zero outside the box."""
    out = np.zeros((len(z), len(y), len(x)), np.float32)
    c0, c1 = p.cols
    r0, r1 = p.rows
    X, Y = np.meshgrid(x[c0 : c1 + 1], y[r0 : r1 + 1], indexing="xy")
    for n in range(len(z)):
        pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z[n])], -1)
        out[n, r0 : r1 + 1, c0 : c1 + 1] = _trilinear(p, mag, pts).reshape(X.shape)
    return out
