"""An estimate that starts from a CT-based prediction: :func:`estimate_with_prediction`.

The prediction (:func:`arfi.predict`, or the JSON of ``arfi predict --json``) gives the estimate
three things: its phases as the prior (``options.prior``), its per-element transmission (each
element of the model without bone driven at what the skull lets through there, so that the
model's focus is as weak as the skull's and its elements weighted as through it), and its error
modes (the head's pose, the CT conversion's bone speed; :mod:`arfi.analysis.prior_modes`), which are
fitted to the images first, on the head with the CT's bone, and move the prior where the images
support it. Which modes are fitted is decided here: the bone speed by default wherever the
prediction holds its sensitivity and the estimate is per element (:data:`BONE_SPEED_STD_PERCENT`
of prior spread; 0 skips it), the pose and a user's modes when asked for.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi import _core
from arfi.analysis import prior_modes
from arfi.analysis.prior_modes import BONE_SPEED_STD_PERCENT, ModesResult, PriorMode
from arfi.estimation import Calibration, Estimate, EstimateOptions
from arfi.scenario import Scenario
from arfi.simulation import Images, Known, Simulation, images_and_known

__all__ = ["BONE_SPEED_STD_PERCENT", "PredictionEstimate", "TARGET_TOLERANCE_MM", "estimate_with_prediction"]

TARGET_TOLERANCE_MM = 0.5
"""How far the focus may lie from the target a prediction was made for: a fraction of the focal
spot's width (2.3 mm at 650 kHz), over which each element's wave crosses the same bone."""

#: How errors name the parameters by default (``names`` of :func:`estimate_with_prediction`
#: renames them).
NAMES = {
    p: p
    for p in (
        "prediction",
        "transmission",
        "groups",
        "bone_speed_std_percent",
        "pose_std_mm",
        "pose_std_deg",
        "modes",
        "calibration",
        "images",
        "known",
    )
} | {"prior": "options.prior", "pose_sensitivity": "arfi.predict(..., pose_sensitivity=True)"}

#: Each mode's prior-std parameter and the key of the prediction's JSON that holds that mode.
MODE_KEYS = {
    "bone_speed_std_percent": "bone_speed_sensitivity_rad_per_percent",
    "pose_std_mm": "pose_sensitivity_rad_per_mm",
    "pose_std_deg": "pose_sensitivity_rad_per_deg",
}


@dataclass(frozen=True)
class PredictionEstimate:
    """What :func:`estimate_with_prediction` gives: the ``estimate`` (its ``recommended`` and
    ``recommended_phases_rad`` say what to apply), the fit of the prediction's modes
    (``modes_fit``; None when none was fitted) and the ``simulation`` the estimate was made on
    (calibrated, driven at the prediction's transmission)."""

    estimate: Estimate
    modes_fit: ModesResult | None
    simulation: Simulation

    @property
    def prior_moved(self) -> bool:
        """Whether the prior the estimate used is the prediction moved along its fitted modes."""
        return self.modes_fit is not None and self.modes_fit.prior_moved

    def to_dict(self) -> dict[str, Any]:
        """The JSON of ``arfi estimate``: the estimate's keys and, where modes were fitted,
        ``prior_modes_fit`` (and ``bone_speed_fit`` with ``prior_bone_speed_std_percent`` where the
        bone speed was among them)."""
        d = self.estimate.to_dict()
        r = self.modes_fit
        if r is None:
            return d
        d["prior_modes_fit"] = r.to_dict()
        bone = r.value("bone_speed")
        if bone is not None:
            std_prior = next(m.std for m in r.modes if m.name == "bone_speed")
            d["prior_bone_speed_std_percent"] = std_prior
            d["bone_speed_fit"] = {
                "percent": bone[0],
                "std_percent": bone[1],
                "std_percent_prior": std_prior,
                "scale": r.scale,
                "misfit": r.misfit,
                "n_pixels": r.n_pixels,
                "prior_moved": r.prior_moved,
                "seconds": r.seconds,
            }
        return d


def estimate_with_prediction(
    scenario: Scenario,
    images: Images,
    known: Known = None,
    options: EstimateOptions | None = None,
    *,
    prediction: _core.Prediction | Mapping[str, Any] | None = None,
    transmission: ArrayLike | None = None,
    calibration: Calibration | None = None,
    groups: int | None = None,
    bone_speed_std_percent: float | None = None,
    pose_std_mm: float | None = None,
    pose_std_deg: float | None = None,
    modes: Sequence[PriorMode] = (),
    log: Callable[[str], None] | None = None,
    progress: bool | Callable[[int, int], None] = False,
    names: Mapping[str, str] | None = None,
) -> PredictionEstimate:
    """The hybrid estimate of ``scenario``'s aberration from ``images`` (each with its ``known``
    phases) with a CT-based prediction (see the module docs): ``options.prior`` is the prediction's
    phases (as ``arfi predict --out-phases`` writes them: a prediction does not set it by itself);
    ``prediction`` (an :class:`arfi.Prediction` or the JSON of ``arfi predict``, predicted
    at the scenario's focus) gives the transmission and the modes, or ``transmission`` (one value
    per element, >= 0) alone. ``bone_speed_std_percent`` (default :data:`BONE_SPEED_STD_PERCENT`
    where the prediction holds the bone speed's sensitivity; 0 skips it), ``pose_std_mm``,
    ``pose_std_deg`` (mm, degrees; the pose is fitted only when given) and ``modes`` (a user's,
    :func:`arfi.analysis.prior_modes.read_modes`) are the modes' prior spreads. ``calibration`` is applied
    to both models (checked against the scenario), ``groups`` as :class:`Simulation` takes it.
    ``log`` receives what is done as it is done (the modes' fit announced before it runs: it
    builds and marches the head with its bone), ``progress`` is :meth:`Simulation.estimate`'s.

    Everything is checked before any model is built; a ``ValueError`` names the parameter, as
    ``names`` maps it where the caller knows it by another name (a command-line option: e.g.
    ``{"pose_std_mm": "--prior-pose-std-mm", "prior": "--prior"}``). The model with bone is dropped
    before the estimation's is built, so that two are never held at once."""
    options = options if options is not None else EstimateOptions()
    if not isinstance(options, EstimateOptions):
        raise ValueError(f"options: must be an arfi.EstimateOptions, got {type(options).__name__}")
    if calibration is not None and not isinstance(calibration, Calibration):
        raise ValueError(f"calibration: must be an arfi.Calibration, got {type(calibration).__name__}")
    say = log or (lambda _: None)
    nm = {**NAMES, **(names or {})}
    outline = scenario.outline()
    if groups is not None and not (isinstance(groups, (int, np.integer)) and 1 <= groups <= outline.n_elements):
        raise ValueError(f"{nm['groups']}: must be an integer between 1 and {outline.n_elements}, got {groups!r}")
    if calibration is not None:
        outline.check_calibration(calibration, nm["calibration"])
    image_list, known_list = images_and_known(images, known)
    for i, image in enumerate(image_list):
        outline.check_image(image.shape, outline.mr_affine_mm, f"{nm['images']}[{i}]")
    for i, k in enumerate(known_list):
        if k is not None:
            outline.known_per_element(k, f"{nm['known']}[{i}]", groups)
    prior = options.prior
    if prior is not None:
        outline.check_prior(prior, nm["prior"], groups)
    d, drive = _prediction_parts(prediction, transmission, outline, nm)
    stds = {"bone_speed_std_percent": bone_speed_std_percent, "pose_std_mm": pose_std_mm, "pose_std_deg": pose_std_deg}
    to_fit = _modes_to_fit(scenario, d, prior, groups, stds, list(modes), outline, nm)
    fit, source = None, None
    if to_fit:
        assert prior is not None  # _modes_to_fit fits none without one
        by_default = bone_speed_std_percent is None and any(m.name == "bone_speed" for m in to_fit)
        say(
            f"fitting the prediction's modes ({', '.join(m.name for m in to_fit)}) to the images first, on a model "
            "of the head with the CT's bone"
            + (
                " (the bone speed by default where the prediction holds its sensitivity; "
                f"{nm['bone_speed_std_percent']}=0 skips it)"
                if by_default
                else ""
            )
        )
        skull = _calibrated(Simulation(scenario.with_ct_bone(), groups), calibration)
        fit = prior_modes.fit_prior_modes(skull, image_list, known_list, prior, to_fit, noise_rad=options.noise_rad)
        source = skull.source_model()
        del skull
        _core.release_freed()
        for line in fit.summary_lines():
            say(line)
        if fit.prior_moved:
            options = options.replace(prior=fit.prior)
    sim = _calibrated(Simulation(scenario, groups, source=source), calibration)
    if drive is not None:
        sim = sim.with_element_amplitudes(drive / drive.mean())
    estimate = sim.estimate(image_list, known_list, options, progress=progress)
    return PredictionEstimate(estimate, fit, sim)


def _calibrated(sim: Simulation, calibration: Calibration | None) -> Simulation:
    """``sim`` with ``calibration`` applied (checked against the scenario before the build)."""
    return sim if calibration is None else sim.calibrated(calibration)


def _prediction_parts(
    prediction: _core.Prediction | Mapping[str, Any] | None,
    transmission: ArrayLike | None,
    outline: _core.ScenarioOutline,
    nm: dict[str, str],
) -> tuple[dict[str, Any], NDArray[np.float64] | None]:
    """The prediction as its JSON dict, and the per-element drive (its transmission, or
    ``transmission``), checked against the scenario: one value per element, finite, >= 0, not
    all zero, predicted at the scenario's focus."""
    if prediction is not None and transmission is not None:
        raise ValueError(
            f"{nm['transmission']}: give the prediction or a transmission, not both (the prediction holds one)"
        )
    d: dict[str, Any] = {}
    name = nm["transmission"]
    values = transmission
    if prediction is not None:
        if isinstance(prediction, _core.Prediction):
            d = prediction.to_dict()
        elif isinstance(prediction, Mapping):
            d = dict(prediction)
        else:
            raise ValueError(
                f"{nm['prediction']}: must be an arfi.Prediction or its JSON, got {type(prediction).__name__}"
            )
        if d.get("transmission") is None:
            raise ValueError(f"{nm['prediction']}: holds no 'transmission' (not the JSON of arfi predict)")
        name, values = f"{nm['prediction']}: 'transmission'", d["transmission"]
    if values is None:
        return d, None
    try:
        drive = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be numbers") from None
    if drive.ndim != 1 or not np.all(np.isfinite(drive)):
        raise ValueError(f"{name}: must be a list of finite numbers, one per element")
    outline.check_per_element(len(drive), name)
    if np.any(drive < 0) or not np.any(drive > 0):
        raise ValueError(f"{name}: transmissions must be non-negative, and not all zero")
    target = d.get("target_mm")
    if target is not None:
        try:
            at = np.asarray(target, dtype=np.float64)
        except (TypeError, ValueError):
            at = np.full(0, np.nan)
        if at.shape != (3,) or not np.all(np.isfinite(at)):
            raise ValueError(f"{nm['prediction']}: 'target_mm' must be three finite numbers")
        # Each element's transmission is its wave's at the point predicted for; a focus
        # elsewhere (beyond a fraction of the focal spot) crosses the skull elsewhere.
        focus = np.asarray(outline.focus_mm)
        if np.linalg.norm(at - focus) > TARGET_TOLERANCE_MM:
            x, y, z = at
            fx, fy, fz = focus
            raise ValueError(
                f"{nm['prediction']}: predicted for the target ({x:.1f}, {y:.1f}, {z:.1f}) mm, but the scenario "
                f"focuses at ({fx:.1f}, {fy:.1f}, {fz:.1f}) mm: predict at the focus (or the focus at the target)"
            )
    return d, drive


def _modes_to_fit(
    scenario: Scenario,
    prediction: dict[str, Any],
    prior: NDArray[np.float64] | None,
    groups: int | None,
    stds: dict[str, float | None],
    modes: list[PriorMode],
    outline: _core.ScenarioOutline,
    nm: dict[str, str],
) -> list[PriorMode]:
    """The modes to fit (see the module docs); a mode asked for where it cannot be fitted is a
    ValueError naming its parameter, one left to its default is skipped quietly."""
    for name, std in stds.items():
        if std is not None and not (np.isfinite(std) and std >= 0):
            raise ValueError(f"{nm[name]}: must be a finite number >= 0, got {std:g}")
    for m in modes:
        if not isinstance(m, PriorMode):
            raise ValueError(
                f"{nm['modes']}: must be arfi.analysis.prior_modes.PriorMode values, got {type(m).__name__}"
            )
    asked = [n for n, v in stds.items() if v] + (["modes"] if modes else [])
    first = nm[asked[0]] if asked else None
    if prior is None:
        if first:
            raise ValueError(f"{first}: needs {nm['prior']} (the prediction the modes belong to)")
        return []
    n_elements = outline.n_elements
    n_groups = outline.n_default_groups if groups is None else groups
    if len(prior) != n_elements or n_groups != n_elements:
        if first and n_groups != n_elements:
            raise ValueError(f"{first}: fitted for per-element estimates only ({nm['groups']} {n_elements})")
        if first:
            raise ValueError(
                f"{first}: fitted for per-element estimates only ({nm['prior']} has {len(prior)} values, one per "
                f"group; give one per element, {n_elements})"
            )
        return []
    for name, key in MODE_KEYS.items():
        if stds[name] and key not in prediction:
            raise ValueError(
                f"{nm[name]}: needs {nm['prediction']} holding '{key}'"
                + (
                    " (this one has none: predict again"
                    + (f" with {nm['pose_sensitivity']})" if key.startswith("pose") else " with the current arfi)")
                    if prediction
                    else " (an arfi.Prediction or the JSON of arfi predict)"
                )
            )
    try:
        fitted = prior_modes.prediction_modes(
            prediction,
            n_elements,
            pose_std_mm=stds["pose_std_mm"],
            pose_std_deg=stds["pose_std_deg"],
            bone_speed_std_percent=(
                BONE_SPEED_STD_PERCENT if stds["bone_speed_std_percent"] is None else stds["bone_speed_std_percent"]
            ),
        )
    except ValueError as e:
        # A malformed mode belongs to the parameter that asked for it, else to the prediction.
        owner = next((n for n, k in MODE_KEYS.items() if stds[n] and str(e).startswith(k)), "prediction")
        raise ValueError(f"{nm[owner]}: {e}") from None
    for m in modes:
        if len(m.per_unit_rad) != n_elements:
            raise ValueError(f"{nm['modes']}: {m.name}: has {len(m.per_unit_rad)} values for {n_elements} elements")
    fitted += modes
    if fitted and scenario.to_dict().get("ct") is None:
        if first:
            raise ValueError(f"{first}: needs a [ct] scenario (the modes are fitted on the head with the CT's bone)")
        return []
    return fitted
