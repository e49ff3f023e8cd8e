"""Exact plane-wave transmission through a fluid | viscoelastic solid | fluid layer.

Written from first principles (Brekhovskikh, *Waves in Layered Media*, ch. 1-4;
global-matrix formulation of Schmidt & Jensen / Lowe 1995), NumPy only.

Conventions
-----------
* Time dependence exp(-i omega t); a plane wave is exp(i (kx x + kz z - omega t)).
  z points down: fluid 1 (z < 0) | solid 0 <= z <= d | fluid 3 (z > d).
* Loss: complex wavenumber k = omega / c + i alpha, alpha in Np/m (> 0), so that
  a wave travelling in +z decays.  Complex moduli follow:  M = rho (omega / k)^2.
* Vertical wavenumber kz = sqrt(k^2 - kx^2) on the branch Im kz >= 0 (and
  Re kz >= 0 when Im kz = 0): down-going waves (exp(+i kz z)) decay or are
  evanescent with depth, and up-going (exp(-i kz z)) decay upwards.  This is the
  physical branch beyond the critical angles (inhomogeneous waves).
* Fluids: u = grad(phi), p = rho omega^2 phi.  Solid (2-D plane strain, P-SV):
  u = grad(phi) + curl(psi e_y): u_x = phi_x - psi_z, u_z = phi_z + psi_x.
* Numerical stability: in the layer, down-going waves are referenced at z = 0 and
  up-going ones at z = d, so every exponential in the 6x6 system has modulus <= 1
  (no overflow for thick, lossy or evanescent layers).
* Outputs (pressure ratios, all reverberations included):
    R = p_reflected(z=0) / p_incident(z=0)
    T = p_transmitted(z=d) / p_incident(z=0)
  The insertion transmission (what replacing water by the plate does to the field
  on a plane behind it) is T * exp(-i kz_water d), see `insertion_T`.
  For the same fluid on both sides and no loss, |R|^2 + |T|^2 = 1.
"""

from __future__ import annotations

import numpy as np

DB_PER_NEPER = 20.0 / np.log(10.0)  # 8.6859 dB per Np


def alpha_np_per_m(db_per_cm: float) -> float:
    """Amplitude attenuation in Np/m from dB/cm."""
    return db_per_cm * 100.0 / DB_PER_NEPER


def kz_branch(k: np.ndarray, kx: np.ndarray) -> np.ndarray:
    """sqrt(k^2 - kx^2) with Im >= 0 (Re >= 0 if Im == 0)."""
    kz = np.sqrt(np.asarray(k, dtype=complex) ** 2 - np.asarray(kx, dtype=complex) ** 2)
    flip = (kz.imag < 0) | ((kz.imag == 0) & (kz.real < 0))
    return np.where(flip, -kz, kz)


