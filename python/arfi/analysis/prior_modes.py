"""A CT prediction's error modes, fitted to MR-ARFI images before the per-element estimate.

A CT-based prediction is off in ways that move every element's phase at once: the CT's
registration to the transducer (three shifts, three turns about the target: the pose) and the
CT conversion's bone sound speed. Each is a *mode*: a per-element pattern ``g`` (rad per unit:
per mm, per degree, per percent) from :func:`arfi.predict`, whose size ``c`` is unknown with a
prior standard deviation ``s`` (typical registration errors are 1-2 mm and 1-2 degrees; bone
speed constants scatter by a tenth to a fifth between skulls). The images fit the coefficients
jointly on the head with the CT's bone driven with the reference steering (the phases otherwise
the prediction's, so that the fit cannot reshape the focal spot along a mode), by Gauss-Newton
(:meth:`arfi.Simulation.fit_modes`); the prediction then moves by ``sum_m c_m g_m``, and the
per-element fit starts from the moved prediction. Any other mode a user can compute (e.g. a
skull thickness scale) enters the same way (:func:`read_modes`).
"""

from __future__ import annotations

import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from arfi.estimation import wrap
from arfi.simulation import Simulation

#: A typical prior standard deviation of a registration's shift along each axis (mm): head-frame
#: and CT-to-MR registrations of stereotactic and MRgFUS workflows are good to 1-2 mm.
POSE_STD_MM = 1.5

#: A typical prior standard deviation of a registration's turn about each axis (degrees): 1-2.
POSE_STD_DEG = 1.5

#: Prior standard deviation (percent) of the CT conversion's bone sound speed: the porosity
#: model's dense-bone speed is a population constant; individual skulls scatter by about a tenth
#: to a fifth around it.
BONE_SPEED_STD_PERCENT = 20.0

#: Names of the pose modes, in the order of the prediction's rows (shifts along x, y, z, turns
#: about x, y, z through the target).
POSE_NAMES = ("shift_x", "shift_y", "shift_z", "turn_x", "turn_y", "turn_z")


@dataclass
class PriorMode:
    """One error mode of a prediction: ``per_unit_rad`` (rad per element for one ``unit``) and
    its prior standard deviation ``std`` (in ``unit``)."""

    name: str
    unit: str
    per_unit_rad: NDArray[np.float64]
    std: float


