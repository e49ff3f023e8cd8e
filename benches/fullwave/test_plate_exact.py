"""Checks of plate_exact.py (fast: < 2 s)."""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import plate_exact as pe  # noqa: E402

F = 500e3
W = 2 * np.pi * F
D = 6.5e-3
RHO_W, C_W = 1000.0, 1500.0
RHO_B, CP, CS = 1850.0, 2800.0, 1500.0
TH = np.deg2rad(np.linspace(0, 89.9, 2000))
KX = W / C_W * np.sin(TH)


def test_energy_conservation_lossless():
    for cs in (1500.0, 1300.0, 1700.0, 600.0, 2500.0):
        for d in (D, 1e-3, 20e-3):
            R, T = pe.solid_layer_RT(F, KX, d, RHO_W, C_W, RHO_B, CP, cs, RHO_W, C_W)
            err = np.abs(np.abs(R) ** 2 + np.abs(T) ** 2 - 1)
            assert err.max() < 1e-10, (cs, d, err.max())


def test_energy_different_fluids_lossless():
    # fluid 3 different: energy flux ratio uses Re(kz3/rho3) / (kz1/rho1) on |T|^2
    rho3, c3 = 1200.0, 1700.0
    th = np.deg2rad(np.linspace(0, 60, 500))  # below the fluid-3 critical angle (61.9 deg)
    kx = W / C_W * np.sin(th)
    R, T = pe.solid_layer_RT(F, kx, D, RHO_W, C_W, RHO_B, CP, CS, rho3, c3)
    kz1 = pe.kz_branch(W / C_W, kx)
    kz3 = pe.kz_branch(W / c3, kx)
    flux = np.abs(R) ** 2 + np.abs(T) ** 2 * (kz3.real / rho3) / (kz1.real / RHO_W) * (RHO_W / rho3) ** 0
    # pressure T: intensity ~ |p|^2 kz / (rho omega); ratio = |T|^2 (kz3/rho3)/(kz1/rho1)
    assert np.abs(flux - 1).max() < 1e-10


def test_shear_to_zero_gives_fluid_layer():
    Rf, Tf = pe.fluid_layer_RT(F, KX, D, RHO_W, C_W, RHO_B, CP, RHO_W, C_W)
    errs = []
    for cs in (10.0, 1.0, 0.1):
        R, T = pe.solid_layer_RT(
            F, KX, D, RHO_W, C_W, RHO_B, CP, cs, RHO_W, C_W, alpha_s_np_m=1.0
        )  # a little shear loss, as a limit
        errs.append(max(np.abs(T - Tf).max(), np.abs(R - Rf).max()))
    # converges like mu ~ cs^2
    assert errs[-1] < 1e-5, errs
    assert errs[0] > errs[1] > errs[2]


def test_fluid_layer_formula_against_normal_incidence():
    # normal incidence: T = 2 / (2 cos kd - i (Z2/Z1 + Z1/Z2) sin kd)
    k2 = W / CP
    z = RHO_B * CP / (RHO_W * C_W)
    T0 = 2 / (2 * np.cos(k2 * D) - 1j * (z + 1 / z) * np.sin(k2 * D))
    _, T = pe.fluid_layer_RT(F, np.array([0.0]), D, RHO_W, C_W, RHO_B, CP, RHO_W, C_W)
    assert abs(T[0] - T0) < 1e-12


def test_thick_lossy_layer_first_face_is_halfspace():
    ap = pe.alpha_np_per_m(4.0)
    as_ = pe.alpha_np_per_m(4.0)
    th = np.deg2rad(np.linspace(0, 89, 500))  # before, between and beyond both critical angles
    kx = W / C_W * np.sin(th)
    for cs in (1500.0, 1300.0, 2000.0):
        R, T = pe.solid_layer_RT(F, kx, 0.6, RHO_W, C_W, RHO_B, CP, cs, RHO_W, C_W, ap, as_)
        Rh = pe.halfspace_R(F, kx, RHO_W, C_W, RHO_B, CP, cs, ap, as_)
        assert np.abs(R - Rh).max() < 1e-10
        assert np.abs(T).max() < 1e-10


def test_halfspace_lossless_total_reflection_beyond_critical():
    # cs = 2000 > c_w: beyond both critical angles (32.4 and 48.6 deg) |R| = 1
    th = np.deg2rad(np.linspace(49, 89, 100))
    kx = W / C_W * np.sin(th)
    Rh = pe.halfspace_R(F, kx, RHO_W, C_W, RHO_B, CP, 2000.0)
    assert np.abs(np.abs(Rh) - 1).max() < 1e-12


def _peaks_T(rho_f, cs, th):
    kx = W / C_W * np.sin(th)
    _, T = pe.solid_layer_RT(F, kx, D, rho_f, C_W, RHO_B, CP, cs, rho_f, C_W)
    return np.abs(T)


def test_total_transmission_at_lamb_modes():
    """|T| = 1 (lossless, same fluid) where c_w / sin(theta) is a leaky Lamb mode's
    phase velocity.  With a light fluid (rho_f = 1 kg/m^3, fluid-loading parameter
    rho_f c_w / (rho_b c_p) ~ 3e-4) the peaks are exactly at the free-plate
    Rayleigh-Lamb velocities within 0.02 % in phase velocity, and |T| = 1 to 1e-9
    at the peak.  Under water (loading ~ 0.29) the peaks stay |T| = 1 (no loss) but
    move: we accept 6 % in phase velocity, a tolerance of the order of the loading
    parameter's effect (the leaky modes' real part shifts by O(loading))."""
    cs = 1500.0
    modes = pe.lamb_phase_velocities(F, D, CP, cs, C_W / np.sin(np.deg2rad(80)), 1e5)
    cl = np.concatenate([modes["S"], modes["A"]])
    assert cl.size >= 3, modes
    for rho_f, rel_tol in ((1.0, 2e-4), (RHO_W, 0.06)):
        for c in cl:
            th0 = np.arcsin(C_W / c)
            # search the |T| maximum within +-rel_tol in phase velocity
            c_grid = c * (1 + np.linspace(-rel_tol, rel_tol, 4001))
            c_grid = c_grid[c_grid > C_W]
            th = np.arcsin(C_W / c_grid)
            t = _peaks_T(rho_f, cs, th)
            i = np.argmax(t)
            # refine with golden section on |T|
            a, b = th[max(i - 1, 0)], th[min(i + 1, th.size - 1)]
            for _ in range(80):
                m1, m2 = a + 0.382 * (b - a), a + 0.618 * (b - a)
                if _peaks_T(rho_f, cs, np.array([m1]))[0] > _peaks_T(rho_f, cs, np.array([m2]))[0]:
                    b = m2
                else:
                    a = m1
            tmax = _peaks_T(rho_f, cs, np.array([0.5 * (a + b)]))[0]
            assert abs(tmax - 1) < 1e-8, (rho_f, c, np.rad2deg(th0), tmax)


def test_lamb_roots_are_roots():
    modes = pe.lamb_phase_velocities(F, D, CP, CS, 1600.0, 1e5)
    for j, name in enumerate(("S", "A")):
        for c in modes[name]:
            lo = pe.rayleigh_lamb(F, c * (1 - 1e-9), D, CP, CS)[j]
            hi = pe.rayleigh_lamb(F, c * (1 + 1e-9), D, CP, CS)[j]
            assert lo * hi <= 0
