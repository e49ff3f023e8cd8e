"""Scenario files: TOML, every key optional with the paper's phantom experiment as defaults, unknown
keys an error."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from arfi import _core
from arfi.io.files import atomic_write_text


class Scenario:
    """A validated scenario. Values are kept in file units (mm, Hz, dB/cm/MHz).

    Build one with :meth:`default`, :meth:`load`, :meth:`from_toml` or :meth:`from_dict`;
    unknown keys and invalid values raise ``ValueError`` naming the key.
    """

    def __init__(self, toml_text: str, base_dir: str | os.PathLike[str] | None = None):
        self._core = _core.CoreScenario(toml_text, "toml", None if base_dir is None else str(base_dir))

    @classmethod
    def default(cls) -> Scenario:
        """The embedded default: the paper's phantom experiment (550 kHz planar quadrant array of
        1024 elements focused at (0, 0, 85) mm into a cylindrical phantom in water)."""
        return cls._of(_core.CoreScenario.default())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Scenario:
        """Reads a TOML scenario file; relative paths inside resolve against its folder."""
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"scenario: {p}: no such file")
        try:
            text = p.read_text(encoding="utf-8")
        except UnicodeDecodeError as e:
            raise ValueError(f"scenario: {p}: not UTF-8 text ({e.reason})") from None
        try:
            return cls(text, p.resolve().parent)
        except ValueError as e:
            raise ValueError(f"scenario file {p}: {e}") from None

    @classmethod
    def from_toml(cls, text: str, base_dir: str | os.PathLike[str] | None = None) -> Scenario:
        """Parses TOML text."""
        return cls(text, base_dir)

    @classmethod
    def from_dict(cls, data: dict[str, Any], base_dir: str | os.PathLike[str] | None = None) -> Scenario:
        """Builds a scenario from a dict with the file's keys (e.g. from :meth:`to_dict`)."""
        try:
            text = json.dumps(data, allow_nan=False)
        except (TypeError, ValueError) as e:
            raise ValueError(f"scenario: cannot be written as JSON: {e}") from None
        return cls._of(_core.CoreScenario(text, "json", None if base_dir is None else str(base_dir)))

    @classmethod
    def _of(cls, core: _core.CoreScenario) -> Scenario:
        """The scenario the core holds (already checked: not parsed again)."""
        s = cls.__new__(cls)
        s._core = core
        return s

    def to_toml(self, chosen_grid: bool = False) -> str:
        """The scenario as TOML with every default written out. With ``chosen_grid``, the
        ``[grid]`` the simulation resolves it to is written out too (spacing, step, lateral size,
        last plane, absorbing layer, reflections, interface model): a template that simulates
        exactly as this scenario does; delete those keys to have them chosen from the wavelength,
        the aperture and the focus again after editing."""
        return self._core.to_toml(bool(chosen_grid))

    def to_dict(self) -> dict[str, Any]:
        """The scenario as a dict with every default written out."""
        return dict(json.loads(self._core.to_json()))

    def with_ct_bone(self) -> Scenario:
        """The head of this ``[ct]`` scenario with the CT's bone (``without_bone = false``) driven
        with the reference steering (``steer_without_bone = true``): the skull ``arfi predict``
        marches, steered as the estimation's model (``without_bone = true``) is. A scenario
        without ``[ct]`` raises ``ValueError``."""
        return Scenario._of(self._core.with_ct_bone())

    def outline(self) -> _core.ScenarioOutline:
        """What the scenario fixes before a simulation is built: the array's elements and default
        groups, the focus and the MR geometry, with the simulation's own rules for phases
        (``element_phases``, ``known_per_element``) and image files (``check_image``). Read in
        milliseconds (no CT, no grid), so inputs are refused before a build of tens of seconds."""
        return self._core.outline()

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the TOML (atomically: a failed write leaves no partial file)."""
        atomic_write_text(Path(path), self.to_toml())

    @property
    def name(self) -> str:
        return self._core.name

    @property
    def base_dir(self) -> str | None:
        return self._core.base_dir

    @property
    def core(self) -> _core.CoreScenario:
        """The checked scenario as the core holds it (what simulations and predictions take)."""
        return self._core

    def __repr__(self) -> str:
        return f"Scenario(name={self.name!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Scenario) and self.to_toml() == other.to_toml()

    def __hash__(self) -> int:
        return hash(self.to_toml())

    def __reduce__(self) -> tuple[Any, ...]:
        # Pickled as its text and folder (the core's value is rebuilt, and checked, on load).
        return (Scenario, (self.to_toml(), self.base_dir))