@dataclass
class ModesResult:
    """The modes' coefficients fitted to images (:func:`fit_prior_modes`)."""

    modes: list[PriorMode]
    #: Fitted value of each mode in its unit, and its posterior standard deviation.
    values: NDArray[np.float64]
    std: NDArray[np.float64]
    #: The prediction moved by the fitted modes (rad per element, wrapped).
    prior: NDArray[np.float64]
    scale: float
    misfit: float
    misfit_at_zero: float
    n_pixels: int
    iterations: int
    converged: bool
    #: Per mode, whether it ended at the fit's bound (four prior standard deviations out).
    at_bound: list[bool]
    #: The fall of the image chi-squared from the prediction as it is to the fit, and whether it
    #: exceeds the 95 % point of chi-squared with as many degrees of freedom as modes (the images
    #: support moving the prediction).
    evidence: float
    threshold: float
    supported: bool
    seconds: float

    @property
    def prior_moved(self) -> bool:
        """Whether the prediction moves along the modes: where the images support the fit and no
        mode ended at its bound."""
        return self.supported and not any(self.at_bound)

    def value(self, name: str) -> tuple[float, float] | None:
        """The fitted value and standard deviation of the mode ``name``, if fitted."""
        for m, v, s in zip(self.modes, self.values, self.std):
            if m.name == name:
                return float(v), float(s)
        return None

    def pose(self) -> dict[str, list[float]] | None:
        """The fitted pose (``shift_mm``, ``shift_std_mm``, ``turn_deg``, ``turn_std_deg``: x, y,
        z of the transducer frame; the head lies so far off the CT's registration), when the pose
        modes were fitted."""
        found = [self.value(n) for n in POSE_NAMES]
        if any(f is None for f in found):
            return None
        v = [f[0] for f in found if f is not None]
        s = [f[1] for f in found if f is not None]
        return {"shift_mm": v[:3], "shift_std_mm": s[:3], "turn_deg": v[3:], "turn_std_deg": s[3:]}

    def summary_lines(self) -> list[str]:
        """The fit in words: the fitted modes (the registration's pose, the bone speed, a user's)
        and the images' verdict, then whether the prior moves and why not."""
        parts = []
        pose = self.pose()
        if pose is not None:
            tri = lambda v: "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"  # noqa: E731
            std = {m.name: m.std for m in self.modes}
            parts.append(
                f"head shifted {tri(pose['shift_mm'])} +- {tri(pose['shift_std_mm'])} mm and turned "
                f"{tri(pose['turn_deg'])} +- {tri(pose['turn_std_deg'])} deg off the CT's registration (prior "
                f"+-{std['shift_x']:g} mm, +-{std['turn_x']:g} deg)"
            )
        for m, v, s in zip(self.modes, self.values, self.std):
            if pose is not None and m.name in POSE_NAMES:
                continue
            what = "bone speed" if m.name == "bone_speed" else m.name
            tail = " of the conversion's" if m.name == "bone_speed" else ""
            parts.append(f"{what} {v:+.1f} +- {s:.1f} {m.unit}{tail} (prior +-{m.std:g} {m.unit})")
        lines = [
            "prediction's modes from the images on the head with the CT's bone: "
            + "; ".join(parts)
            + f", amplitude scale {self.scale:.3f}, misfit {self.misfit:.2f} ({self.misfit_at_zero:.2f} with the "
            f"prediction as it is) over {self.n_pixels} pixels, {self.iterations} iterations"
            + ("" if self.converged else " (not converged: the iterations ran out or a step failed)")
            + f", the model with bone built and marched in {self.seconds:.1f} s; the images' chi-squared falls by "
            f"{self.evidence:.1f} ({self.threshold:.1f} needed to move the prior: the 95 % point of noise alone, as "
            "many degrees of freedom as modes)"
        ]
        at_edge = [m.name for m, edge in zip(self.modes, self.at_bound) if edge]
        if at_edge:
            lines.append(
                f"PRIOR NOT MOVED: {', '.join(at_edge)} at the fit's end (four prior spreads): check the CT's "
                "conversion and registration against the images (arfi diagnose)"
            )
        elif not self.supported:
            lines.append(
                "PRIOR NOT MOVED: the images do not support it (the modes explain no more of them than as many "
                "free coefficients explain of noise)"
            )
        else:
            lines.append("prior moved along the modes by the fitted values")
        return lines

    def to_dict(self) -> dict[str, Any]:
        """The JSON of ``arfi estimate``'s ``prior_modes_fit``."""
        d: dict[str, Any] = {
            "modes": [
                {
                    "name": m.name,
                    "unit": m.unit,
                    "value": float(v),
                    "std": float(s),
                    "prior_std": m.std,
                    "at_bound": bool(b),
                }
                for m, v, s, b in zip(self.modes, self.values, self.std, self.at_bound)
            ],
            "scale": self.scale,
            "misfit": self.misfit,
            "misfit_at_zero": self.misfit_at_zero,
            "n_pixels": self.n_pixels,
            "iterations": self.iterations,
            "converged": self.converged,
            "evidence_chi2": self.evidence,
            "threshold_chi2": self.threshold,
            "supported": self.supported,
            "prior_moved": self.prior_moved,
            "seconds": self.seconds,
        }
        pose = self.pose()
        if pose is not None:
            d["pose"] = pose
        return d


def prediction_modes(
    prediction: dict[str, Any],
    n_elements: int,
    pose_std_mm: float | None = None,
    pose_std_deg: float | None = None,
    bone_speed_std_percent: float | None = BONE_SPEED_STD_PERCENT,
) -> list[PriorMode]:
    """The modes a prediction's JSON (``arfi predict --json``, or :meth:`Prediction.to_dict`)
    holds: its pose modes (``pose_sensitivity_rad_per_mm``/``_per_deg``) with the priors
    ``pose_std_mm`` and ``pose_std_deg``, and its bone-speed mode
    (``bone_speed_sensitivity_rad_per_percent``) with ``bone_speed_std_percent``. A std of None
    or 0 leaves that kind out (the pose by default: see ``arfi estimate --prior-pose-std-mm``;
    :data:`POSE_STD_MM` and :data:`POSE_STD_DEG` are typical values); a kind the JSON lacks is
    left out. Raises ValueError for malformed values."""
    modes: list[PriorMode] = []
    for key, std, names, unit in (
        ("pose_sensitivity_rad_per_mm", pose_std_mm, POSE_NAMES[:3], "mm"),
        ("pose_sensitivity_rad_per_deg", pose_std_deg, POSE_NAMES[3:], "deg"),
    ):
        if std is not None and not (np.isfinite(std) and std >= 0):
            raise ValueError(f"the prior std of {key}: must be a finite number >= 0, got {std}")
        if not std or key not in prediction:
            continue
        rows = _matrix(prediction[key], key, n_elements)
        if rows.shape[0] != 3:
            raise ValueError(f"{key}: must hold three rows (x, y, z), got {rows.shape[0]}")
        modes += [PriorMode(n, unit, r, float(std)) for n, r in zip(names, rows)]
    key = "bone_speed_sensitivity_rad_per_percent"
    if bone_speed_std_percent is not None and not (np.isfinite(bone_speed_std_percent) and bone_speed_std_percent >= 0):
        raise ValueError(f"the prior std of {key}: must be a finite number >= 0, got {bone_speed_std_percent}")
    if bone_speed_std_percent and key in prediction:
        g = _matrix([prediction[key]], key, n_elements)[0]
        modes.append(PriorMode("bone_speed", "%", g, float(bone_speed_std_percent)))
    return modes