def solid_layer_RT(
    f_hz: float,
    kx: np.ndarray,
    d_m: float,
    rho1: float,
    c1: float,
    rho2: float,
    cp2: float,
    cs2: float,
    rho3: float,
    c3: float,
    alpha_p_np_m: float = 0.0,
    alpha_s_np_m: float = 0.0,
    alpha1_np_m: float = 0.0,
    alpha3_np_m: float = 0.0,
    return_amplitudes: bool = False,
):
    """R and T (pressure ratios) of a solid layer between two fluids, for horizontal
    wavenumbers kx (rad/m, array).  See module docstring for conventions.

    If return_amplitudes, also returns the (n, 6) solution vector
    [R_phi, A (P down), B (P up), C (S down), D (S up), T_phi] (potential amplitudes).
    """
    w = 2 * np.pi * f_hz
    kx = np.atleast_1d(np.asarray(kx, dtype=complex))
    k1 = w / c1 + 1j * alpha1_np_m
    k3 = w / c3 + 1j * alpha3_np_m
    kp = w / cp2 + 1j * alpha_p_np_m
    ks = w / cs2 + 1j * alpha_s_np_m
    mu = rho2 * (w / ks) ** 2  # complex shear modulus
    kz1 = kz_branch(k1, kx)
    kz3 = kz_branch(k3, kx)
    kzp = kz_branch(kp, kx)
    kzs = kz_branch(ks, kx)
    Ep = np.exp(1j * kzp * d_m)
    Es = np.exp(1j * kzs * d_m)
    # per-unit-amplitude contributions (see docstring): for phi = a exp(i kx x + i q z)
    #   u_z = i q a, s_zz = mu (2 kx^2 - ks^2) a, s_xz = -2 mu kx q a
    # for psi = b exp(i kx x + i s z)
    #   u_z = i kx b, s_zz = -2 mu kx s b,       s_xz = mu (ks^2 - 2 kx^2) b
    g = mu * (2 * kx**2 - ks**2)
    n = kx.size
    M = np.zeros((n, 6, 6), dtype=complex)
    rhs = np.zeros((n, 6), dtype=complex)
    # unknowns: 0 R, 1 A, 2 B, 3 C, 4 D, 5 T   (fluid potentials R, T)
    # --- z = 0: exponentials: A 1, B Ep, C 1, D Es
    # u_z:  i kz1 (1 - R) = i kzp (A - Ep B) + i kx (C + Es D)
    M[:, 0, 0] = 1j * kz1
    M[:, 0, 1] = 1j * kzp
    M[:, 0, 2] = -1j * kzp * Ep
    M[:, 0, 3] = 1j * kx
    M[:, 0, 4] = 1j * kx * Es
    rhs[:, 0] = 1j * kz1
    # s_zz: -rho1 w^2 (1 + R) = g (A + Ep B) - 2 mu kx kzs (C - Es D)
    M[:, 1, 0] = rho1 * w**2
    M[:, 1, 1] = g
    M[:, 1, 2] = g * Ep
    M[:, 1, 3] = -2 * mu * kx * kzs
    M[:, 1, 4] = 2 * mu * kx * kzs * Es
    rhs[:, 1] = -rho1 * w**2
    # s_xz: 0 = -2 mu kx kzp (A - Ep B) + mu (ks^2 - 2 kx^2) (C + Es D)
    M[:, 2, 1] = -2 * mu * kx * kzp
    M[:, 2, 2] = 2 * mu * kx * kzp * Ep
    M[:, 2, 3] = -g
    M[:, 2, 4] = -g * Es
    # --- z = d: exponentials: A Ep, B 1, C Es, D 1
    # u_z: i kzp (Ep A - B) + i kx (Es C + D) - i kz3 T = 0
    M[:, 3, 1] = 1j * kzp * Ep
    M[:, 3, 2] = -1j * kzp
    M[:, 3, 3] = 1j * kx * Es
    M[:, 3, 4] = 1j * kx
    M[:, 3, 5] = -1j * kz3
    # s_zz: g (Ep A + B) - 2 mu kx kzs (Es C - D) + rho3 w^2 T = 0
    M[:, 4, 1] = g * Ep
    M[:, 4, 2] = g
    M[:, 4, 3] = -2 * mu * kx * kzs * Es
    M[:, 4, 4] = 2 * mu * kx * kzs
    M[:, 4, 5] = rho3 * w**2
    # s_xz: -2 mu kx kzp (Ep A - B) - g (Es C + D) = 0
    M[:, 5, 1] = -2 * mu * kx * kzp * Ep
    M[:, 5, 2] = 2 * mu * kx * kzp
    M[:, 5, 3] = -g * Es
    M[:, 5, 4] = -g
    # row scaling (stress rows ~ rho w^2, displacement rows ~ k) for conditioning
    scale = np.array(
        [1 / abs(k1), 1 / (rho1 * w**2), 1 / (rho1 * w**2), 1 / abs(k1), 1 / (rho1 * w**2), 1 / (rho1 * w**2)]
    )
    M *= scale[None, :, None]
    rhs *= scale[None, :]
    x = np.linalg.solve(M, rhs[..., None])[..., 0]
    R = x[:, 0]
    T = x[:, 5] * rho3 / rho1
    if return_amplitudes:
        return R, T, x
    return R, T


