"""``arfi field``: the complex pressure on a plane and along the beam axis."""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from arfi._core import MemoryLimitError
from arfi.analysis.focal import metrics_text
from arfi.analysis.safety import ISPPA_LIMIT_W_CM2, MI_LIMIT, check_limit, exceeded, summary
from arfi.cli.common import add_common, add_report, finish, load_scenario, read_checked_phases
from arfi.io.files import npz_path, volume_path, write_npz
from arfi.io.volume import IntensityVolume, PressureVolume
from arfi.simulation import Field, Simulation
from arfi.validation.fdtd import ENGINE_VERSION, FdtdOptions, FdtdResult


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "field",
        help="complex pressure on a plane and the beam axis (.npz)",
        description="Simulate the beam (HAS) and write the complex pressure amplitude (Pa) on the "
        "plane z = Z and along the beam's axis (the line from the array's centre through the target). Prints the focal "
        "peak near the target on the plane, along the axis and in 3-D (its -6 dB extents and volume, I_SPPA and "
        "mechanical index there), the hottest place of each tissue (skull, scalp, brain, water) over the whole grid, "
        "and names any place on the plane or axis hotter than the focus. --volume writes |p| in 3-D as NIfTI for "
        "overlay, --intensity-volume the intensity.",
        epilog="example: arfi field --z-mm 85 --out focus.npz",
    )
    add_common(p)
    p.add_argument(
        "--phases", metavar="P", help="phases (rad) added to the steering: .npy or text, one per element or group"
    )
    p.add_argument(
        "--correction",
        metavar="P",
        help="an estimate's or a prediction's phases_rad (.npy or text), "
        "subtracted from the steering: the corrected beam (with --phases: both)",
    )
    p.add_argument("--z-mm", type=float, dest="z_mm", help="plane z in mm (default: the focus)")
    p.add_argument(
        "--out",
        required=True,
        metavar="F.npz",
        help="write the complex pressure (Pa) on the plane and along the axis, with their coordinates (mm)",
    )
    p.add_argument(
        "--mi-limit",
        type=float,
        default=MI_LIMIT,
        metavar="MI",
        help=f"mechanical index flagged when exceeded at the focal peak or at the hottest place of a tissue "
        f"(default {MI_LIMIT:g})",
    )
    p.add_argument(
        "--isppa-limit-w-cm2",
        type=float,
        default=ISPPA_LIMIT_W_CM2,
        metavar="I",
        help=f"I_SPPA (W/cm²) flagged when exceeded at the focal peak or at the hottest place of a tissue "
        f"(default {ISPPA_LIMIT_W_CM2:g})",
    )
    p.add_argument(
        "--volume",
        metavar="F.nii.gz",
        help="also write |p| (Pa) in 3-D as NIfTI (.nii or .nii.gz) on the "
        "simulation grid, its affine in the transducer frame (mm)",
    )
    p.add_argument(
        "--volume-ct",
        metavar="F.nii.gz",
        dest="volume_ct",
        help="also write |p| (Pa) resampled into the "
        "voxel grid of the scenario's [ct], with the CT's own affine: it opens on top of the CT",
    )
    p.add_argument(
        "--intensity-volume",
        metavar="F.nii.gz",
        dest="intensity_volume",
        help="also write the intensity "
        "I = |p|²/(2ρc) (W/cm², pulse average; ρ and c the medium's at each voxel; its maximum is I_SPPA) in 3-D as "
        "NIfTI on the simulation grid",
    )
    p.add_argument(
        "--intensity-volume-ct",
        metavar="F.nii.gz",
        dest="intensity_volume_ct",
        help="also write the "
        "intensity I = |p|²/(2ρc) (W/cm²) on the voxel grid of the scenario's [ct] (|p| resampled there, ρ and c of "
        "each CT voxel)",
    )
    p.add_argument(
        "--volume-box-mm",
        type=float,
        nargs=6,
        metavar=("X0", "X1", "Y0", "Y1", "Z0", "Z1"),
        dest="volume_box_mm",
        help="crop the --volume and --intensity-volume files to this box (mm, transducer frame)",
    )
    p.add_argument(
        "--engine",
        choices=("has", "fdtd"),
        default="has",
        help="has (default): the hybrid angular spectrum march, seconds; fdtd: the full-wave viscoelastic engine "
        "BabelViscoFDTD (install with pip install 'arfi[fullwave]'), minutes to hours, fed the march's own source "
        "plane and the same medium (with shear where the scenario gives it); its field is read as the march's is (same "
        "outputs and JSON keys) and printed beside the march's. The time it will take is printed before it starts",
    )
    p.add_argument(
        "--fdtd-points-per-wavelength",
        type=float,
        default=FdtdOptions.points_per_wavelength,
        metavar="N",
        dest="fdtd_ppw",
        help="--engine fdtd: voxels per shortest wavelength present (default "
        f"{FdtdOptions.points_per_wavelength:g}; the time goes as N^4: 6 is about 3x faster and reads a cortical cap's "
        "focal pressure about 9 %% high)",
    )
    add_report(
        p,
        "PNG figures (|p| in MPa on the plane in mm, the axis profile, and the beam on the three planes through the "
        "target over the CT in HU or the sound speed, with the focal -6 dB contour)",
    )
    p.set_defaults(run=run)


