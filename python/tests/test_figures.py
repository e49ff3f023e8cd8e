"""The report figures read at a glance: the beam visible where it is weak, the target circled
without hiding the focus, phases near 0 visible on their ground."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib
import numpy as np

from arfi.reports.figures import BEAM_FLOOR, BEAM_OPAQUE, beam_rgba, element_map, pyplot, section_figure


def test_the_beam_fades_with_its_amplitude_instead_of_vanishing_below_a_threshold() -> None:
    f = np.linspace(0.0, 1.2, 241)
    rgba = beam_rgba(f * 2.0, 2.0)
    alpha = rgba[:, 3]
    # Opacity never falls as |p| grows; clear below the floor, opaque from BEAM_OPAQUE up.
    assert np.all(np.diff(alpha) >= 0.0)
    assert np.all(alpha[f < BEAM_FLOOR] == 0.0) and np.all(alpha[f >= BEAM_OPAQUE] == 1.0)
    # A converging beam at 5 % of the focal peak (in the brain, before the focus) is drawn at
    # about 40 % opacity, where a 10 % mask hid it.
    assert 0.35 < alpha[np.argmin(np.abs(f - 0.05))] < 0.45
    # The colours are the colour bar's (inferno 0..vmax), saturating above it.
    np.testing.assert_allclose(rgba[-1, :3], matplotlib.colormaps["inferno"](1.0)[:3])
    np.testing.assert_allclose(rgba[100, :3], matplotlib.colormaps["inferno"](0.5)[:3])
    assert np.all(beam_rgba(np.array([np.nan]), 1.0)[:, 3] == 0.0)
    # A field without pressure (a scale of 0) draws nothing rather than NaN.
    assert np.all(beam_rgba(np.zeros(3), 0.0)[:, 3] == 0.0)


def test_sections_circle_the_target_and_phase_maps_have_a_grey_ground() -> None:
    x = np.linspace(-20.0, 20.0, 81)
    z = np.linspace(0.0, 60.0, 121)
    focus = np.exp(-((x[None, :] - 3.0) ** 2 + (z[:, None] - 40.0) ** 2) / 4.0) * 1e6
    section = SimpleNamespace(
        x_mm=x, z_mm=z, y_mm=0.0, pressure=np.stack([focus, 0.5 * focus]), sound_speed_m_s=np.full(focus.shape, 1500.0)
    )
    fig = section_figure(section, ["a", "b"], [3.0, 0.0, 40.0])
    for ax in fig.axes[:2]:
        circles = [ln for ln in ax.lines if ln.get_marker() == "o"]
        assert len(circles) == 1 and circles[0].get_mfc() == "none"
        assert (circles[0].get_xdata()[0], circles[0].get_ydata()[0]) == (3.0, 40.0)
    pyplot().close(fig)

    fig, ax = pyplot().subplots()
    sim = SimpleNamespace(element_phases=lambda p: p, element_positions_mm=np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]]))
    element_map(fig, ax, sim, np.array([0.0, 1.0]), "phases")
    # twilight_shifted draws 0 rad near white: the ground must not be white.
    assert matplotlib.colors.to_rgb(ax.get_facecolor()) == (0.55, 0.55, 0.55)
    pyplot().close(fig)
