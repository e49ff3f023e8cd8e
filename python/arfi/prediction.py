"""CT-based prediction of the skull's per-element aberration: :func:`predict`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi import _core
from arfi.scenario import Scenario
from arfi.simulation import Simulation
from arfi.validate import as_point_mm


@dataclass(frozen=True)
class Prediction:
    """What the scenario's CT bone does to each element's wave at the target, by reciprocity.

    Each element's complex pressure ``h_e`` at the target (unit drive) is computed through the
    head with its CT and through the same head with the CT's bone read as soft tissue (the
    *reference*: the head without its skull, which the estimation's model assumes), from one
    transposed march each instead of one march per element. ``phases_rad`` is
    ``arg(h_skull · conj(h_reference))`` less its weighted circular mean: the aberration in the sign
    of an estimate's ``phases_rad`` (driving the reference steering minus it corrects; it is the
    ``--prior`` of ``arfi estimate``). The focal pressures are exact sums of the responses."""

    phases_rad: NDArray[np.float64]
    """Predicted aberration per element (rad, wrapped to (-pi, pi])."""
    transmission: NDArray[np.float64]
    """Per element, ``|h_skull| / |h_reference|`` at the target."""
    reference_steering_rad: NDArray[np.float64]
    """Steering phases toward the target through the head without bone (straight-ray times of
    flight; at the focus, those of the estimation's model)."""
    target_mm: tuple[float, float, float]
    """The point predicted for (transducer frame, mm); between grid points the fields are
    interpolated there (band-limited across, an angular-spectrum sub-step along z)."""
    reference_pa: float
    """Focal |p| of the reference steering in the head without bone."""
    reference_optimal_pa: float
    """The most any phases give in the head without bone, ``sum |h_reference|``: ``reference_pa``
    falls short of it by what straight rays miss without any bone (refraction, oblique paths
    through soft tissue), which a correction relative to the reference steering keeps."""
    uncorrected_pa: float
    """Focal |p| of the reference steering through the skull (the aberrated focus)."""
    ray_steering_pa: float
    """Focal |p| of the scenario's own steering toward the target (straight rays through the CT's
    bone) through the skull."""
    corrected_pa: float
    """Focal |p| of the reference steering minus ``phases_rad`` through the skull."""
    optimal_pa: float
    """The most any phases give through the skull at this drive amplitude: ``sum |h_skull|``."""
    skull_responses: NDArray[np.complex128]
    """Per element, ``h_skull``: its complex pressure (Pa) at the target through the skull when it
    alone is driven with a unit phasor."""
    bone_speed_sensitivity_rad_per_percent: NDArray[np.float64] | None = None
    """Per element, how ``phases_rad`` moves (rad) per percent of the CT conversion's bone sound
    speed (``predict(..., bone_speed_sensitivity=True)``; else None): a finite difference over
    +10 % through the wave model, its weighted common phase removed. ``s`` times it is the
    prediction's error if the conversion's bone is ``s`` percent off: give it to an estimate as a
    prior mode (``prior_modes``; the CLI's ``--prior-bone-speed-std-percent``)."""
    simulation: Simulation | None = field(default=None, compare=False, repr=False)
    """The skull's simulation the prediction marched (``predict(..., keep_simulation=True)``; else
    None): fields, sections and element maps of the predicted drives without building its plan
    again. Its ARFI amplitude is not calibrated (1 unless the scenario gives one): not for
    MR-ARFI images."""

    def pressure_with(self, phases_rad: ArrayLike) -> float:
        """Focal |p| (Pa) at the target through this prediction's skull when the array drives the
        reference steering minus ``phases_rad`` (one per element): e.g. an estimate's, another
        prediction's, or zeros for the uncorrected beam; exact in the model."""
        phases = np.asarray(phases_rad, dtype=np.float64)
        if phases.shape != self.skull_responses.shape or not np.all(np.isfinite(phases)):
            raise ValueError(f"phases_rad: must hold {self.skull_responses.size} finite values (one per element), "
                             f"got shape {phases.shape}")
        return float(abs(np.sum(self.skull_responses * np.exp(1j * (self.reference_steering_rad - phases)))))

    def correction_rad(self, steering_rad: NDArray[np.float64]) -> NDArray[np.float64]:
        """Phases to add to a simulation's own ``steering_rad`` to drive the corrected array
        (reference steering minus the prediction), e.g. ``sim.field(p.correction_rad(sim.steering_phases_rad))``."""
        return self.reference_steering_rad - self.phases_rad - np.asarray(steering_rad, dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``arfi predict`` writes: per-element vectors and the focal pressures."""
        return {
            "phases_rad": self.phases_rad.tolist(),
            "transmission": self.transmission.tolist(),
            "reference_steering_rad": self.reference_steering_rad.tolist(),
            "target_mm": list(self.target_mm),
            "focal_pressure_pa": {
                "reference": self.reference_pa,
                "reference_optimal": self.reference_optimal_pa,
                "uncorrected": self.uncorrected_pa,
                "ray_steering": self.ray_steering_pa,
                "corrected": self.corrected_pa,
                "optimal": self.optimal_pa,
            },
        } | ({} if self.bone_speed_sensitivity_rad_per_percent is None
             else {"bone_speed_sensitivity_rad_per_percent": self.bone_speed_sensitivity_rad_per_percent.tolist()})


def predict(scenario: Scenario, target_mm: ArrayLike | None = None, bone_speed_sensitivity: bool = False,
            keep_simulation: bool = False) -> Prediction:
    """Simulates ``scenario`` (which needs a ``[ct]``) and predicts each element's aberration at
    ``target_mm`` (transducer frame, mm; default: the focus): see :class:`Prediction`. Costs two
    plans (the head without bone, then the skull's), two transposed marches and one transposed
    projection, whatever the number of elements; each plan is dropped before the next is built,
    so that two are never held at once. The ARFI amplitude is not calibrated (a prediction makes
    no image), which spares a march through a reverberating head. ``bone_speed_sensitivity`` also
    gives :attr:`Prediction.bone_speed_sensitivity_rad_per_percent` (needs the porosity
    conversion, ``aubry2003``), at the cost of one more simulation of the skull (built and dropped
    before the skull's own). ``keep_simulation`` keeps the skull's simulation as
    :attr:`Prediction.simulation` (its plan stays in memory as long as the prediction does)."""
    target = None if target_mm is None else as_point_mm(target_mm, "target_mm")
    d = _core.predict(scenario.to_toml(), "toml", scenario.base_dir, target, bool(bone_speed_sensitivity),
                      bool(keep_simulation))
    core = d.pop("simulation")
    kept = None
    if core is not None:
        fields_only = scenario.to_dict()
        fields_only.setdefault("arfi", {}).setdefault("amplitude_rad_m3_per_n", 1.0)
        kept = Simulation._wrap(Scenario.from_dict(fields_only, scenario.base_dir), core)
    return Prediction(**{**d, "target_mm": tuple(float(v) for v in d["target_mm"]), "simulation": kept})