@dataclass(frozen=True)
class VolumeOutput:
    """One volume file ``arfi field`` can write: its argument (``key``, ``flag``), what it holds
    (``intensity``: I = |p|²/(2ρc), else |p|; ``quantity`` as printed, ``max_key`` its maximum in
    the JSON) and where (``in_ct``: the CT's voxels, else the simulation grid cropped to
    ``--volume-box-mm``)."""

    key: str
    flag: str
    intensity: bool
    in_ct: bool

    @property
    def quantity(self) -> str:
        return "intensity in 3-D (W/cm²)" if self.intensity else "|p| in 3-D (Pa)"

    @property
    def max_key(self) -> str:
        return "max_w_cm2" if self.intensity else "max_pa"

    def make(self, f: Field, box_mm: list[float] | None) -> PressureVolume | IntensityVolume:
        """The volume of the field ``f``."""
        box = None if self.in_ct else box_mm
        return f.intensity_volume(box, in_ct=self.in_ct) if self.intensity else f.pressure_volume(box, in_ct=self.in_ct)

    @staticmethod
    def values(v: PressureVolume | IntensityVolume) -> NDArray[np.float32]:
        """The volume's array."""
        return v.pressure_pa if isinstance(v, PressureVolume) else v.intensity_w_cm2


VOLUMES = (
    VolumeOutput("volume", "--volume", intensity=False, in_ct=False),
    VolumeOutput("volume_ct", "--volume-ct", intensity=False, in_ct=True),
    VolumeOutput("intensity_volume", "--intensity-volume", intensity=True, in_ct=False),
    VolumeOutput("intensity_volume_ct", "--intensity-volume-ct", intensity=True, in_ct=True),
)


def hottest_line(hottest: dict[str, Any]) -> str:
    """The hottest place of each tissue class over the grid, hottest first (``Field.hottest``)."""
    parts = [
        f"{tissue} {h.pressure_pa / 1e6:.3f} MPa at ({', '.join(f'{v:.1f}' for v in h.position_mm)}) mm, "
        f"MI {h.mechanical_index:.2f}"
        for tissue, h in hottest.items()
    ]
    return "field: hottest in each tissue: " + "; ".join(parts)


