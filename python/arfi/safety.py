"""Safety lines a user sets: exposure limits checked at the focal peak and at the hotter places
``arfi field`` names.

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


def exceeded(focus: dict[str, Any], frequency_hz: float, mi_limit: float = MI_LIMIT,
             isppa_limit_w_cm2: float = ISPPA_LIMIT_W_CM2) -> list[dict[str, Any]]:
    """The exposures above the limits, one entry each (``where``, ``tissue``, ``quantity``,
    ``value``, ``limit``): the mechanical index and I_SPPA at the focal peak, and the mechanical
    index at the hottest place on the plane and on the axis when those are hotter than the focus.
    ``focus`` is ``Field.focus()`` with the hottest places' ``*_hottest_tissue`` added."""
    mi_limit = check_limit(mi_limit, "mi_limit")
    isppa_limit_w_cm2 = check_limit(isppa_limit_w_cm2, "isppa_limit_w_cm2")
    rows: list[dict[str, Any]] = []

    def flag(where: str, tissue: str | None, quantity: str, value: float, limit: float) -> None:
        if value > limit:
            rows.append({"where": where, "tissue": tissue, "quantity": quantity, "value": value, "limit": limit})

    if focus.get("focal_peak_pa") is not None:
        flag("focal peak", focus["focal_tissue"], "mechanical_index", focus["mechanical_index"], mi_limit)
        flag("focal peak", focus["focal_tissue"], "isppa_w_cm2", focus["isppa_w_cm2"], isppa_limit_w_cm2)
    for key in ("plane", "axis"):
        pa = focus.get(f"{key}_hottest_pa")
        if pa is not None:
            mi = pa / 1e6 / math.sqrt(frequency_hz / 1e6)
            flag(f"hottest on the {key}", focus.get(f"{key}_hottest_tissue"), "mechanical_index", mi, mi_limit)
    return rows


def summary(rows: list[dict[str, Any]]) -> str:
    """One line naming each exposure above its limit (``rows`` from :func:`exceeded`, not empty)."""
    name = {"mechanical_index": "MI", "isppa_w_cm2": "I_SPPA"}
    value = {"mechanical_index": "{:.2f}", "isppa_w_cm2": "{:.1f} W/cm²"}
    parts = [f"{name[r['quantity']]} {value[r['quantity']].format(r['value'])} at the {r['where']} ({r['tissue']}) > {r['limit']:g}"
             for r in rows]
    return "above the safety lines: " + "; ".join(parts)
