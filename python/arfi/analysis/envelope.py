"""The treatment envelope: where in a head the array can focus, how strongly, and at what cost to
the skull, before any sonication.

Over a grid of targets in the brain (a box and a spacing, or a list), each target gets the CT
prediction of :func:`arfi.predict_targets` (one plan of each head for many targets): the focal
pressure at the target with the corrected phases, uncorrected (the reference steering) and with
straight-ray CT steering, against the focus the array gives there in water (every element in
phase, direct Rayleigh sums); then one march of the corrected beam through the skull, which gives
its focal peak near the target (the focus's distance from it) and the hottest place in the skull.
Intensity scales with the square of the drive, so the skull's I_SPPA is given per MPa² of focal
pressure at the target: how hot the skull runs for a given focus, whatever the drive.

The targets run in tasks of many targets each (each task builds its plans once), in this process
or on dask.distributed workers. Finished targets are written to ``envelope.csv`` as their task
ends, so a run that stops is resumed by running it again: targets already in the file are skipped.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi import _core
from arfi.analysis.cluster import client_on, distributed, refuse_unreachable, threads_each
from arfi.analysis.prediction import predict_targets
from arfi.checks import real_array
from arfi.io.files import atomic_write_text, csv_text, write_volume
from arfi.reports.figures import pyplot, save_figure
from arfi.scenario import Scenario

#: The CSV's columns, in order: the target (mm, transducer frame), its tissue, then per target.
COLUMNS = (
    "x_mm",
    "y_mm",
    "z_mm",
    "tissue",
    "corrected_pa",
    "uncorrected_pa",
    "ray_steering_pa",
    "optimal_pa",
    "water_pa",
    "corrected_to_water",
    "focal_peak_pa",
    "focus_distance_mm",
    "skull_hottest_pa",
    "skull_isppa_w_cm2",
    "skull_isppa_w_cm2_per_mpa2",
)

#: The volumes written on the CT's voxels: a column each (file ``<column>.nii.gz``).
VOLUMES = (
    "corrected_pa",
    "uncorrected_pa",
    "ray_steering_pa",
    "corrected_to_water",
    "focus_distance_mm",
    "skull_isppa_w_cm2_per_mpa2",
)

#: The most targets one envelope takes (a box of 5 mm spacing over a whole brain is about 10 000).
MAX_TARGETS = 100_000


@dataclass(frozen=True)
class EnvelopePoint:
    """One target of the envelope (pressures in Pa for the scenario's drive amplitude)."""

    target_mm: tuple[float, float, float]
    tissue: str
    corrected_pa: float
    """At the target, the reference steering minus the predicted aberration."""
    uncorrected_pa: float
    """At the target, the reference steering (straight rays through the head without bone)."""
    ray_steering_pa: float
    """At the target, the scenario's straight-ray steering through the CT's bone."""
    optimal_pa: float
    """The most any phases give at the target through the skull."""
    water_pa: float
    """The focus the array gives at the target in water, every element in phase."""
    focal_peak_pa: float | None
    """The corrected beam's focal peak near the target (None without a closed -6 dB region)."""
    focus_distance_mm: float | None
    """The distance of that peak from the target."""
    skull_hottest_pa: float | None
    """``|p|`` at the hottest place in the skull of the corrected beam (None: no bone on the grid)."""
    skull_isppa_w_cm2: float | None
    """I_SPPA there, ``p²/(2ρc)``."""

    @property
    def corrected_to_water(self) -> float:
        """The corrected focus over the focus in water."""
        return self.corrected_pa / self.water_pa if self.water_pa > 0 else math.nan

    @property
    def skull_isppa_w_cm2_per_mpa2(self) -> float | None:
        """The skull's I_SPPA per MPa² of corrected focal pressure at the target (W/cm² per MPa²)."""
        if self.skull_isppa_w_cm2 is None or self.corrected_pa <= 0:
            return None
        return self.skull_isppa_w_cm2 / (self.corrected_pa / 1e6) ** 2

    def to_row(self) -> dict[str, Any]:
        """The CSV row (:data:`COLUMNS`; an absent value is an empty cell)."""
        x, y, z = self.target_mm
        values = {
            "x_mm": x,
            "y_mm": y,
            "z_mm": z,
            "tissue": self.tissue,
            "corrected_to_water": self.corrected_to_water,
            "skull_isppa_w_cm2_per_mpa2": self.skull_isppa_w_cm2_per_mpa2,
        }
        row = {c: values[c] if c in values else getattr(self, c) for c in COLUMNS}
        return {k: "" if v is None else v for k, v in row.items()}

    @classmethod
    def from_row(cls, row: dict[str, str]) -> EnvelopePoint:
        """The point of a CSV row written by :meth:`to_row`."""
        number = lambda c: None if row[c] == "" else float(row[c])  # noqa: E731
        return cls(
            target_mm=(float(row["x_mm"]), float(row["y_mm"]), float(row["z_mm"])),
            tissue=row["tissue"],
            corrected_pa=float(row["corrected_pa"]),
            uncorrected_pa=float(row["uncorrected_pa"]),
            ray_steering_pa=float(row["ray_steering_pa"]),
            optimal_pa=float(row["optimal_pa"]),
            water_pa=float(row["water_pa"]),
            focal_peak_pa=number("focal_peak_pa"),
            focus_distance_mm=number("focus_distance_mm"),
            skull_hottest_pa=number("skull_hottest_pa"),
            skull_isppa_w_cm2=number("skull_isppa_w_cm2"),
        )


def box_targets(box_mm: ArrayLike, spacing_mm: float) -> NDArray[np.float64]:
    """The points of a box (x0, x1, y0, y1, z0, z1 in mm, transducer frame) ``spacing_mm`` apart
    along each axis, from its lowest corner (the last point along an axis at most its far face):
    shape (n, 3), x fastest. ``ValueError`` naming ``box_mm`` or ``spacing_mm``."""
    b = real_array(box_mm, "box_mm")
    if b.shape != (6,):
        raise ValueError(f"box_mm: must be six numbers (x0, x1, y0, y1, z0, z1 in mm), got {list(np.ravel(b))}")
    if not (np.isfinite(spacing_mm) and spacing_mm > 0):
        raise ValueError(f"spacing_mm: must be a positive number, got {spacing_mm}")
    lo, hi = b[0::2], b[1::2]
    if np.any(hi < lo):
        raise ValueError(f"box_mm: each axis must run from low to high (x0 <= x1, ...), got {list(b)}")
    counts = np.floor((hi - lo) / spacing_mm + 1e-9).astype(np.int64) + 1
    if int(np.prod(counts)) > MAX_TARGETS:
        raise ValueError(
            f"spacing_mm: {spacing_mm} mm gives {int(np.prod(counts))} targets in the box, more than {MAX_TARGETS}"
        )
    axes = [lo[a] + spacing_mm * np.arange(counts[a]) for a in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def target_tissues(scenario: Scenario, targets_mm: ArrayLike) -> list[str]:
    """The tissue class at each target as the skull's simulation names it (``skull``, ``scalp``, the
    CT's soft tissue by name, the coupling medium's), without building a plan; a target off the
    grid or outside the CT is refused (``ValueError`` naming it by index)."""
    targets = np.ascontiguousarray(np.atleast_2d(real_array(targets_mm, "targets_mm")))
    return _core.target_tissues(scenario.core, targets)


def evaluate(scenario: Scenario, targets_mm: Sequence[Sequence[float]], tissues: Sequence[str]) -> list[EnvelopePoint]:
    """The envelope's values at ``targets_mm`` from one plan of each head: the predictions, then one
    march of each target's corrected beam through the kept skull (its focal peak near the target,
    the hottest place in the skull)."""
    predictions = predict_targets(scenario, np.asarray(targets_mm, dtype=np.float64), keep_simulation=True)
    sim = predictions[0].kept_simulation()
    steering = sim.steering_phases_rad
    out = []
    for p, tissue in zip(predictions, tissues):
        metrics, hottest = sim.exposure_at(p.correction_rad(steering), p.target_mm)
        skull = hottest.get("skull")
        out.append(
            EnvelopePoint(
                target_mm=tuple(float(v) for v in p.target_mm),  # type: ignore[arg-type]
                tissue=tissue,
                corrected_pa=p.corrected_pa,
                uncorrected_pa=p.uncorrected_pa,
                ray_steering_pa=p.ray_steering_pa,
                optimal_pa=p.optimal_pa,
                water_pa=p.water_pa,
                focal_peak_pa=metrics.focal_peak_pa,
                focus_distance_mm=metrics.peak_to_target_mm,
                skull_hottest_pa=None if skull is None else skull.pressure_pa,
                skull_isppa_w_cm2=None if skull is None else skull.isppa_w_cm2,
            )
        )
    return out


def _evaluate_task(scenario: Scenario, targets_mm: list[list[float]], tissues: list[str]) -> list[dict[str, Any]]:
    """:func:`evaluate` on a worker, its points as CSV rows (plain values travel between processes)."""
    return [p.to_row() for p in evaluate(scenario, targets_mm, tissues)]


def _key(target_mm: Sequence[float]) -> tuple[float, float, float]:
    """A target as the CSV holds it, to a micrometre: how a resumed run recognises it."""
    x, y, z = (round(float(v), 3) for v in target_mm)
    return (x, y, z)


def read_points(path: Path) -> list[EnvelopePoint]:
    """The points of an ``envelope.csv`` (none when it does not exist); ``ValueError`` naming the
    file when it is not one."""
    if not path.exists():
        return []
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if tuple(reader.fieldnames or ()) != COLUMNS:
            raise ValueError(f"out: {path} is not an envelope's CSV (its header is not {','.join(COLUMNS)})")
        try:
            return [EnvelopePoint.from_row(r) for r in reader]
        except (TypeError, ValueError) as e:
            raise ValueError(f"out: {path}: a row is not an envelope point ({e})") from None


def _chunks(items: list[Any], size: int) -> Iterator[list[Any]]:
    for k in range(0, len(items), size):
        yield items[k : k + size]


def run_envelope(
    scenario: Scenario,
    targets_mm: ArrayLike,
    out: str | Path,
    task_size: int | None = None,
    scheduler: str | None = None,
    workers: int = 1,
    progress: Callable[[int, int], object] | None = None,
) -> tuple[list[EnvelopePoint], dict[str, int]]:
    """Evaluates the envelope at the targets in the brain among ``targets_mm`` (mm, transducer
    frame) and writes ``envelope.csv`` and ``scenario.toml`` (the scenario, for a resumed run to
    check) in ``out``. Targets in other tissue (skull, scalp, the coupling medium: the tissue
    classes of :func:`target_tissues`, the brain being the focus's) are counted, not evaluated.
    Targets already in ``out``'s CSV are skipped; each task's points are added to it as the task
    ends (the file rewritten whole, atomically). Tasks of ``task_size`` targets (default: the
    targets shared evenly among the workers, at most 25 a task, so that a stopped run keeps most of
    its work) run in this process (``workers`` 1, no ``scheduler``) or on dask.distributed: a
    local cluster of ``workers`` processes sharing this machine's cores, or the existing cluster at
    ``scheduler``. ``progress(done, total)`` is called per target evaluated. Returns every point
    of the CSV, in the order of ``targets_mm``, and the count of targets per tissue."""
    out = Path(out)
    targets = np.ascontiguousarray(np.atleast_2d(real_array(targets_mm, "targets_mm")), dtype=np.float64)
    if targets.ndim != 2 or targets.shape[1] != 3 or len(targets) == 0:
        raise ValueError(f"targets_mm: must be points (n, 3) in mm, got shape {targets.shape}")
    if len(targets) > MAX_TARGETS:
        raise ValueError(f"targets_mm: {len(targets)} targets, more than {MAX_TARGETS}")
    if task_size is not None and not 1 <= int(task_size) <= MAX_TARGETS:
        raise ValueError(f"task_size: must be at least 1, got {task_size}")
    if not 1 <= int(workers) <= 256:
        raise ValueError(f"workers: must be between 1 and 256, got {workers}")
    if scheduler is not None or workers > 1:
        distributed("envelope")  # before anything is computed: the extra's name if missing
    if scheduler is not None:
        refuse_unreachable(scheduler)
    focus = scenario.to_dict()["focus"]["position_mm"]
    classes = target_tissues(scenario, np.vstack([focus, targets]))
    brain, tissues = classes[0], classes[1:]
    counts: dict[str, int] = {}
    for t in tissues:
        counts[t] = counts.get(t, 0) + 1
    csv_path, toml_path = out / "envelope.csv", out / "scenario.toml"
    if out.exists() and not out.is_dir():
        raise ValueError(f"out: {out} is a file, not a folder")
    done = {_key(p.target_mm): p for p in read_points(csv_path)}
    if done and toml_path.exists() and toml_path.read_text(encoding="utf-8") != scenario.to_toml():
        raise ValueError(
            f"out: {out} holds the envelope of another scenario (its scenario.toml differs): choose another"
        )
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(toml_path, scenario.to_toml())
    todo = [
        (k, [float(v) for v in t], tissues[k])
        for k, t in enumerate(targets)
        if tissues[k] == brain and _key(t) not in done
    ]
    total, finished = len(todo), 0

    def add(rows: list[dict[str, Any]]) -> None:
        nonlocal finished
        for r in rows:
            p = EnvelopePoint.from_row({k: str(v) for k, v in r.items()})
            done[_key(p.target_mm)] = p
        ordered = [done[_key(t)] for t in targets if _key(t) in done]
        atomic_write_text(csv_path, csv_text([p.to_row() for p in ordered]) if ordered else ",".join(COLUMNS) + "\n")
        finished += len(rows)
        if progress is not None:
            progress(finished, total)

    if todo:
        parallel = scheduler is not None or workers > 1
        size = task_size or max(1, min(25, math.ceil(len(todo) / (workers if parallel else 1))))
        tasks = [([t for _, t, _ in chunk], [tissue for _, _, tissue in chunk]) for chunk in _chunks(todo, int(size))]
        if not parallel:
            for points, names in tasks:
                add(_evaluate_task(scenario, points, names))
        else:
            client, cluster = client_on(scheduler, workers, "envelope", threads_each(workers))
            try:
                futures = [
                    client.submit(_evaluate_task, scenario, points, names, pure=False) for points, names in tasks
                ]
                for f in distributed("envelope").as_completed(futures):
                    add(f.result())
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
    elif not csv_path.exists():
        atomic_write_text(csv_path, ",".join(COLUMNS) + "\n")
    return [done[_key(t)] for t in targets if _key(t) in done], counts


def reachable_pa(points: Sequence[EnvelopePoint], min_pressure_pa: float | None) -> float:
    """The focal pressure a target must reach to count as reachable: ``min_pressure_pa``, by
    default half the highest corrected focus of the envelope (-6 dB of its best target)."""
    return 0.5 * max(p.corrected_pa for p in points) if min_pressure_pa is None else float(min_pressure_pa)


def reachable(points: Sequence[EnvelopePoint], min_pressure_pa: float | None) -> list[bool]:
    """Per point, whether its corrected focus reaches :func:`reachable_pa`."""
    threshold = reachable_pa(points, min_pressure_pa)
    return [p.corrected_pa >= threshold for p in points]


def summary_line(points: Sequence[EnvelopePoint], counts: dict[str, int], min_pressure_pa: float | None) -> str:
    """One line: how much of the brain the envelope found reachable, and what it costs the skull."""
    total = sum(counts.values())
    others = ", ".join(
        f"{n} in {t}" for t, n in sorted(counts.items()) if n and t != (points[0].tissue if points else "")
    )
    if not points:
        return f"envelope: none of the {total} targets lies in the brain ({others})"
    ok = reachable(points, min_pressure_pa)
    threshold = reachable_pa(points, min_pressure_pa)
    rule = f"{threshold / 1e6:.3g} MPa" + (" (half the best target's)" if min_pressure_pa is None else "")
    ratio = np.median([p.corrected_to_water for p in points])
    skull = [v for v in (p.skull_isppa_w_cm2_per_mpa2 for p in points) if v is not None]
    cost = f"; skull I_SPPA {np.median(skull):.3g} W/cm² per MPa² of focus (median)" if skull else ""
    rest = f" ({others} not evaluated)" if others else ""
    return (
        f"envelope: {sum(ok)} of {len(points)} targets in the brain ({100 * sum(ok) / len(points):.0f} %) reach "
        f"{rule} with the corrected phases; corrected/water {ratio:.2f} (median){cost}{rest}"
    )


def cell_size_mm(targets_mm: NDArray[np.float64]) -> float:
    """The side of the cube each target fills in the volumes when no spacing is given: the median
    distance from a target to its nearest neighbour (1 mm for a single target)."""
    if len(targets_mm) < 2:
        return 1.0
    d = np.linalg.norm(targets_mm[:, None, :] - targets_mm[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


@dataclass(frozen=True)
class CtVolumes:
    """The envelope's quantities on the CT's voxels (:func:`on_ct_voxels`)."""

    volumes: dict[str, NDArray[np.float32]]
    """One per :data:`VOLUMES`, indexed [k, j, i]."""
    ras_affine: NDArray[np.float64]
    """The CT file's 4 x 4 affine, voxel (i, j, k) to RAS+ mm."""
    to_frame: NDArray[np.float64]
    """The 4 x 4 map from voxel (i, j, k) to the transducer frame (mm)."""


def on_ct_voxels(scenario: Scenario, points: Sequence[EnvelopePoint], cell_mm: float) -> CtVolumes:
    """Each of :data:`VOLUMES` on the CT's voxels (indexed [k, j, i]): every voxel whose centre lies
    in the cube of side ``cell_mm`` about a target (transducer frame; half-open, so that the cubes of
    a box's targets tile it without overlap) takes that target's value,
    the others 0 (an absent value is 0 too); with the CT's grid as the core reads it."""
    shape, ras, to_frame = _core.ct_voxel_grid(scenario.core)
    nk, nj, ni = shape
    volumes = {name: np.zeros(shape, dtype=np.float32) for name in VOLUMES}
    to_voxel = np.linalg.inv(to_frame)
    half = 0.5 * cell_mm
    for p in points:
        t = np.asarray(p.target_mm)
        corners = np.array(
            [
                [t[0] + sx * half, t[1] + sy * half, t[2] + sz * half, 1.0]
                for sx in (-1, 1)
                for sy in (-1, 1)
                for sz in (-1, 1)
            ]
        )
        idx = (to_voxel @ corners.T)[:3]
        lo = np.clip(np.floor(idx.min(axis=1)).astype(int), 0, [ni - 1, nj - 1, nk - 1])
        hi = np.clip(np.ceil(idx.max(axis=1)).astype(int), 0, [ni - 1, nj - 1, nk - 1])
        k, j, i = np.meshgrid(
            np.arange(lo[2], hi[2] + 1), np.arange(lo[1], hi[1] + 1), np.arange(lo[0], hi[0] + 1), indexing="ij"
        )
        at = to_frame @ np.stack([i.ravel(), j.ravel(), k.ravel(), np.ones(i.size)])
        offset = at[:3] - t[:, None]
        inside = np.all((offset >= -half - 1e-9) & (offset < half - 1e-9), axis=0)
        kk, jj, ii = k.ravel()[inside], j.ravel()[inside], i.ravel()[inside]
        row = p.to_row()
        for name in VOLUMES:
            v = row[name]
            volumes[name][kk, jj, ii] = 0.0 if v == "" or not np.isfinite(float(v)) else float(v)
    return CtVolumes(volumes, ras, to_frame)


def write_volumes(ct: CtVolumes, out: Path) -> list[str]:
    """The volumes of :func:`on_ct_voxels` written as ``<name>.nii.gz`` in ``out`` with the CT's own
    affine (they open on top of the CT in 3D Slicer); returns the file names."""
    names = []
    for name, values in ct.volumes.items():
        write_volume(out / f"{name}.nii.gz", values, ct.ras_affine, f"arfi envelope: {name}, on the CT's voxels, RAS")
        names.append(f"{name}.nii.gz")
    return names


def plot(scenario: Scenario, points: Sequence[EnvelopePoint], on_ct: CtVolumes, path: Path) -> None:
    """Three orthogonal slices of the CT through the envelope's best target, with the corrected
    focus over the focus in water (``on_ct``: :func:`on_ct_voxels` of ``points``) drawn over them."""
    import nibabel as nib

    ratio = on_ct.volumes["corrected_to_water"]
    shape = ratio.shape
    ct = scenario.to_dict()["ct"]["file"]
    ct_path = Path(ct) if Path(ct).is_absolute() else Path(scenario.base_dir or ".") / ct
    img = nib.load(str(ct_path))
    assert isinstance(img, nib.spatialimages.SpatialImage), "the core has read it as a NIfTI image"
    hu = np.asarray(img.get_fdata(dtype=np.float32)).transpose(2, 1, 0)  # [k, j, i]
    best = max(points, key=lambda p: p.corrected_to_water)
    i, j, k = np.rint((np.linalg.inv(on_ct.to_frame) @ [*best.target_mm, 1.0])[:3]).astype(int)
    k, j, i = (int(np.clip(v, 0, n - 1)) for v, n in zip((k, j, i), shape))
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4))
    vmax = max(float(ratio.max()), 1e-9)
    for ax, (title, ct_slice, r_slice) in zip(
        axes,
        [
            (f"voxel plane k = {k}", hu[k], ratio[k]),
            (f"voxel plane j = {j}", hu[:, j, :], ratio[:, j, :]),
            (f"voxel plane i = {i}", hu[:, :, i], ratio[:, :, i]),
        ],
    ):
        ax.imshow(ct_slice, cmap="gray", origin="lower", vmin=-200, vmax=1500)
        shown = np.ma.masked_where(r_slice <= 0, r_slice)
        im = ax.imshow(shown, cmap="viridis", origin="lower", vmin=0, vmax=vmax, alpha=0.8)
        ax.set(title=title, xticks=[], yticks=[])
    fig.colorbar(im, ax=axes[-1], label="corrected focus / focus in water", shrink=0.85)
    x, y, z = best.target_mm
    fig.suptitle(f"treatment envelope over the CT, through the best target ({x:.0f}, {y:.0f}, {z:.0f}) mm")
    save_figure(fig, path)