def focus_lines(sim: Simulation, f: Field, focus: Any, out: str) -> tuple[list[str], dict[str, str]]:
    """The printed summary: the focal peak near the target on the plane and along the beam's axis,
    any hotter place named by its tissue (returned as the JSON's ``*_hottest_tissue``), and the
    propagation model. ``focus`` is ``f.focus()``."""
    t = tuple(focus.target_mm)
    lines = [
        f"field: plane z = {f.z_mm:.2f} mm: focal peak {focus.plane_peak_pa / 1e6:.3f} MPa at "
        f"({focus.plane_peak_x_mm:.2f}, {focus.plane_peak_y_mm:.2f}) mm, {focus.plane_peak_to_axis_mm:.2f} mm "
        f"from the beam's axis; along the axis to the target ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm: "
        f"{focus.axis_peak_pa / 1e6:.3f} MPa at z = {focus.axis_peak_z_mm:.2f} mm -> {out}"
    ]
    lines.append(f"field: {metrics_text(focus.focal_metrics)}")
    if focus.hottest is not None:
        lines.append(hottest_line(focus.hottest))
    tissues = {}
    for where, key in (("on the plane", "plane"), ("on the axis", "axis")):
        pa, p = getattr(focus, f"{key}_hottest_pa"), getattr(focus, f"{key}_hottest_mm")
        if pa is not None:
            point = [*p, f.z_mm] if len(p) == 2 else list(p)
            tissue = sim.tissue_classes(point)[0]
            tissues[f"{key}_hottest_tissue"] = tissue
            lines.append(
                f"field: hottest {where}: {tissue}, {pa / 1e6:.3f} MPa at ({point[0]:.1f}, "
                f"{point[1]:.1f}, {point[2]:.1f}) mm (not the focus)"
            )
    lines.append(f"field: {sim.propagation_summary()}")
    return lines, tissues


def fdtd_line(r: FdtdResult, focus: Any, march: Any) -> str:
    """The full-wave run in one line, its focal peak beside the march's (``focus`` and ``march``:
    the two fields' focal metrics)."""
    nx, ny, nz = r.plan.shape
    text = (
        f"field: computed by BabelViscoFDTD (full wave, {r.plan.h_m * 1e3:.3f} mm voxels, {nx} x {ny} x {nz}, "
        f"{r.materials} materials) in {r.seconds:.0f} s, steady to {100 * r.steady_change:.2f} %"
    )
    if focus.focal_peak_pa and march.focal_peak_pa:
        fp, mp = focus.focal_peak_mm, march.focal_peak_mm
        gap = sum((a - b) ** 2 for a, b in zip(fp, mp)) ** 0.5
        text += (
            f"; the march: {march.focal_peak_pa / 1e6:.3f} MPa at ({', '.join(f'{v:.1f}' for v in mp)}) mm, "
            f"{100 * (march.focal_peak_pa / focus.focal_peak_pa - 1):+.1f} % and {gap:.2f} mm from the full "
            "wave's"
        )
    return text


def fdtd_json(r: FdtdResult, march: Any) -> dict[str, Any]:
    """The full-wave run's JSON: its grid, time step, steadiness and the march's focal metrics."""
    p = r.plan
    return {
        "engine": "BabelViscoFDTD",
        "engine_version": ENGINE_VERSION,
        "voxel_mm": p.h_m * 1e3,
        "shape_xyz": list(p.shape),
        "time_step_s": p.dt_s,
        "steps": p.steps,
        "materials": r.materials,
        "steady_change": r.steady_change,
        "seconds": r.seconds,
        "march_focal_peak_pa": march.focal_peak_pa,
        "march_focal_peak_mm": march.focal_peak_mm,
    }


