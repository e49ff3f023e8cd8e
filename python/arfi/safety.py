"""Safety lines a user sets: exposure limits checked at the focal peak and at the hottest place of
each tissue class (skull, scalp, brain, water …) over the whole grid.

The defaults are the common guidance for diagnostic ultrasound (FDA, Track 3): a mechanical index
of 1.9 and a spatial-peak pulse-average intensity of 190 W/cm². Therapy and MR-ARFI pulses may be
meant to exceed them; the check says where and by how much, it does not judge the plan.
The mechanical index is in situ, ``p[MPa] / sqrt(f[MHz])`` of the simulated (not derated)
pressure amplitude; I_SPPA is ``p² / (2·rho·c)`` with the tissue's rho and c.
"""

from __future__ import annotations

import math
from typing import Any

#: Default limit of the mechanical index.
MI_LIMIT = 1.9
#: Default limit of I_SPPA (W/cm²).
ISPPA_LIMIT_W_CM2 = 190.0


def check_limit(value: float, name: str) -> float:
    """``value`` if it is a positive finite number, else a ``ValueError`` naming ``name``."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: must be a positive number, got {value}")
    return float(value)


def exceeded(
    focus: Any, mi_limit: float = MI_LIMIT, isppa_limit_w_cm2: float = ISPPA_LIMIT_W_CM2
) -> list[dict[str, Any]]:
    """The exposures above the limits, one entry each (``where``, ``tissue``, ``quantity``,
    ``value``, ``limit``): the mechanical index and I_SPPA at the focal peak
    (``focus.focal_metrics``), and at the hottest place of each tissue class (``focus.hottest``)
    unless that place is the focus itself (``is_focus``). ``focus`` is ``Field.focus()``."""
    mi_limit = check_limit(mi_limit, "mi_limit")
    isppa_limit_w_cm2 = check_limit(isppa_limit_w_cm2, "isppa_limit_w_cm2")
    rows: list[dict[str, Any]] = []

    def flag(where: str, tissue: str | None, exposure: Any) -> None:
        for quantity, limit in (("mechanical_index", mi_limit), ("isppa_w_cm2", isppa_limit_w_cm2)):
            value = getattr(exposure, quantity)
            if value > limit:
                rows.append({"where": where, "tissue": tissue, "quantity": quantity, "value": value, "limit": limit})

    m = focus.focal_metrics
    if m.focal_peak_pa is not None:
        flag("focal peak", m.focal_tissue, m)
    for tissue, h in (focus.hottest or {}).items():
        if not h.is_focus:
            flag("hottest place", tissue, h)
    return rows


def summary(rows: list[dict[str, Any]]) -> str:
    """One line naming each exposure above its limit (``rows`` from :func:`exceeded`, not empty)."""
    name = {"mechanical_index": "MI", "isppa_w_cm2": "I_SPPA"}
    value = {"mechanical_index": "{:.2f}", "isppa_w_cm2": "{:.1f} W/cm²"}
    parts = [
        f"{name[r['quantity']]} {value[r['quantity']].format(r['value'])} at the {r['where']} ({r['tissue']}) > "
        f"{r['limit']:g}"
        for r in rows
    ]
    return "above the safety lines: " + "; ".join(parts)