def read_modes(path: str | Path, n_elements: int) -> list[PriorMode]:
    """A user's modes from a NumPy ``.npz`` file: ``modes`` (rad per element for one unit of each
    mode, shape ``(M, n_elements)``), ``std`` (each mode's prior standard deviation in its unit,
    ``M`` values > 0), and optionally ``names`` and ``units`` (``M`` strings each). Raises
    ValueError naming what is wrong."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        loaded = np.load(p, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise ValueError(f"{p}: is a single array, not a NumPy .npz of 'modes' and 'std'")
        with loaded as z:
            if "modes" not in z or "std" not in z:
                raise ValueError(f"{p}: needs arrays 'modes' (M x {n_elements}, rad per unit) and 'std' (M prior stds)")
            rows = _matrix(z["modes"], f"{p}: modes", n_elements)
            std = np.asarray(z["std"], dtype=np.float64).reshape(-1)
            names = [str(n) for n in z["names"]] if "names" in z else [f"mode_{m}" for m in range(len(rows))]
            units = [str(u) for u in z["units"]] if "units" in z else ["unit"] * len(rows)
    except (OSError, ValueError, TypeError, zipfile.BadZipFile, EOFError) as e:
        raise ValueError(str(e) if str(p) in str(e) else f"{p}: not a NumPy .npz of modes ({e})") from None
    if std.shape != (len(rows),) or not np.all(np.isfinite(std)) or np.any(std <= 0):
        raise ValueError(
            f"{p}: 'std' must hold {len(rows)} finite numbers > 0 (one prior std per mode), got {std.tolist()}"
        )
    if len(names) != len(rows) or len(units) != len(rows):
        raise ValueError(f"{p}: 'names' and 'units' must hold one string per mode ({len(rows)})")
    return [PriorMode(n, u, r, float(s)) for n, u, r, s in zip(names, units, rows, std)]


def _matrix(values: Any, name: str, n_elements: int) -> NDArray[np.float64]:
    """``values`` as a finite ``(M, n_elements)`` float64 array, or ValueError naming ``name``."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (ValueError, TypeError):
        raise ValueError(f"{name}: must be numbers") from None
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] != n_elements:
        raise ValueError(
            f"{name}: must hold {n_elements} finite numbers per row (one per element), got shape {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return a


def fit_prior_modes(
    skull: Simulation,
    images: list[NDArray[np.float64]],
    known: list[NDArray[np.float64] | None],
    prior: NDArray[np.float64],
    modes: list[PriorMode],
    noise_rad: float | None = None,
) -> ModesResult:
    """Fits the coefficients of ``modes`` to ``images`` (each with its ``known`` phases) on
    ``skull``, the head with the CT's bone driven with the reference steering
    (``Simulation(scenario.with_ct_bone())``), and moves ``prior`` (the prediction, rad per
    element) by them: see the module docs. ``supported`` says whether the images support the move
    (a likelihood-ratio test); the caller keeps the prediction unmoved where they do not.
    ``noise_rad``: the images' noise where it is known (default: their background floor)."""
    if not modes:
        raise ValueError("modes: none to fit")
    if len(prior) != skull.n_elements:
        raise ValueError(f"prior: has {len(prior)} values for {skull.n_elements} elements")
    t = time.perf_counter()
    scaled = np.stack([m.std * m.per_unit_rad for m in modes])
    fit = skull.fit_modes(images, known, scaled, noise_rad=noise_rad)
    coefficients = np.asarray(fit.coefficients)
    prior_std = np.array([m.std for m in modes])
    moved = wrap(prior + coefficients @ scaled)
    return ModesResult(
        modes=modes,
        values=coefficients * prior_std,
        std=np.asarray(fit.std) * prior_std,
        prior=moved,
        scale=fit.scale,
        misfit=fit.misfit,
        misfit_at_zero=fit.misfit_at_zero,
        n_pixels=fit.n_pixels,
        iterations=fit.iterations,
        converged=fit.converged,
        at_bound=list(fit.at_bound),
        evidence=fit.evidence,
        threshold=fit.threshold,
        supported=fit.supported,
        seconds=time.perf_counter() - t,
    )
