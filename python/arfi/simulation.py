"""Simulation of fields and MR-ARFI images for one scenario."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi import _core
from arfi._core import Diagnosis
from arfi.checks import as_count, as_image, as_number, as_phases, as_point_mm, real_array
from arfi.cost import CostModel
from arfi.estimation import Calibration, Estimate
from arfi.io.volume import PressureVolume
from arfi.progress import callback
from arfi.scenario import Scenario

#: One MR-ARFI image (2-D, or a list of rows) or several (a sequence of 2-D arrays, or a 3-D stack).
Images = ArrayLike | Sequence[ArrayLike]
#: Known added phases: one vector for one image, or one entry (a vector or None) per image; None: none.
Known = ArrayLike | Sequence[ArrayLike | None] | None


def images_and_known(
    images: Images, known: Known
) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64] | None]]:
    """The images as 2-D float64 arrays and their known phases (one entry, or None, per image;
    a single image also takes its vector in a one-entry list). The core checks that the counts
    agree."""
    single = (isinstance(images, np.ndarray) and images.ndim != 3) or (
        isinstance(images, (list, tuple))
        and len(images) > 0
        and not hasattr(images[0], "shape")
        and np.ndim(images[0]) == 1
    )
    several = cast(Sequence[ArrayLike], images)
    imgs = (
        [as_image(cast(ArrayLike, images), "images[0]")]
        if single
        else [as_image(m, f"images[{i}]") for i, m in enumerate(several)]
    )
    if not imgs:
        raise ValueError("images: need at least one image")
    if known is None:
        return imgs, [None] * len(imgs)
    entries = cast(Sequence[ArrayLike | None], known)
    if single and isinstance(known, (list, tuple)) and len(known) == 1 and (known[0] is None or np.ndim(known[0]) == 1):
        return imgs, [as_phases(known[0], "known[0]")]
    if single:
        return imgs, [as_phases(cast(ArrayLike, known), "known")]
    return imgs, [as_phases(k, f"known[{i}]") for i, k in enumerate(entries)]


def _group_map(groups: int | ArrayLike, n_elements: int) -> NDArray[np.int64]:
    """``G`` → contiguous groups ``e * G // n`` (the core's rule); an array → itself (validated in
    the core)."""
    if isinstance(groups, (int, np.integer)):
        if groups < 1:  # the core takes a count; a negative one is named here, not overflowed
            raise ValueError(f"groups: must be between 1 and {n_elements}, got {int(groups)}")
        return _core.contiguous_groups(n_elements, int(groups))
    a = np.asarray(groups)
    if a.ndim != 1 or a.dtype.kind not in "iu":
        raise ValueError("groups: must be an integer count or a 1-D integer array (element -> group)")
    return a.astype(np.int64)


# The beam results are the core's types (arrays in Pa and mm; ``Field.focus()`` computed there).
Field = _core.Field
Section = _core.Section
FocalMetrics = _core.FocalMetrics
FieldFocus = _core.FieldFocus
HottestPlace = _core.HottestPlace
# What a simulation's plan is made of (typed; ``to_dict()`` for JSON).
Grid = _core.Grid
Propagation = _core.Propagation
Reverberation = _core.Reverberation


class Simulation:
    """A scenario made ready to simulate: grid chosen, beam steered to the focus, HAS plan built.

    Phases passed to the methods are *added* to the steering, one per element or one per group
    (rad; a positive phase ``phi`` delays that element's emission by ``phi / (2*pi*f)``).
    """

    def __init__(
        self,
        scenario: Scenario | None = None,
        groups: int | ArrayLike | None = None,
        *,
        source: _core.CoreSourceModel | None = None,
    ):
        """``source``: another simulation's :meth:`source_model`, reused where this scenario has
        the same array, grid, acoustic power and coupling medium (its projected elements are
        then not projected again: seconds for a 1024-element hemisphere); otherwise ignored.
        The simulation is the same either way."""
        self.scenario = scenario if scenario is not None else Scenario.default()
        if source is not None and not isinstance(source, _core.CoreSourceModel):
            raise ValueError(f"source: must be a Simulation.source_model(), got {type(source).__name__}")
        self._core = _core.CoreSimulation(self.scenario.core, source)
        if groups is not None:
            self._core = self._core.with_groups(_group_map(groups, self.n_elements))

    def source_model(self) -> _core.CoreSourceModel:
        """The array projected onto the grid's first plane, to pass as ``source`` to another
        :class:`Simulation` of the same array (e.g. the head with and without its bone); it keeps
        the projections alive after this simulation is dropped."""
        return self._core.source_model()

    @classmethod
    def _wrap(cls, scenario: Scenario, core: Any) -> Simulation:
        s = cls.__new__(cls)
        s.scenario = scenario
        s._core = core
        return s

    def with_calibration(self, broadening_width_mm: float, amplitude: float) -> Simulation:
        """The same simulation with a fitted broadening width (mm) and amplitude; the HAS plan
        is shared, so this is cheap."""
        return self._wrap(self.scenario, self._core.with_calibration(float(broadening_width_mm), float(amplitude)))

    def calibrated(self, calibration: Calibration) -> Simulation:
        """The same simulation with ``calibration``'s width and amplitude (from :meth:`calibrate`
        or :meth:`Calibration.load`), once checked that it was fitted for this scenario and
        frequency where it records them (``ValueError`` otherwise)."""
        if not isinstance(calibration, Calibration):
            raise ValueError(f"calibration: must be an arfi.Calibration, got {type(calibration).__name__}")
        return self._wrap(self.scenario, self._core.calibrated(calibration))

    def with_element_amplitudes(self, amplitudes: ArrayLike) -> Simulation:
        """The same simulation with each element driven at ``amplitudes`` (one per element, >= 0)
        times the scenario's amplitude: e.g. a CT prediction's ``transmission``, so that a model of
        the head without its skull loses at each element what the skull loses there. The HAS plan
        and the calibration are kept; the steered source is projected again (seconds for a
        hemisphere)."""
        a = as_phases(amplitudes, "amplitudes")
        return self._wrap(self.scenario, self._core.with_element_amplitudes(a))

    @property
    def element_amplitudes(self) -> NDArray[np.float64]:
        """Each element's drive amplitude relative to the scenario's (1 unless set by
        :meth:`with_element_amplitudes`)."""
        return np.asarray(self._core.element_amplitudes)

    def with_groups(self, groups: int | ArrayLike) -> Simulation:
        """The same simulation with ``groups`` contiguous groups (or an element → group array)."""
        return self._wrap(self.scenario, self._core.with_groups(_group_map(groups, self.n_elements)))

    @property
    def n_elements(self) -> int:
        return int(self._core.n_elements)

    @property
    def frequency_hz(self) -> float:
        """The drive frequency (Hz)."""
        return float(self._core.frequency_hz)

    @property
    def n_groups(self) -> int:
        return int(self._core.n_groups)

    @property
    def n_default_groups(self) -> int:
        """Number of the array's default groups (16 on the paper's quadrant array: ``group = element // 64``,
        a 4-row strip of one quadrant); known phases may also be given per default group to a
        per-element estimate."""
        return int(self._core.n_default_groups)

    @property
    def groups(self) -> NDArray[np.int64]:
        """Element → group index."""
        return self._core.groups

    @property
    def steering_phases_rad(self) -> NDArray[np.float64]:
        return self._core.steering_phases_rad

    @property
    def element_positions_mm(self) -> NDArray[np.float64]:
        """Element centres (mm), shape (n_elements, 3)."""
        return self._core.element_positions_mm

    @property
    def focus_mm(self) -> NDArray[np.float64]:
        return self._core.focus_mm

    @property
    def amplitude(self) -> float:
        """Scale from broadened force density (N/m³) to ARFI phase (rad). ``ValueError`` says why a
        scenario has none: no radiation force in the MR slice (e.g. lossless water) and no
        ``[arfi] amplitude_rad_m3_per_n`` given. Fields need none."""
        return float(self._core.amplitude)

    @property
    def propagation(self) -> Propagation:
        """How changes of medium are crossed (:class:`Propagation`: ``interfaces``, ``screen``,
        ``reflections``, ``shear``, ``reverberation``)."""
        return self._core.propagation

    @property
    def has_ct(self) -> bool:
        """Whether the medium holds a CT (a ``[ct]`` scenario): what ``pressure_volume(in_ct=True)`` needs."""
        return self._core.has_ct

    def propagation_summary(self) -> str:
        """:attr:`propagation` in one sentence, for reports."""
        p = self.propagation
        text = (
            "angle-dependent interface transmission (plane-wave coefficients on the angular spectrum)"
            if p.interfaces == "angular"
            else "normal-incidence interface transmission (T = 2·Z2/(Z1+Z2) per pixel)"
        )
        if p.screen == "vertical":
            text += ", vertical phase screen (original HAS)"
        r = p.reverberation
        if r is not None:
            text += (
                f", reverberation between z = {r.first_interface_z_mm:.1f} and {r.last_interface_z_mm:.1f} mm "
                f"({r.round_trips} round trips)"
            )
        text += ", reflections towards the source added" if p.reflections else ""
        ct_shear = bool(((self.scenario.to_dict().get("ct") or {}).get("bone_shear_sound_speed_m_s") or 0) > 0)
        if p.shear:
            text += (
                "; shear waves carried through solids whose faces lie on the march's planes (material regions, and a "
                "CT's faces between layers) or on planar walls tilted against them (a CT's), with mode conversion at "
                "each such face"
            )
        if self.has_shear and (ct_shear or not p.shear):
            text += (
                "; compressional waves only through a CT's other faces (curved, or on planes that also hold other "
                "jumps), a voxel map's other faces and faces crossed pixel by pixel: the shear speeds the scenario "
                "gives there are not carried by the march (arfi field --engine fdtd carries them)"
            )
        return text

    @property
    def has_shear(self) -> bool:
        """Whether the scenario gives a solid a shear wave (a material's ``shear_sound_speed_m_s``
        or ``[ct] bone_shear_sound_speed_m_s`` above 0). The march carries it where the solid's faces
        lie on its planes (a CT's where they lie between layers) or on planar walls tilted against
        them (``propagation.shear``); the
        full-wave engine everywhere."""
        d = self.scenario.to_dict()
        ct = d.get("ct") or {}
        return bool(
            (ct.get("bone_shear_sound_speed_m_s") or 0) > 0
            or any((m.get("shear_sound_speed_m_s") or 0) > 0 for m in d.get("material") or [])
        )

    @property
    def noise_rad(self) -> float:
        return float(self._core.noise_rad)

    @property
    def grid(self) -> Grid:
        """The grid the march runs on (:class:`Grid`: ``nx``, ``ny``, ``nz``, ``dx_mm``, ``dy_mm``,
        ``dz_mm``, ``z0_mm``)."""
        return self._core.grid

    @property
    def mr_affine_mm(self) -> NDArray[np.float64]:
        """4x4 affine from NIfTI voxel indices to the transducer frame (mm)."""
        return self._core.mr_affine_mm

    @property
    def mr_plane(self) -> str:
        """The MR image plane: ``"xy"``, ``"xz"`` or ``"yz"`` (image axes u, v in that order)."""
        return str(self._core.mr_plane)

    @property
    def mr_volume_shape(self) -> tuple[int, int, int]:
        a, b, c = self._core.mr_volume_shape
        return int(a), int(b), int(c)

    def field(self, phases: ArrayLike | None = None, z_mm: float | None = None, volume: bool = False) -> Field:
        """Pressure on the plane nearest ``z_mm`` (default: the focus) and along the axis, with
        the focal metrics in 3-D. With ``volume``, the same march also keeps |p| on the whole grid
        (8 bytes a voxel while marching, 4 kept): ``Field.hottest`` (each tissue's hottest
        place), ``Field.pressure_volume``, ``Field.intensity_volume`` and ``Field.to_nifti``, as
        ``arfi field`` reports and writes them."""
        return self._core.field(as_phases(phases), None if z_mm is None else as_number(z_mm, "z_mm"), bool(volume))

    def field_from_volume(self, plane: ArrayLike, z_mm: float, axis: ArrayLike, magnitude: ArrayLike) -> Field:
        """The :class:`Field` of pressure computed by another engine on this simulation's grid
        (``arfi field --engine fdtd``): ``plane`` (complex Pa, (ny, nx)) on the grid plane nearest
        ``z_mm``, ``axis`` (complex Pa, one per grid plane, on the beam's axis) and ``magnitude``
        (``|p|`` in Pa, (nz, ny, nx)); its focal metrics and hottest places are found exactly as
        for a march. Wrong sizes or values that are not finite: ValueError naming the array."""
        return self._core.field_from_volume(
            np.ascontiguousarray(plane, dtype=np.complex128),
            float(z_mm),
            np.ascontiguousarray(axis, dtype=np.complex128),
            np.ascontiguousarray(magnitude, dtype=np.float32),
        )

    def focal_metrics(self, phases: ArrayLike | None = None, target_mm: ArrayLike | None = None) -> FocalMetrics:
        """The focal metrics in 3-D of the beam driven with ``phases`` (as for :meth:`field`)
        around ``target_mm`` (mm, transducer frame; default: the focus), from one march that
        records only a box around it: a :class:`FocalMetrics` (``target_mm``, ``focal_peak_mm``,
        ``focal_peak_pa``, ``peak_to_target_mm``, ``fwhm_6db_mm`` [along, across],
        ``fwhm_6db_across_mm``, ``fwhm_3db_mm``, ``focal_volume_6db_mm3``, ``isppa_w_cm2``,
        ``mechanical_index`` and ``focal_tissue``, the JSON's keys by ``to_dict()``; each but the
        target None when no closed -6 dB region lies around the target). Cheaper than
        :meth:`field` when only the metrics are wanted, and for a target other than the focus
        (e.g. a prediction's)."""
        target = None if target_mm is None else as_point_mm(target_mm, "target_mm")
        return self._core.focal_metrics(as_phases(phases), target)

    def exposure_at(
        self, phases: ArrayLike | None, target_mm: ArrayLike
    ) -> tuple[FocalMetrics, dict[str, HottestPlace]]:
        """The focal metrics around ``target_mm`` (mm, transducer frame; as :meth:`focal_metrics`) and
        the hottest place of each tissue class over the whole grid (``{tissue: HottestPlace}``,
        hottest first, as ``Field.hottest``) of the beam driven with ``phases`` (as for
        :meth:`field`), from one march that keeps ``|p|`` on the whole grid (8 bytes a voxel while
        marching): what a focus at the target costs the skull."""
        return self._core.exposure_at(as_phases(phases), as_point_mm(target_mm, "target_mm"))

    def pressure_volume(
        self, phases: ArrayLike | None = None, box_mm: ArrayLike | None = None, in_ct: bool = False
    ) -> PressureVolume:
        """``|p|`` (Pa) of the beam in 3-D from one march, on the whole grid or on the box
        ``box_mm`` (x0, x1, y0, y1, z0, z1 in mm, transducer frame): a :class:`PressureVolume`
        (``to_nifti(path)`` writes it). With ``in_ct`` (a ``[ct]`` scenario), resampled into the
        CT's voxel grid with the CT's own RAS affine, to open on top of the CT. ``phases`` as for
        :meth:`field`."""
        if in_ct:
            if box_mm is not None:
                raise ValueError("box_mm: crops the volume on the simulation grid; in_ct takes the CT's own voxel grid")
            pressure, affine = self._core.pressure_volume_in_ct(as_phases(phases))
            return PressureVolume(pressure_pa=pressure, affine_mm=affine, frame="ct")
        box = None
        if box_mm is not None:
            b = real_array(box_mm, "box_mm")
            if b.shape != (6,):
                raise ValueError(f"box_mm: must be six numbers (x0, x1, y0, y1, z0, z1 in mm), got {box_mm!r}")
            box = [float(v) for v in b]
        pressure, affine = self._core.pressure_volume(as_phases(phases), box)
        return PressureVolume(pressure_pa=pressure, affine_mm=affine)

    def tissue_at(self, points_mm: ArrayLike) -> list[str]:
        """The tissue at each point (mm, transducer frame, shape (n, 3) or (3,)): ``"bone"`` or
        the CT's soft-tissue material where a CT holds tissue, else the material's name."""
        p = np.atleast_2d(np.asarray(points_mm, dtype=np.float64))
        return self._core.tissue_at(np.ascontiguousarray(p))

    def tissue_classes(self, points_mm: ArrayLike) -> list[str]:
        """The tissue class of each point (mm, transducer frame, shape (n, 3) or (3,)) as the
        hottest places (``Field.hottest``) name it: ``"skull"`` for bone, ``"scalp"`` for the
        target's own tissue whose straight path to the target crosses bone, else the tissue's
        name (``"brain"``, ``"water"`` …); each point by the grid sample nearest it (a point off
        the grid: ValueError naming ``points_mm``)."""
        p = np.atleast_2d(np.asarray(points_mm, dtype=np.float64))
        return self._core.tissue_classes(np.ascontiguousarray(p))

    def properties_at(self, points_mm: ArrayLike) -> dict[str, NDArray[np.float64]]:
        """The medium at each point (mm, transducer frame, shape (n, 3) or (3,)): arrays
        ``sound_speed_m_s`` and ``density_kg_m3`` (the CT's conversion where a CT holds tissue),
        ``attenuation_np_m`` (amplitude, at the scenario's frequency), ``shear_sound_speed_m_s``
        and ``shear_attenuation_np_m`` (0 in a fluid) and ``hu`` (the CT's value, NaN outside the
        CT or without one)."""
        p = np.atleast_2d(np.asarray(points_mm, dtype=np.float64))
        return self._core.properties_at(np.ascontiguousarray(p))

    def section(
        self,
        phases: ArrayLike | Sequence[ArrayLike] | None = None,
        y_mm: float | None = None,
        target_mm: ArrayLike | None = None,
    ) -> Section:
        """Pressure on the x–z plane nearest ``y_mm`` (default: the focus's) with the sound speed
        there. ``phases``: one drive (phases added to the steering, per element or per group;
        None: the steering alone) or a sequence (None entries: the steering alone) or 2-D array of
        drives, marched in one batch. With ``target_mm`` (mm, transducer frame), the same march
        also gives each drive's focal metrics around it as :meth:`focal_metrics` does
        (``Section.focal_metrics``, one :class:`FocalMetrics` per drive)."""
        none = np.zeros(0)
        if phases is None:
            drives = [none]
        elif (
            isinstance(phases, (Sequence, np.ndarray))
            and len(phases) > 0
            and all(p is None or np.ndim(p) == 1 for p in phases)
        ):
            drives = [none if p is None else as_phases(p, f"phases[{k}]") for k, p in enumerate(phases)]
        else:
            drives = [as_phases(cast(ArrayLike, phases))]
        y = None if y_mm is None else as_number(y_mm, "y_mm")
        target = None if target_mm is None else as_point_mm(target_mm, "target_mm")
        return self._core.section(drives, y, target)

    def arfi_image(self, phases: ArrayLike | None = None, noise_rad: float = 0.0, seed: int = 0) -> NDArray[np.float64]:
        """MR-ARFI phase image (rad), shape (n_u, n_v) (x by y for the default ``"xy"`` plane).

        ``noise_rad`` adds seeded Gaussian noise (same seed, same noise). Pixels without MR signal
        (bone; see ``imaged``) are NaN, as a scanner leaves them: use ``focal_arfi`` or
        ``np.nanmax`` rather than ``max``."""
        noise = as_number(noise_rad, "noise_rad")
        return self._core.arfi_image(as_phases(phases), noise, as_count(seed, "seed"))

    def focal_arfi(self, image: ArrayLike) -> tuple[float, tuple[int, int]]:
        """The focal ARFI of an image (rad) and its pixel (i, j): the largest imaged pixel within
        the scenario's ``[arfi] focal_search_radius_mm`` of the target in the image plane (bone,
        scalp or a side lobe farther away never stand in for the focus). Raises ValueError when
        no imaged pixel lies there."""
        return self._core.focal_arfi(as_image(image, "image"))

    @property
    def focal_region(self) -> NDArray[np.bool_]:
        """The pixels within ``[arfi] focal_search_radius_mm`` of the target in the image plane,
        shape (n_u, n_v): where ``focal_arfi`` looks for the focus."""
        return self._core.focal_region()

    @property
    def imaged(self) -> NDArray[np.bool_]:
        """Which pixels of the MR image are imaged, shape (n_u, n_v): at least half of the pixel
        (over the slice) is tissue with MR signal (not bone)."""
        return self._core.imaged()

    def skull_phases(
        self, seed: int, correlation_length_mm: float = 12.0, peak_to_peak_rad: float = 6.0, jitter_rad: float = 0.5
    ) -> NDArray[np.float64]:
        """Seeded skull-like per-element aberration (rad): a smooth random screen over the
        aperture plus per-element jitter; condensed to the 16 default groups (:meth:`condense`) it is
        the paper's 16-aberration case."""
        return self._core.skull_phases(
            int(seed), float(correlation_length_mm), float(peak_to_peak_rad), float(jitter_rad)
        )

    def focus_shift_phases(self, shift_mm: ArrayLike, name: str = "shift_mm") -> NDArray[np.float64]:
        """Known per-element phases (rad) that move the focus by ``shift_mm`` (x, y, z in the
        transducer frame, mm): the steering phases for the shifted target minus the current ones.
        Added to an acquisition (``arfi_image(aberration + p)``, ``arfi simulate --known-phases``)
        they give a displaced or, along z, a defocused diversity image: the classic phase-diversity
        choice (Gonsalves 1982); per element they inform more than images with random known
        group phases (BENCHMARKS.md, "Ladder constants"). Errors name ``name``."""
        return self._core.focus_shift_phases(as_point_mm(shift_mm, name), name)

    def element_responses(self, target_mm: ArrayLike | None = None) -> NDArray[np.complex128]:
        """Each element's complex pressure (Pa per unit drive, without steering) at ``target_mm``
        (mm, transducer frame; default the focus), from one reciprocal march: the pressure there
        for added phases ``phi`` is ``sum(h * exp(1j * (steering_phases_rad + phi)))``, and
        ``sum(abs(h))`` the most any phases give."""
        target = None if target_mm is None else as_point_mm(target_mm, "target_mm")
        return self._core.element_responses(target)

    def element_phases(self, phases: ArrayLike, name: str = "phases") -> NDArray[np.float64]:
        """Added phases, one per element or one per group, as one per element. Errors name ``name``."""
        a = as_phases(phases, name)
        if a is None:
            raise ValueError(f"{name}: required, got None")
        return self._core.element_phases(a, name)

    def known_per_element(self, known: ArrayLike, name: str = "known") -> NDArray[np.float64]:
        """An image's known added phases, given per element, per group or per default group (the
        paper's 16), as one per element. Errors name ``name``."""
        return self._core.known_per_element(as_phases(known, name), name)

    def condense(self, element_phases: ArrayLike) -> NDArray[np.float64]:
        """Per-group circular means (the angle of the mean phasor) of per-element phases."""
        a = as_phases(element_phases, "element_phases")
        if a is None:
            raise ValueError("element_phases: required, got None")
        return self._core.condense(a)

    def calibrate(self, image: ArrayLike, known: ArrayLike | None = None, max_width_mm: float = 10.0) -> Calibration:
        """Fits the broadening width and amplitude to a no-aberration image (paper Eq. 2)."""
        return self._core.calibrate(
            as_image(image, "image"), as_phases(known, "known"), None, as_number(max_width_mm, "max_width_mm")
        )

    def estimate(
        self,
        images: Images,
        known: Known = None,
        options: _core.EstimateOptions | None = None,
        *,
        progress: bool | Callable[[int, int], object] = False,
        **kwargs: Any,
    ) -> Estimate:
        """Hybrid estimation of the per-group aberration from one or more MR-ARFI images, each
        taken with ``known`` phases (per element or per group) added to the steering.

        What to estimate with is ``options`` (an :class:`arfi.EstimateOptions`: method, limits,
        prior, noise, nuisance, suggestion), or the same options as keywords
        (``sim.estimate(image, method="nelder-mead")``), not both. ``progress``: True draws a bar
        on a terminal (stderr) as the element basis is marched; a callable is called with
        ``(done, total)`` element fields instead (an exception it raises stops the estimate). The
        result flags ``ambiguous`` when clearly different solutions fit within the noise.

        With one group per element (``with_groups(n_elements)``, the CLI's ``--groups 1024``)
        the estimate is per element: an L-BFGS fit on the element field basis (one march per
        element), warm-started by the estimate on the default 16 groups (with a prior it starts
        from the prediction, and ``ambiguous`` is judged on searches of the element posterior
        from draws of the prior: ``worst_recovery``).

        With a prior, ``cost`` stays the images' cost (paper Eq. 4) and ``posterior_cost`` is the
        minimised negative log posterior. Per element, a prior and one acquisition (one image, or
        repeats with the same known phases) keep the prediction unsearched (``kept_prediction``):
        one in-focus image cannot check a per-element correction of it (a correction that fits
        the image better than the truth does can leave less focus than the prediction), while a
        second image with other known phases (a defocus) constrains it. With fitted nuisance
        parameters their values are in ``nuisance`` and ``misfit`` is judged on the fit with them.

        What to apply is ``recommended_phases_rad`` (``recommended`` names it, ``supported`` is
        True when it is the estimate): with a prior, the prediction when the model does not explain
        the images (``model_mismatch``) or, per element, when the images' chi-squared at the
        prediction lies far above what truths within the prior's std give (``prior_check``: the
        search's move would absorb what the model cannot form). Per element without a prior, the
        estimate is judged on what the images determine (``support``: the Fisher information at
        the estimate): unless the correction it is expected to leave reaches the uncorrected
        beam's focus and the group fit's, and its search converged (``converged``), the estimate
        is not recommended (``underdetermined`` when the images do not determine it) and
        ``recommended`` is ``"uncorrected"`` (zero phases) or ``"groups"`` (``group_phases_rad`` on
        their elements)."""
        arrays, kn_arrays = images_and_known(images, known)
        if options is None:
            options = _core.EstimateOptions(**kwargs)
        elif kwargs:
            raise ValueError(f"options: give EstimateOptions or keyword options ({', '.join(kwargs)}), not both")
        elif not isinstance(options, _core.EstimateOptions):
            raise ValueError(f"options: must be an EstimateOptions, got {type(options).__name__}")
        report = callback(progress, "arfi: element fields", "elements")
        return self._core.estimate(arrays, kn_arrays, options, progress=report)

    def cost_model(self, images: Images, known: Known = None, fit_amplitude: bool = False) -> CostModel:
        """The hybrid cost (paper Eq. 4) that ``estimate`` minimises, for one MR-ARFI image or a
        list of them, each taken with its ``known`` added phases (rad, per element or group; None
        = none): the same masks (``mask_fraction`` of each image's maximum, connected to it) and
        per-pixel group kernels. ``fit_amplitude`` fits one amplitude scale for all images at each
        evaluation. At most 256 groups."""
        imgs, knowns = images_and_known(images, known)
        return CostModel(self._core.cost_model(imgs, knowns, bool(fit_amplitude)))

    def fit_mode(self, images: Images, known: Known, mode: ArrayLike) -> _core.ModeFit:
        """The coefficient ``c`` of a prior ``mode`` (rad per element for c = 1; standard normal a
        priori) that best explains the images, each taken with its ``known`` phases added: image
        ``k`` is this model's with ``c * mode + known_k`` added, one amplitude scale fitted, ``c``
        searched at steps of one (one march per image each) out to +-3, then by successive
        parabolic steps (``bracketed`` is false when the best lies at +-3). Meant for
        a CT prediction's bone-speed mode on the head with the CT's bone driven with the
        reference steering (:meth:`arfi.scenario.Scenario.with_ct_bone`): the phases stay the
        prediction's, so a model without the skull cannot pull the coefficient by reshaping its
        focus. Returns ``coefficient``, ``std`` (posterior), ``scale``, ``misfit`` (chi-squared per
        pixel), ``n_pixels``, ``noise_rad``, ``tried`` ((c, cost) pairs) and ``bracketed``. Ctrl-C
        stops it before the next coefficient."""
        imgs, knowns = images_and_known(images, known)
        return self._core.fit_mode(imgs, knowns, as_phases(mode, "mode"))

    def fit_modes(
        self, images: Images, known: Known, modes: ArrayLike, noise_rad: float | None = None
    ) -> _core.ModesFit:
        """The coefficients ``c`` of several prior ``modes`` (rows: rad per element for c_m = 1;
        each standard normal a priori) that best explain the images jointly, each taken with its
        ``known`` phases: image ``k`` is this model's with ``sum_m c_m * modes[m] + known_k``
        added, one amplitude scale fitted, by Gauss-Newton with the images' exact derivatives along
        each mode (one batch march of every image and its derivatives per iteration, a few
        iterations). Meant for a CT prediction's pose and bone-speed modes on the head with the
        CT's bone (:mod:`arfi.analysis.prior_modes`). Returns ``coefficients``, ``std`` and
        ``covariance`` (posterior), ``scale``, ``misfit`` and ``misfit_at_zero`` (chi-squared per
        pixel at the fit and with every coefficient zero), ``n_pixels``, ``noise_rad``,
        ``iterations`` and ``converged``. ``noise_rad``: the images' noise where it is known, as
        for :meth:`estimate` (default: their background floor). Ctrl-C stops it before the next
        iteration."""
        imgs, knowns = images_and_known(images, known)
        rows = real_array(modes, "modes")
        if rows.ndim != 2:
            raise ValueError(f"modes: must be two-dimensional (modes x elements), got shape {rows.shape}")
        noise = None if noise_rad is None else as_number(noise_rad, "noise_rad")
        return self._core.fit_modes(imgs, knowns, np.ascontiguousarray(rows), noise_rad=noise)

    def diagnose(
        self,
        images: Images,
        known: Known = None,
        threshold: float = 0.0,
        effects: list[str] | None = None,
        max_iterations: int = 1500,
        time_limit_s: float | None = None,
    ) -> Diagnosis:
        """The model-discrepancy workflow (fit each candidate effect, add the best while the BIC
        favours it, repeat) on one MR-ARFI image or a list of them (e.g. a
        calibration image and an aberrated one), each taken with its ``known`` added phases (rad,
        per element or group; None = none). Names the effects missing from this model, in order,
        with their fitted parameters, until the residual is consistent with the noise of the
        image backgrounds. ``effects`` limits the library (default: all of
        ``arfi.analysis.diagnose.EFFECTS``); ``threshold`` is the evidence (BIC gain, in units of the noise
        variance) an effect needs, 0 being the plain BIC. ``max_iterations`` bounds each candidate's
        Nelder–Mead fit; after ``time_limit_s`` the effects added so far are returned with
        ``stop == "time limit"``. Ctrl-C stops the run within a second."""
        imgs, knowns = images_and_known(images, known)
        if effects is not None and (isinstance(effects, str) or not all(isinstance(e, str) for e in effects)):
            raise ValueError(f"effects: must be a list of effect names, got {effects!r}")
        return self._core.diagnose(
            imgs,
            knowns,
            as_number(threshold, "threshold"),
            as_count(max_iterations, "max_iterations"),
            None if effects is None else list(effects),
            None if time_limit_s is None else as_number(time_limit_s, "time_limit_s"),
        )

    def effect_images(
        self, effects: dict[str, Any], known: Sequence[ArrayLike | None] | None = None
    ) -> list[NDArray[np.float64]]:
        """The model's MR-ARFI images (rad) with effects of the diagnosis library applied:
        ``effects`` maps parameter names, exactly as ``diagnose`` reports them, to values
        (``arfi.analysis.diagnose.PARAMETERS`` lists them with their meaning: ``scale``,
        ``broadening_width_mm``, ``broadening_width_u_mm`` / ``broadening_width_v_mm``,
        ``dx_mm``, ``dz_mm``, ``group_phases_rad``, ``dead_groups``, ...); one image per entry of
        ``known``. A diagnosis's ``params`` fed back here give its model images."""
        knowns = [as_phases(k, f"known[{i}]") for i, k in enumerate(known or [None])]
        effects = dict(effects)
        if "sound_speed_m_per_s" in effects:
            warnings.warn(
                "effects: 'sound_speed_m_per_s' is now 'sound_speed_m_s' (the scenario's name); the old name goes in "
                "the next release",
                DeprecationWarning,
                stacklevel=2,
            )
            effects["sound_speed_m_s"] = effects.pop("sound_speed_m_per_s")
        for key, value in effects.items():
            if key != "dead_groups":
                real_array(value, f"effects[{key!r}]")
        return self._core.effect_images(knowns, effects)

    def source_field(self, phases: ArrayLike | None = None) -> NDArray[np.complex128]:
        """Pressure (Pa) on the source plane, shape (ny, nx)."""
        return self._core.source_field(as_phases(phases))
