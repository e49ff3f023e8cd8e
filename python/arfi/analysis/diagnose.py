"""Results of the model-discrepancy workflow (``arfi diagnose``): the effect library and the
typed outcome (its report: :mod:`arfi.reports.diagnose`)."""

from __future__ import annotations

from arfi import _core

_effects, _parameters = _core.effect_library()

#: The effect library, in the order ties are broken (simpler first); from the Rust core's table.
EFFECTS: tuple[str, ...] = tuple(_effects)

#: Every parameter name ``diagnose`` reports and ``Simulation.effect_images`` accepts (units in
#: the name), with its effect and meaning: ``{name: (effect, meaning)}``.
PARAMETERS: dict[str, tuple[str, str]] = {name: (effect, meaning) for name, effect, meaning in _parameters}


#: The outcome of ``Simulation.diagnose``: the effects added, in order, and the gap before and after
#: (the extension's typed result; ``to_dict()`` is the JSON of ``arfi diagnose``).
Diagnosis = _core.Diagnosis