def fluid_layer_RT(f_hz, kx, d_m, rho1, c1, rho2, c2, rho3, c3, alpha2_np_m=0.0):
    """Classic fluid layer (Brekhovskikh 1980, eq. 2.4 family), via the pressure /
    normal-velocity transfer matrix of the layer:
        p(d) = p(0) cos(phi) + i Z2 v(0) sin(phi),  v(d) = v(0) cos(phi) + i p(0) sin(phi) / Z2
    with phi = kz2 d and Z_i = rho_i omega / kz_i (= rho c / cos(theta)).  Same R, T
    definitions as solid_layer_RT."""
    w = 2 * np.pi * f_hz
    kx = np.atleast_1d(np.asarray(kx, dtype=complex))
    kz1 = kz_branch(w / c1, kx)
    kz2 = kz_branch(w / c2 + 1j * alpha2_np_m, kx)
    kz3 = kz_branch(w / c3, kx)
    Z1, Z2, Z3 = rho1 * w / kz1, rho2 * w / kz2, rho3 * w / kz3
    cphi, sphi = np.cos(kz2 * d_m), np.sin(kz2 * d_m)
    # incident+reflected: p(0) = 1 + R, Z1 v(0) = 1 - R; transmitted: p(d) = T = Z3 v(d)
    # closed form:
    den = (1 + Z1 / Z3) * cphi - 1j * (Z2 / Z3 + Z1 / Z2) * sphi
    T = 2 / den
    R = ((1 - Z1 / Z3) * cphi - 1j * (Z2 / Z3 - Z1 / Z2) * sphi) / den
    return R, T


def halfspace_R(f_hz, kx, rho1, c1, rho2, cp2, cs2, alpha_p_np_m=0.0, alpha_s_np_m=0.0):
    """Textbook fluid / solid half-space reflection coefficient (Brekhovskikh eq. 4.2.x):
    R = (Zp cos^2 2ts + Zs sin^2 2ts - Z1) / (Zp cos^2 2ts + Zs sin^2 2ts + Z1),
    Z_i = rho_i c_i / cos(theta_i) = rho_i omega / kz_i, complex for loss."""
    w = 2 * np.pi * f_hz
    kx = np.atleast_1d(np.asarray(kx, dtype=complex))
    kp = w / cp2 + 1j * alpha_p_np_m
    ks = w / cs2 + 1j * alpha_s_np_m
    kz1, kzp, kzs = kz_branch(w / c1, kx), kz_branch(kp, kx), kz_branch(ks, kx)
    Z1, Zp, Zs = rho1 * w / kz1, rho2 * w / kzp, rho2 * w / kzs
    sin2 = 2 * (kx / ks) * (kzs / ks)
    cos2 = 1 - 2 * (kx / ks) ** 2
    Zt = Zp * cos2**2 + Zs * sin2**2
    return (Zt - Z1) / (Zt + Z1)


def insertion_T(T, f_hz, kx, d_m, c_water):
    """Transmitted field behind the plate relative to the water-only field on the same
    plane: T * exp(-i kz_w d)."""
    kzw = kz_branch(2 * np.pi * f_hz / c_water, np.asarray(kx, dtype=complex))
    return T * np.exp(-1j * kzw * d_m)


# ----------------------------------------------------------------- Rayleigh-Lamb
def rayleigh_lamb(f_hz, c_phase, d_m, cp, cs):
    """Real dispersion functions of the free (traction-free) plate, written without
    tangents so they have no poles and are real for c_phase above or below cp:
        symmetric:     (q^2-k^2)^2 cos(ph) sin(qh) + 4 k^2 [p sin(ph)] q cos(qh)
        antisymmetric: (q^2-k^2)^2 [sin(ph)/p] cos(qh) + 4 k^2 q cos(ph) sin(qh)
    h = d/2, k = omega/c_phase, p^2 = omega^2/cp^2 - k^2, q^2 = omega^2/cs^2 - k^2.
    (Divided through by suitable powers of k for scale.)"""
    w = 2 * np.pi * f_hz
    k = w / np.asarray(c_phase, dtype=float)
    h = d_m / 2
    p = np.sqrt((w / cp) ** 2 - k**2 + 0j)
    q = np.sqrt((w / cs) ** 2 - k**2 + 0j)
    psin = np.where(np.abs(p) < 1e-12, 0.0, p * np.sin(p * h))
    sinc_p = np.where(np.abs(p) < 1e-12, h, np.sin(p * h) / np.where(p == 0, 1, p))
    a = (q**2 - k**2) ** 2
    fs = a * np.cos(p * h) * np.sin(q * h) + 4 * k**2 * psin * q * np.cos(q * h)
    fa = a * sinc_p * np.cos(q * h) + 4 * k**2 * q * np.cos(p * h) * np.sin(q * h)
    return fs.real / k**4, fa.real / k**3


