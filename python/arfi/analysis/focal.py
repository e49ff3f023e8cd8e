"""The focal region in words. The focal peak, its metrics and the hottest places themselves are
found in the core (``Field.focus()``, ``Simulation.focal_metrics``): the local maximum of |p|
reached by climbing from the target's sample, and the hottest sample outside its -6 dB lobe when
that is hotter; ``Simulation.tissue_classes`` names the tissue a place lies in.
"""

from __future__ import annotations

from arfi._core import FocalMetrics


def metrics_text(m: FocalMetrics) -> str:
    """The focal region in 3-D in words: its peak, extents and volume, and the exposure there
    (``Simulation.focal_metrics``, ``Section.focal_metrics`` or ``Field.focal_metrics``)."""
    if m.focal_peak_mm is None or m.fwhm_6db_mm is None:
        return "no closed -6 dB focal region around the target inside the grid (no focal metrics)"
    p = [round(v, 2) + 0.0 for v in m.focal_peak_mm]  # + 0.0: no "-0.00" for a peak on the axis
    along, across = m.fwhm_6db_mm
    return (
        f"focus in 3-D: {(m.focal_peak_pa or 0.0) / 1e6:.3f} MPa at ({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}) mm, "
        f"{m.peak_to_target_mm:.2f} mm from the target; -6 dB {along:.2f} mm along the beam x {across:.2f} mm "
        f"across, {m.focal_volume_6db_mm3:.1f} mm³; in {m.focal_tissue}: I_SPPA {m.isppa_w_cm2:.1f} W/cm², MI "
        f"{m.mechanical_index:.2f}"
    )
