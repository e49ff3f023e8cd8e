"""arfi: hybrid simulation–MR-ARFI phase aberration correction for focused ultrasound.

The beam is simulated with the Hybrid Angular Spectrum method (Rust core, ``has-core``), turned
into radiation force ``F = 2·alpha·I/c``, averaged over the MR slice, broadened with a Gaussian
and sampled onto MR pixels (Vyas, Kaye & Butts Pauly, Med Phys 41(3):032901, 2014).

Quick start::

    import arfi
    sim = arfi.Simulation()              # the paper's phantom experiment (550 kHz, focus at 85 mm)
    image = sim.arfi_image()             # ideal MR-ARFI phase image, rad, shape (128, 96)
    field = sim.field()                  # complex pressure (Pa) on the focal plane and the axis
    p = arfi.predict(arfi.Scenario.load("head.toml"))  # a CT's per-element aberration (needs [ct])
"""

from arfi._core import MemoryLimitError, ModeFit, ModesFit
from arfi.analysis.loop import LoopResult, loop2
from arfi.analysis.prediction import Prediction, predict, predict_targets
from arfi.analysis.prediction_estimate import PredictionEstimate, estimate_with_prediction
from arfi.cost import CostModel, CostTerm
from arfi.estimation import Calibration, Estimate, EstimateOptions, EstimateSupport, NextAcquisition, NuisanceFit
from arfi.io.files import read_arfi_image, read_phases, write_arfi_image
from arfi.io.volume import IntensityVolume, PressureVolume
from arfi.scenario import Scenario
from arfi.simulation import (
    Field,
    FieldFocus,
    FocalMetrics,
    Grid,
    HottestPlace,
    Propagation,
    Reverberation,
    Section,
    Simulation,
)

__all__ = [
    "Grid",
    "Propagation",
    "Reverberation",
    "PredictionEstimate",
    "estimate_with_prediction",
    "Scenario",
    "Simulation",
    "Field",
    "Section",
    "FocalMetrics",
    "FieldFocus",
    "HottestPlace",
    "PressureVolume",
    "IntensityVolume",
    "read_arfi_image",
    "write_arfi_image",
    "read_phases",
    "loop2",
    "LoopResult",
    "CostModel",
    "CostTerm",
    "predict",
    "predict_targets",
    "Prediction",
    "ModeFit",
    "ModesFit",
    "MemoryLimitError",
    "Calibration",
    "Estimate",
    "EstimateOptions",
    "EstimateSupport",
    "NuisanceFit",
    "NextAcquisition",
]

try:
    from importlib.metadata import version as _version

    __version__ = _version("arfi")
except Exception:  # pragma: no cover - running from a source tree without metadata
    __version__ = "0.0.0"