def lamb_phase_velocities(f_hz, d_m, cp, cs, c_min, c_max, n=200001):
    """Phase velocities in (c_min, c_max) of the free plate's Lamb modes, symmetric
    and antisymmetric, by a fine scan in slowness and bisection of sign changes."""
    out = {}
    s = np.linspace(1 / c_max, 1 / c_min, n)[1:-1]
    for j, name in enumerate(("S", "A")):

        def f(sl, j=j):
            return rayleigh_lamb(f_hz, 1 / sl, d_m, cp, cs)[j]

        v = f(s)
        idx = np.nonzero(np.sign(v[:-1]) * np.sign(v[1:]) < 0)[0]
        roots = []
        for i in idx:
            a, b = s[i], s[i + 1]
            fa = f(a)
            for _ in range(60):
                m = 0.5 * (a + b)
                fm = f(m)
                if np.sign(fm) == np.sign(fa):
                    a, fa = m, fm
                else:
                    b = m
            roots.append(1 / (0.5 * (a + b)))
        # drop trivial roots at c = cs*sqrt(2)... and q = 0 (c = cs) that are sign-free
        out[name] = np.array(sorted(roots))
    return out


# ----------------------------------------------------------------- the bench plate
WATER = dict(c=1500.0, rho=1000.0)
BONE = dict(cp=2800.0, cs=1500.0, rho=1850.0, alpha_p_db_cm=4.0, alpha_s_db_cm=4.0)
F0_HZ = 500e3
D_M = 6.5e-3


def bench_plate_T(angles_deg, cs=BONE["cs"], lossy=True, fluid=False, f_hz=F0_HZ, d_m=D_M):
    """Insertion transmission (complex) of the bench plate versus angle in water."""
    th = np.deg2rad(np.asarray(angles_deg, dtype=float))
    kx = 2 * np.pi * f_hz / WATER["c"] * np.sin(th)
    ap = alpha_np_per_m(BONE["alpha_p_db_cm"]) if lossy else 0.0
    as_ = alpha_np_per_m(BONE["alpha_s_db_cm"]) if lossy else 0.0
    if fluid:
        _, T = fluid_layer_RT(
            f_hz, kx, d_m, WATER["rho"], WATER["c"], BONE["rho"], BONE["cp"], WATER["rho"], WATER["c"], alpha2_np_m=ap
        )
    else:
        _, T = solid_layer_RT(
            f_hz, kx, d_m, WATER["rho"], WATER["c"], BONE["rho"], BONE["cp"], cs, WATER["rho"], WATER["c"], ap, as_
        )
    return insertion_T(T, f_hz, kx, d_m, WATER["c"])


def bench_plate_T_kx(kx, cs=BONE["cs"], lossy=True, fluid=False, f_hz=F0_HZ, d_m=D_M):
    """Same as bench_plate_T for horizontal wavenumbers kx (rad/m); |kx| > k_w gives
    evanescent incidence, handled on the decaying branch."""
    ap = alpha_np_per_m(BONE["alpha_p_db_cm"]) if lossy else 0.0
    as_ = alpha_np_per_m(BONE["alpha_s_db_cm"]) if lossy else 0.0
    if fluid:
        _, T = fluid_layer_RT(
            f_hz, kx, d_m, WATER["rho"], WATER["c"], BONE["rho"], BONE["cp"], WATER["rho"], WATER["c"], alpha2_np_m=ap
        )
    else:
        _, T = solid_layer_RT(
            f_hz, kx, d_m, WATER["rho"], WATER["c"], BONE["rho"], BONE["cp"], cs, WATER["rho"], WATER["c"], ap, as_
        )
    return insertion_T(T, f_hz, kx, d_m, WATER["c"])


def main():
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--angles-deg", type=float, nargs="*", default=[0, 5, 10, 15, 20, 25, 30, 32, 35, 40, 45, 50, 60])
    args = ap.parse_args()
    a = np.array(args.angles_deg)
    cols = [
        ("fluid", dict(fluid=True)),
        ("solid cs1500", dict()),
        ("solid lossless", dict(lossy=False)),
        ("solid cs1300", dict(cs=1300.0)),
        ("solid cs1700", dict(cs=1700.0)),
    ]
    print("angle_deg | " + " | ".join(f"|T|^2 {n}" for n, _ in cols))
    res = {n: bench_plate_T(a, **kw) for n, kw in cols}
    for i, th in enumerate(a):
        print(f"{th:6.1f} | " + " | ".join(f"{abs(res[n][i]) ** 2:.4f}" for n, _ in cols))


if __name__ == "__main__":
    main()
