"""Safety lines a user sets: exposure limits checked at the focal peak and at the hottest place of
each tissue class (skull, scalp, brain, water …) over the whole grid.

The defaults are the common guidance for diagnostic ultrasound (FDA, Track 3): a mechanical index
of 1.9 and a spatial-peak pulse-average intensity of 190 W/cm². Therapy and MR-ARFI pulses may be
meant to exceed them; the check says where and by how much, it does not judge the plan.
The mechanical index is in situ, ``p[MPa] / sqrt(f[MHz])`` of the simulated (not derated)
pressure amplitude; I_SPPA is ``p² / (2·rho·c)`` with the tissue's rho and c.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

#: Default limit of the mechanical index.
MI_LIMIT = 1.9
#: Default limit of I_SPPA (W/cm²).
ISPPA_LIMIT_W_CM2 = 190.0


@dataclasses.dataclass(frozen=True)
class Exceedance:
    """One exposure above its limit: ``quantity`` (``"mechanical_index"`` or ``"isppa_w_cm2"``)
    of ``value`` above ``limit`` at ``where`` (``"focal peak"`` or ``"hottest place"``) in
    ``tissue``."""

    where: Literal["focal peak", "hottest place"]
    tissue: str | None
    quantity: Literal["mechanical_index", "isppa_w_cm2"]
    value: float
    limit: float

    def to_dict(self) -> dict[str, Any]:
        """The JSON entry: the field names as keys."""
        return dataclasses.asdict(self)

    def text(self) -> str:
        """``MI 2.12 at the hottest place (skull) > 1.9``."""
        if self.quantity == "mechanical_index":
            shown = f"MI {self.value:.2f}"
        else:
            shown = f"I_SPPA {self.value:.1f} W/cm²"
        return f"{shown} at the {self.where} ({self.tissue}) > {self.limit:g}"


def check_limit(value: float, name: str) -> float:
    """``value`` if it is a positive finite number, else a ``ValueError`` naming ``name``."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: must be a positive number, got {value}")
    return float(value)


def exceeded(focus: Any, mi_limit: float = MI_LIMIT, isppa_limit_w_cm2: float = ISPPA_LIMIT_W_CM2) -> list[Exceedance]:
    """The exposures above the limits, one :class:`Exceedance` each: the mechanical index and I_SPPA at the focal peak
    (``focus.focal_metrics``), and at the hottest place of each tissue class (``focus.hottest``)
    unless that place is the focus itself (``is_focus``). ``focus`` is ``Field.focus()``."""
    mi_limit = check_limit(mi_limit, "mi_limit")
    isppa_limit_w_cm2 = check_limit(isppa_limit_w_cm2, "isppa_limit_w_cm2")
    rows: list[Exceedance] = []
    limits: tuple[tuple[Literal["mechanical_index", "isppa_w_cm2"], float], ...] = (
        ("mechanical_index", mi_limit),
        ("isppa_w_cm2", isppa_limit_w_cm2),
    )

    def flag(where: Literal["focal peak", "hottest place"], tissue: str | None, exposure: Any) -> None:
        for quantity, limit in limits:
            value = float(getattr(exposure, quantity))
            if value > limit:
                rows.append(Exceedance(where, tissue, quantity, value, limit))

    m = focus.focal_metrics
    if m.focal_peak_pa is not None:
        flag("focal peak", m.focal_tissue, m)
    for tissue, h in (focus.hottest or {}).items():
        if not h.is_focus:
            flag("hottest place", tissue, h)
    return rows


def summary(rows: list[Exceedance]) -> str:
    """One line naming each exposure above its limit (``rows`` from :func:`exceeded`, not empty)."""
    return "above the safety lines: " + "; ".join(r.text() for r in rows)