def run(args: argparse.Namespace) -> int:
    npz_path(args.out)  # before the simulation
    asked = [v for v in VOLUMES if getattr(args, v.key) is not None]
    if args.volume_box_mm is not None and not any(not v.in_ct for v in asked):
        raise ValueError("--volume-box-mm: crops the --volume or --intensity-volume, neither of which is asked for")
    for v in asked:
        volume_path(getattr(args, v.key), v.flag)
    limits = check_limit(args.mi_limit, "--mi-limit"), check_limit(args.isppa_limit_w_cm2, "--isppa-limit-w-cm2")
    fdtd_options = None
    if args.engine == "fdtd":
        from arfi.validation.fdtd import require_engine

        require_engine()
        try:
            fdtd_options = FdtdOptions(points_per_wavelength=args.fdtd_ppw)
        except ValueError as e:
            raise ValueError(f"--fdtd-points-per-wavelength: {str(e).split(': ', 1)[1]}") from None
    t = time.perf_counter()
    scenario = load_scenario(args)
    outline = scenario.outline()  # the inputs checked before the simulation is built
    phases = read_checked_phases(outline, args.phases, "--phases")
    correction = read_checked_phases(outline, args.correction, "--correction")
    sim = Simulation(scenario)
    if correction is not None:
        added = sim.element_phases(phases, "--phases") if phases is not None else np.zeros(sim.n_elements)
        phases = added - sim.element_phases(correction, "--correction")
    for v in asked:
        if v.in_ct and not sim.has_ct:
            raise ValueError(
                f"{v.flag}: needs a scenario with a [ct] section (the CT is the grid it is resampled into)"
            )
    skipped = None
    fdtd: FdtdResult | None = None
    march = None
    try:
        f = sim.field(phases, args.z_mm, volume=True)
    except MemoryLimitError as e:  # the whole grid's |p| does not fit: without volume outputs, the field alone
        if asked or args.report or fdtd_options is not None:
            raise
        f, skipped = sim.field(phases, args.z_mm), str(e)
    if fdtd_options is not None:
        from arfi.validation.fdtd import run as run_fdtd

        march = f
        fdtd = run_fdtd(sim, march, phases, fdtd_options, progress=lambda m: print(m, flush=True))
        f = sim.field_from_volume(fdtd.plane, fdtd.z_mm, fdtd.axis, fdtd.magnitude)
    # The volumes (from the field's own march) before anything is written: a box outside the
    # grid leaves no file behind.
    volumes = [(v, v.make(f, args.volume_box_mm)) for v in asked]
    write_npz(
        args.out,
        {
            "pressure": f.pressure,
            "x_mm": f.x_mm,
            "y_mm": f.y_mm,
            "z_mm": np.float64(f.z_mm),
            "axis_pressure": f.axis_pressure,
            "axis_z_mm": f.axis_z_mm,
            "axis_x_mm": f.axis_x_mm,
            "axis_y_mm": f.axis_y_mm,
            "surface_pressure_pa": np.float64(f.surface_pressure_pa),
        },
    )
    focus = f.focus()
    lines, tissues = focus_lines(sim, f, focus, args.out)
    summary_values = {**focus.to_dict(), **tissues}
    if skipped:
        lines.insert(2, f"field: no hottest place per tissue: {skipped}")
    written = {}
    for v, made in volumes:
        path = getattr(args, v.key)
        made.to_nifti(path)
        values = v.values(made)
        nk, nj, ni = values.shape
        frame = "the CT's voxels and affine" if v.in_ct else "transducer frame"
        lines.insert(-1, f"field: {v.quantity} on {ni} x {nj} x {nk} voxels, {frame} -> {path}")
        written[v.key] = {"path": path, "shape_ijk": [ni, nj, nk], v.max_key: float(values.max())}
        if not v.in_ct:
            written[v.key]["box_mm"] = args.volume_box_mm
    engine_line = None if fdtd is None or march is None else fdtd_line(fdtd, f.focal_metrics, march.focal_metrics)
    if engine_line is not None:
        lines.insert(-1, engine_line)
    rows = exceeded(focus, *limits)
    if rows:
        lines.insert(-1, f"field: {summary(rows)}")
    summary_values["safety"] = {
        "mechanical_index_limit": limits[0],
        "isppa_limit_w_cm2": limits[1],
        "exceeded": [r.to_dict() for r in rows],
    }
    print("\n".join(lines))
    if args.report:
        from arfi.reports.html import field_report

        safety = (
            summary(rows) if rows else f"within the safety lines (MI <= {limits[0]:g}, I_SPPA <= {limits[1]:g} W/cm²)"
        )
        engine = sim.propagation_summary() if engine_line is None else engine_line[len("field: ") :]
        page = field_report(
            args.report, sim, f, {"out": args.out, **summary_values, "safety": safety, "propagation": engine}, phases
        )
        print(f"field: report -> {page}")
    finish(
        args,
        {
            "out": args.out,
            "z_mm": f.z_mm,
            "surface_pressure_pa": f.surface_pressure_pa,
            **summary_values,
            **{v.key: written.get(v.key) for v in VOLUMES},
            "propagation": sim.propagation.to_dict(),
            "engine": args.engine,
            "fdtd": None if fdtd is None or march is None else fdtd_json(fdtd, march.focal_metrics),
            "seconds": time.perf_counter() - t,
        },
    )
    return 0
