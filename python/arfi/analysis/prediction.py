"""CT-based prediction of the skull's per-element aberration: :func:`predict`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi import _core
from arfi.checks import as_point_mm, real_array
from arfi.scenario import Scenario
from arfi.simulation import Section, Simulation

#: What the scenario's CT bone does to each element's wave at the target (the extension's typed
#: result: ``phases_rad``, ``transmission``, the focal pressures ``*_pa``, ``pressure_with``,
#: ``correction_rad``; ``to_dict()`` is the JSON of ``arfi predict``).
Prediction = _core.Prediction


#: The drives a CT-based prediction compares, by the names of its focal pressures, as a reader
#: names them (the printed focal-metrics lines and the report's titles).
DRIVE_LABELS = {"uncorrected": "uncorrected", "ray_steering": "straight-ray CT steering", "corrected": "corrected"}


def drive_labels(scenario: Any) -> dict[str, str]:
    """:data:`DRIVE_LABELS` true to ``scenario``: where it steers by straight rays through the head
    without its bone (``[ct] steer_without_bone``), its straight-ray steering is the uncorrected
    drive, and is called so."""
    ct = scenario.to_dict().get("ct") or {}
    if ct.get("steer_without_bone"):
        return {**DRIVE_LABELS, "ray_steering": "straight-ray steering without bone (the uncorrected drive)"}
    return dict(DRIVE_LABELS)


def predict(
    scenario: Scenario,
    target_mm: ArrayLike | None = None,
    bone_speed_sensitivity: bool = False,
    keep_simulation: bool = False,
    pose_sensitivity: bool = False,
) -> Prediction:
    """Simulates ``scenario`` (which needs a ``[ct]``) and predicts each element's aberration at
    ``target_mm`` (transducer frame, mm; default: the focus): see :class:`Prediction`. Costs two
    plans (the head without bone, then the skull's), two transposed marches and one transposed
    projection, whatever the number of elements; each plan is dropped before the next is built,
    so that two are never held at once. The ARFI amplitude is not calibrated (a prediction makes
    no image), which spares a march through a reverberating head. ``bone_speed_sensitivity`` also
    gives :attr:`Prediction.bone_speed_sensitivity_rad_per_percent` (needs the porosity
    conversion, ``aubry2003``), at the cost of one more simulation of the skull (built and dropped
    before the skull's own). ``pose_sensitivity`` also gives the pose modes,
    :attr:`Prediction.pose_sensitivity_rad_per_mm` and ``_per_deg`` (how the predicted phases move
    when the head lies shifted or turned off the CT's registration: six more transposed marches
    through the skull, side by side, no plan; needs a curved array). ``keep_simulation`` keeps the skull's simulation as
    :attr:`Prediction.simulation` (its plan stays in memory as long as the prediction does)."""
    target = None if target_mm is None else as_point_mm(target_mm, "target_mm")
    prediction, kept = _core.predict(
        scenario.core,
        target,
        bool(bone_speed_sensitivity),
        bool(keep_simulation),
        bool(pose_sensitivity),
    )
    return prediction if kept is None else prediction.with_simulation(_kept_simulation(kept))


def predict_targets(
    scenario: Scenario,
    targets_mm: ArrayLike,
    bone_speed_sensitivity: bool = False,
    keep_simulation: bool = False,
    pose_sensitivity: bool = False,
    progress: Callable[[int, int], object] | None = None,
) -> list[Prediction]:
    """:func:`predict` at each of ``targets_mm`` (shape (n, 3), transducer frame, mm), from one plan
    of each head: the head without bone is built once and marched from every target, then the
    skull likewise (a plan depends on the head, the grid and the scenario's steering, not on the
    target), so each target beyond the first costs its transposed marches and projection, not a
    plan. Each prediction equals :func:`predict`'s at its target to the last bit. The scenario's
    grid must hold every target and each lies in the CT's box: one outside either is refused
    (``ValueError`` naming it by index and position) before anything is built. ``progress(done,
    total)`` is called per transposed march. With ``keep_simulation`` every prediction holds the
    one skull simulation (:attr:`Prediction.simulation`)."""
    targets = np.ascontiguousarray(np.atleast_2d(real_array(targets_mm, "targets_mm")))
    predictions, kept = _core.predict_targets(
        scenario.core,
        targets,
        bool(bone_speed_sensitivity),
        bool(keep_simulation),
        bool(pose_sensitivity),
        progress,
    )
    if kept is None:
        return predictions
    sim = _kept_simulation(kept)
    return [p.with_simulation(sim) for p in predictions]


def _kept_simulation(kept: tuple[_core.CoreSimulation, _core.CoreScenario]) -> Simulation:
    """A prediction's kept skull simulation, with the scenario it was built from."""
    core, built_from = kept
    return Simulation._wrap(Scenario._of(built_from), core)


def compared_drives(prediction: Prediction) -> dict[str, NDArray[np.float64]]:
    """The drives a prediction compares (:data:`DRIVE_LABELS`), as phases added to its kept
    simulation's steering (rad, per element): ``uncorrected`` (the reference steering toward the
    target, the head read without bone), ``ray_steering`` (the scenario's straight-ray CT steering
    toward the target) and ``corrected`` (the reference steering minus the prediction). Needs a
    prediction made with ``keep_simulation=True``."""
    sim = prediction.kept_simulation()
    steering = sim.steering_phases_rad
    return {
        "uncorrected": prediction.reference_steering_rad - steering,
        "ray_steering": sim.focus_shift_phases(np.subtract(prediction.target_mm, sim.focus_mm)),
        "corrected": prediction.correction_rad(steering),
    }


def focal_metrics(prediction: Prediction) -> dict[str, _core.FocalMetrics]:
    """The focal metrics in 3-D around the prediction's target (``Simulation.focal_metrics``: the
    focal peak, its distance from the target, -3/-6 dB extents, -6 dB volume, I_SPPA and MI) for
    each of :func:`compared_drives`, one march each through the kept skull, stopping past the
    focal box."""
    drives = compared_drives(prediction)
    sim = prediction.kept_simulation()
    return {name: sim.focal_metrics(phases, target_mm=prediction.target_mm) for name, phases in drives.items()}


def compared_section(prediction: Prediction) -> tuple[Section, dict[str, _core.FocalMetrics]]:
    """Each of :func:`compared_drives` on the x–z section through the prediction's target, and
    its focal metrics there (as :func:`focal_metrics` gives them), from one batch march of the
    three through the kept skull (what ``arfi predict --report`` draws and prints)."""
    drives = compared_drives(prediction)
    section = prediction.kept_simulation().section(
        list(drives.values()), y_mm=prediction.target_mm[1], target_mm=prediction.target_mm
    )
    return section, dict(zip(drives, cast(list, section.focal_metrics)))
