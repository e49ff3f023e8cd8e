"""What every verb of the command line shares: usage errors, the common options, reading the
scenario, phase vectors and MR-ARFI images, the calibrated simulation, writing results."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from arfi import _core
from arfi.estimation import METHODS, Calibration
from arfi.io.files import read_arfi_image, read_phases, write_json
from arfi.scenario import Scenario
from arfi.simulation import Simulation


class UsageError(Exception):
    """Bad command-line input: reported as one line, exit 2."""


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit 2 (argparse prints usage too)."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message}")


def add_common(p: argparse.ArgumentParser) -> None:
    """The options every verb takes."""
    p.add_argument("--scenario", metavar="FILE", help="scenario TOML (default: the embedded phantom experiment)")
    p.add_argument("--json", metavar="FILE", help="write machine-readable results to FILE")


def add_calibration(p: argparse.ArgumentParser) -> None:
    """``--calibration``, read by :func:`calibrated_simulation`."""
    p.add_argument(
        "--calibration", metavar="CAL.json", help="output of arfi calibrate (default: the scenario's W and amplitude)"
    )


def add_method(p: argparse.ArgumentParser, default: str, help: str) -> None:
    """``--method``: one of the estimators of ``Simulation.estimate``."""
    p.add_argument("--method", choices=METHODS, default=default, help=help)


def add_report(p: argparse.ArgumentParser, figures: str) -> None:
    """``--report DIR``: ``figures`` (what the verb draws) and report.html."""
    p.add_argument("--report", metavar="DIR", help=f"write {figures} and report.html to DIR")


def load_scenario(args: argparse.Namespace) -> Scenario:
    """The ``--scenario`` file, or the embedded default."""
    return Scenario.load(args.scenario) if args.scenario else Scenario.default()


def read_optional_phases(path: str | None, name: str) -> np.ndarray | None:
    """A phase vector file given as option ``name``, or None."""
    return None if path is None else read_phases(path, name)


def prediction_json(path: str, option: str) -> dict[str, Any]:
    """The JSON of ``arfi predict`` given as ``option``, as a dict: FileNotFoundError when there is
    no such file, UsageError (naming the option) when it is not a JSON object."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{option}: {p}: no such file")
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except ValueError as e:
        raise UsageError(f"{option}: {p}: not the JSON of arfi predict ({e})") from None
    if not isinstance(d, dict):
        raise UsageError(f"{option}: {p}: not the JSON of arfi predict (not an object)")
    return d


def finish(args: argparse.Namespace, result: dict[str, Any]) -> None:
    """Writes ``--json`` when asked."""
    if args.json:
        write_json(args.json, result)


def image_peak(sim: Simulation, image: np.ndarray) -> tuple[float, list[float]]:
    """The focal ARFI of an image (its largest imaged pixel near the target) and that pixel's
    centre (mm, transducer frame)."""
    value, idx = sim.focal_arfi(image)
    vox = np.zeros(3)
    shape = sim.mr_volume_shape
    axes = [a for a in range(3) if shape[a] != 1]
    for a, i in zip(axes, idx):
        vox[a] = i
    pos = sim.mr_affine_mm @ np.append(vox, 1.0)
    return float(value), [float(v) for v in pos[:3]]


def read_checked_phases(
    outline: _core.ScenarioOutline, path: str | None, option: str, groups: int | None = None
) -> np.ndarray | None:
    """A phase vector file given as ``option`` (or None), checked against the scenario's outline
    before anything is built: one value per element or per group (``groups`` contiguous groups,
    or the array's default ones), errors naming the option and the file."""
    values = read_optional_phases(path, option)
    if values is not None:
        outline.element_phases(values, f"{option}: {path}", groups)
    return values


def read_image(
    outline: _core.ScenarioOutline, path: str, groups: int | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """An MR-ARFI image given as ``--image``, checked against the scenario's MR geometry, and
    its known phases (one per element, per group or per default group), by the simulation's own
    rules but before anything is built."""
    image, affine, side = read_arfi_image(path)
    if image.ndim != 2:
        raise ValueError(f"--image: {path}: an MR-ARFI image is one slice, got shape {image.shape}")
    outline.check_image(image.shape, np.asarray(affine, dtype=np.float64), f"--image: {path}")
    known = side.get("applied_phases_rad")
    if known is not None:
        try:
            known = np.asarray(known, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"sidecar of {path}: applied_phases_rad must be a list of numbers") from None
        if known.ndim != 1:
            raise ValueError(f"sidecar of {path}: applied_phases_rad must be a list of numbers")
        outline.known_per_element(known, f"sidecar of {path}: applied_phases_rad", groups)
    return image, known


def estimate_options(**values: Any) -> _core.EstimateOptions:
    """The estimate's options from the command line's values, checked by the library's rules
    before any model is built; an error names the option as typed (``--prior-std-rad: ...``)."""
    try:
        return _core.EstimateOptions(**values)
    except ValueError as e:
        name, sep, reason = str(e).partition(":")
        if sep and name in _core.EstimateOptions._fields:
            raise UsageError(f"--{name.replace('_', '-')}:{reason}") from None
        raise


def read_calibration(args: argparse.Namespace) -> Calibration | None:
    """The ``--calibration`` file, if given (errors name the option)."""
    path = getattr(args, "calibration", None)
    try:
        return Calibration.load(path) if path else None
    except (FileNotFoundError, ValueError) as e:
        raise type(e)(f"--calibration: {e}") from None


def calibrated_simulation(
    args: argparse.Namespace, scenario: Scenario | None = None, source: _core.CoreSourceModel | None = None
) -> Simulation:
    """The simulation of ``scenario`` (default: the ``--scenario``), with the calibration file
    applied when given; ``source`` as :class:`Simulation` takes it."""
    scenario = scenario or load_scenario(args)
    cal = read_calibration(args)
    if cal is not None:  # before the simulation is built
        scenario.outline().check_calibration(cal, f"--calibration: {args.calibration}")
    sim = Simulation(scenario, groups=getattr(args, "groups", None), source=source)
    return sim if cal is None else sim.calibrated(cal)


def npy_path(path: str, option: str) -> str:
    """``path``, given as ``option``, if it names a .npy file: check it before computing what
    :func:`save_npy` will write there."""
    if not path.endswith(".npy"):
        raise UsageError(f"{option}: {path}: phase vectors are written as .npy")
    return path


def save_npy(path: str, array: np.ndarray) -> None:
    """Writes a .npy file atomically (``path`` checked with :func:`npy_path`)."""
    from arfi.io.files import atomic_path

    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, array)
