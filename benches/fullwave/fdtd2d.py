"""A small 2-D P-SV velocity-stress staggered-grid FDTD (Virieux 1986), NumPy only,
as an independent full-wave check of the plate's plane-wave transmission.

* x periodic (np.roll): an exact infinite plane wave with horizontal wavenumber
  kx = 2 pi m / Lx, i.e. sin(theta) = m lambda_w / Lx; the angle actually simulated
  is reported (theta_sim) and the exact solution is evaluated there.
* z: long water columns ending in gradual damping sponges.
* Staggering: sxx, szz at (i, k); vx at (i+1/2, k); vz at (i, k+1/2); sxz at
  (i+1/2, k+1/2).  Densities averaged arithmetically at the velocity nodes, the
  shear modulus harmonically over the 4 cells around a sxz node (zero if any of them
  is fluid) -- the same interface treatment as BabelViscoFDTD.
* Source: additive, equal on sxx and szz on one row: envelope(t) cos(kx x - w t),
  exactly periodic in x.  The plate fills whole cells (its faces on cell faces).
* Measurement: pressure -(sxx + szz)/2 on a row behind the plate; DFT at f0 over the
  whole record (convention exp(-i w t)), projected on exp(i kx x).  The ratio to a
  water-only run (same grid and dt) is the engine's insertion transmission T_ins.
* Loss: Kelvin-Voigt viscosities chosen so that at f0 the complex wavenumbers are
  exactly w/c + i alpha (the exact solution's), for P and S; the DFT at f0 then
  compares like with like.  cs = 0 gives the fluid plate.
"""

from __future__ import annotations

import time

import numpy as np
import plate_exact as pe

F0 = pe.F0_HZ
C_W, RHO_W = pe.WATER["c"], pe.WATER["rho"]


def kv_moduli(rho, c, alpha_np_m, f=F0):
    """Kelvin-Voigt modulus M0 and viscosity eta giving exactly k = w/c + i alpha at f:
    M(w) = rho (w/k)^2 = M0 - i w eta   (exp(-i w t))."""
    w = 2 * np.pi * f
    M = rho * (w / (w / c + 1j * alpha_np_m)) ** 2
    return M.real, -M.imag / w


def simulate(
    angle_deg,
    dx,
    cs,
    with_plate,
    cp=pe.BONE["cp"],
    rho_b=pe.BONE["rho"],
    d_m=pe.D_M,
    n_env_cycles=10,
    t_record=160e-6,
    lossy=False,
    dt=None,
    verbose=True,
):
    lam = C_W / F0
    th = np.deg2rad(angle_deg)
    if angle_deg == 0:
        nx = 4
        kx = 0.0
    else:
        nx = int(round(lam / (np.sin(th) * dx)))
        kx = 2 * np.pi / (nx * dx)
    th_sim = np.rad2deg(np.arcsin(kx * C_W / (2 * np.pi * F0)))
    n_sponge = int(round(30e-3 / dx))
    gap = int(round(6e-3 / dx))
    d_cells = int(round(d_m / dx))
    nz = 2 * n_sponge + 4 * gap + d_cells
    k_src = n_sponge + gap
    k_top = k_src + gap
    k_bot = k_top + d_cells
    k_sens = k_bot + gap
    rho = np.full((nx, nz), RHO_W)
    lam2mu = np.full((nx, nz), RHO_W * C_W**2)
    mu = np.zeros((nx, nz))
    eta_p = np.zeros((nx, nz))
    eta_s = np.zeros((nx, nz))
    if with_plate:
        ap = pe.alpha_np_per_m(pe.BONE["alpha_p_db_cm"]) if lossy else 0.0
        as_ = pe.alpha_np_per_m(pe.BONE["alpha_s_db_cm"]) if lossy else 0.0
        Mp, ep = kv_moduli(rho_b, cp, ap)
        rho[:, k_top:k_bot] = rho_b
        lam2mu[:, k_top:k_bot] = Mp
        eta_p[:, k_top:k_bot] = ep
        if cs > 0:
            Ms, es = kv_moduli(rho_b, cs, as_)
            mu[:, k_top:k_bot] = Ms
            eta_s[:, k_top:k_bot] = es
    lam_ = lam2mu - 2 * mu
    etal = eta_p - 2 * eta_s
    bx = 2.0 / (rho + np.roll(rho, -1, axis=0))
    rz = np.concatenate([rho[:, 1:], rho[:, -1:]], axis=1)
    bz = 2.0 / (rho + rz)
    m4 = [mu, np.roll(mu, -1, 0)]
    m4 += [np.concatenate([m[:, 1:], m[:, -1:]], axis=1) for m in m4]
    with np.errstate(divide="ignore"):
        mu_xz = np.where(np.all([m > 0 for m in m4], axis=0), 4.0 / sum(1.0 / np.where(m > 0, m, 1) for m in m4), 0.0)
        e4 = [eta_s, np.roll(eta_s, -1, 0)]
        e4 += [np.concatenate([m[:, 1:], m[:, -1:]], axis=1) for m in e4]
        eta_xz = np.where(np.all([m > 0 for m in e4], axis=0), 4.0 / sum(1.0 / np.where(m > 0, m, 1) for m in e4), 0.0)
    dt_given = dt
    dt_cfl = 0.5 * dx / (cp * np.sqrt(2.0))
    nu = max(eta_p.max(), 1e-30) / rho_b
    dt_own = min(dt_cfl, 0.08 * dx**2 / nu)
    if lossy:
        # the water run shares the time step of a lossy plate run
        dt_own = min(
            dt_own, 0.08 * dx**2 / (kv_moduli(rho_b, cp, pe.alpha_np_per_m(pe.BONE["alpha_p_db_cm"]))[1] / rho_b)
        )
    dt = dt_own if dt_given is None else dt_given
    nt = int(np.ceil(t_record / dt))
    # sponge profile (applied as exp(-sigma dt) to all fields)
    zz = np.arange(nz)
    prof = np.zeros(nz)
    prof[:n_sponge] = ((n_sponge - zz[:n_sponge]) / n_sponge) ** 2
    prof[nz - n_sponge :] = ((zz[nz - n_sponge :] - (nz - n_sponge - 1)) / n_sponge) ** 2
    damp = np.exp(-prof * 3.0 * C_W / (n_sponge * dx) * 4.0 * dt)[None, :]
    vx = np.zeros((nx, nz))
    vz = np.zeros((nx, nz))
    sxx = np.zeros((nx, nz))
    szz = np.zeros((nx, nz))
    sxz = np.zeros((nx, nz))
    xs = np.arange(nx) * dx
    w = 2 * np.pi * F0
    T_env = n_env_cycles / F0
    acc = np.zeros(nx, complex)
    e_tail = 0.0
    e_tot = 0.0
    t0 = time.time()
    idt = dt / dx
    viscous = lossy and with_plate
    r_xx = np.zeros((nx, nz))
    r_zz = np.zeros((nx, nz))
    r_xz = np.zeros((nx, nz))
    for n in range(nt):
        # velocities (at t + dt/2)
        dsxx_dx = np.roll(sxx, -1, 0) - sxx
        dsxz_dz = sxz.copy()
        dsxz_dz[:, 1:] -= sxz[:, :-1]
        dsxz_dx = sxz - np.roll(sxz, 1, 0)
        dszz_dz = np.zeros_like(szz)
        dszz_dz[:, :-1] = szz[:, 1:] - szz[:, :-1]
        vx += idt * bx * (dsxx_dx + dsxz_dz)
        vz += idt * bz * (dsxz_dx + dszz_dz)
        vx *= damp
        vz *= damp
        # stresses (at t + dt)
        dvx_dx = vx - np.roll(vx, 1, 0)
        dvz_dz = vz.copy()
        dvz_dz[:, 1:] -= vz[:, :-1]
        dvx_dz = np.zeros_like(vx)
        dvx_dz[:, :-1] = vx[:, 1:] - vx[:, :-1]
        dvz_dx = np.roll(vz, -1, 0) - vz
        sxx += idt * (lam2mu * dvx_dx + lam_ * dvz_dz)
        szz += idt * (lam_ * dvx_dx + lam2mu * dvz_dz)
        sxz += idt * mu_xz * (dvx_dz + dvz_dx)
        if viscous:  # Kelvin-Voigt: sigma += eta * d(strain rate)
            exx, ezz, exz = dvx_dx / dx, dvz_dz / dx, (dvx_dz + dvz_dx) / dx
            sxx += eta_p * (exx - r_xx) + etal * (ezz - r_zz)
            szz += etal * (exx - r_xx) + eta_p * (ezz - r_zz)
            sxz += eta_xz * (exz - r_xz)
            r_xx, r_zz, r_xz = exx, ezz, exz
        sxx *= damp
        szz *= damp
        sxz *= damp
        ts = (n + 1) * dt
        if ts < T_env:
            env = np.sin(np.pi * ts / T_env) ** 2
            s = env * np.cos(kx * xs - w * ts) * 1.0
            sxx[:, k_src] += s
            szz[:, k_src] += s
        p = -0.5 * (sxx[:, k_sens] + szz[:, k_sens])
        acc += p * np.exp(1j * w * ts)
        e = float((p**2).sum())
        e_tot += e
        if n >= 0.9 * nt:
            e_tail += e
    P = (acc * np.exp(-1j * kx * xs)).mean()
    wall = time.time() - t0
    if verbose:
        print(
            f"[fdtd2d] angle {angle_deg} (sim {th_sim:.3f}) deg, cs {cs}, plate={with_plate}, dx {dx * 1e3} mm, grid "
            f"{nx}x{nz}, dt {dt * 1e9:.2f} ns, {nt} steps, {wall:.1f} s, tail energy {e_tail / e_tot:.1e}",
            flush=True,
        )
    return dict(
        P=P, dt=dt, nt=nt, wall=wall, grid=[nx, nz], d_m=d_cells * dx, th_sim=th_sim, kx=kx, tail=e_tail / e_tot
    )


def run(args, compare_spectra, save):
    dx = args.dx_mm * 1e-3
    rows = []
    lossy = not args.lossless
    for ang in args.angles_deg:
        w = simulate(ang, dx, args.cs, False, lossy=lossy, t_record=args.record_us * 1e-6)
        p = simulate(ang, dx, args.cs, True, lossy=lossy, t_record=args.record_us * 1e-6, dt=w["dt"])
        Te = p["P"] / w["P"]
        fluid = args.cs == 0
        T = pe.bench_plate_T_kx(np.array([p["kx"]]), cs=max(args.cs, 1.0), lossy=lossy, d_m=p["d_m"], fluid=fluid)[0]
        Tf = pe.bench_plate_T_kx(np.array([p["kx"]]), lossy=lossy, d_m=p["d_m"], fluid=True)[0]
        row = dict(
            angle_deg=ang,
            angle_simulated_deg=p["th_sim"],
            power_ratio_engine=abs(Te) ** 2,
            power_ratio_exact=abs(T) ** 2,
            power_ratio_exact_fluid_plate=abs(Tf) ** 2,
            ratio_engine_over_exact=abs(Te) ** 2 / abs(T) ** 2,
            amp_engine_re=Te.real,
            amp_engine_im=Te.imag,
            amp_exact_re=T.real,
            amp_exact_im=T.imag,
            phase_diff_deg=float(np.angle(Te / T, deg=True)),
            grid=p["grid"],
            dt_s=p["dt"],
            n_steps=p["nt"],
            runtime_s=w["wall"] + p["wall"],
            plate_thickness_grid_mm=p["d_m"] * 1e3,
            record_tail_energy_fraction=p["tail"],
        )
        rows.append(row)
        print(
            f"angle {p['th_sim']:6.2f}: engine |T|^2 {abs(Te) ** 2:.4f}  exact {abs(T) ** 2:.4f}  (fluid plate "
            f"{abs(Tf) ** 2:.4f})  ratio {row['ratio_engine_over_exact']:.3f}  phase diff {row['phase_diff_deg']:.1f} "
            "deg",
            flush=True,
        )
        save(
            args,
            rows,
            dict(
                engine="fdtd2d (this bench, NumPy P-SV staggered grid, periodic x)",
                source="additive stress row, periodic cos(kx x - w t), 10-cycle Hann envelope",
                absorbing="30 mm quadratic sponges",
                precision="double",
            ),
        )


# ---------------------------------------------------------------- tilted, staircased plate
def simulate_tilted(
    angle_deg,
    dx,
    cs,
    with_plate,
    lossy=True,
    waist_m=12e-3,
    cp=pe.BONE["cp"],
    rho_b=pe.BONE["rho"],
    d_m=pe.D_M,
    n_env_cycles=4,
    t_record=70e-6,
    dt=None,
    verbose=True,
):
    """Gaussian beam along z onto a plate tilted by angle_deg in the x-z plane (staircased:
    a cell is bone if its centre is inside the plate).  Sponges on all four sides.
    Returns the 500 kHz pressure along a row behind the plate."""
    th = np.deg2rad(angle_deg)
    half = 2.3 * waist_m
    n_sp = int(round(20e-3 / dx))
    lx = 2 * half + d_m * np.tan(th) + 4e-3
    nx = int(np.ceil(lx / dx)) + 2 * n_sp
    gap = 3e-3
    lz = gap + 2 * half * np.tan(th) + d_m / np.cos(th) + gap + 4e-3
    nz = int(np.ceil(lz / dx)) + 2 * n_sp
    x = (np.arange(nx) - nx / 2) * dx
    z = np.arange(nz) * dx
    k_src = n_sp + int(round(1e-3 / dx))
    z_top_c = z[k_src] + gap + half * np.tan(th)
    X, Z = np.meshgrid(x, z, indexing="ij")
    s = X * np.sin(th) + (Z - z_top_c) * np.cos(th)
    inside = (s >= -1e-12) & (s < d_m - 1e-12) if with_plate else np.zeros((nx, nz), bool)
    k_sens = int(np.ceil((z_top_c + half * np.tan(th) + d_m / np.cos(th) + gap) / dx))
    assert k_sens < nz - n_sp
    rho = np.where(inside, rho_b, RHO_W)
    ap = pe.alpha_np_per_m(pe.BONE["alpha_p_db_cm"]) if lossy else 0.0
    as_ = pe.alpha_np_per_m(pe.BONE["alpha_s_db_cm"]) if lossy else 0.0
    Mp, ep = kv_moduli(rho_b, cp, ap)
    Ms, es = kv_moduli(rho_b, cs, as_) if cs > 0 else (0.0, 0.0)
    lam2mu = np.where(inside, Mp, RHO_W * C_W**2)
    mu = np.where(inside, Ms, 0.0)
    eta_p = np.where(inside, ep, 0.0)
    eta_s = np.where(inside, es, 0.0)
    lam_ = lam2mu - 2 * mu
    etal = eta_p - 2 * eta_s
    bx = 2.0 / (rho + np.roll(rho, -1, axis=0))
    bz = 2.0 / (rho + np.concatenate([rho[:, 1:], rho[:, -1:]], axis=1))

    def hm4(a):
        m4 = [a, np.roll(a, -1, 0)]
        m4 += [np.concatenate([m[:, 1:], m[:, -1:]], axis=1) for m in m4]
        with np.errstate(divide="ignore"):
            return np.where(
                np.all([m > 0 for m in m4], axis=0), 4.0 / sum(1.0 / np.where(m > 0, m, 1) for m in m4), 0.0
            )

    mu_xz, eta_xz = hm4(mu), hm4(eta_s)
    if dt is None:
        dt = 0.5 * dx / (cp * np.sqrt(2.0))
        if lossy:
            dt = min(dt, 0.08 * dx**2 / (ep / rho_b))
    nt = int(np.ceil(t_record / dt))

    def prof(n, n_sp):
        i = np.arange(n)
        p = np.zeros(n)
        p[:n_sp] = ((n_sp - i[:n_sp]) / n_sp) ** 2
        p[n - n_sp :] = ((i[n - n_sp :] - (n - n_sp - 1)) / n_sp) ** 2
        return p

    sig = (prof(nx, n_sp)[:, None] + prof(nz, n_sp)[None, :]) * 3.0 * C_W / (n_sp * dx) * 4.0
    damp = np.exp(-sig * dt)
    vx = np.zeros((nx, nz))
    vz = np.zeros((nx, nz))
    sxx = np.zeros((nx, nz))
    szz = np.zeros((nx, nz))
    sxz = np.zeros((nx, nz))
    r_xx = np.zeros((nx, nz))
    r_zz = np.zeros((nx, nz))
    r_xz = np.zeros((nx, nz))
    apod = np.exp(-((x / waist_m) ** 2))
    w = 2 * np.pi * F0
    T_env = n_env_cycles / F0
    acc = np.zeros(nx, complex)
    idt = dt / dx
    viscous = lossy and with_plate
    t0 = time.time()
    for n in range(nt):
        dsxx_dx = np.roll(sxx, -1, 0) - sxx
        dsxz_dz = sxz.copy()
        dsxz_dz[:, 1:] -= sxz[:, :-1]
        dsxz_dx = sxz - np.roll(sxz, 1, 0)
        dszz_dz = np.zeros_like(szz)
        dszz_dz[:, :-1] = szz[:, 1:] - szz[:, :-1]
        vx += idt * bx * (dsxx_dx + dsxz_dz)
        vz += idt * bz * (dsxz_dx + dszz_dz)
        vx *= damp
        vz *= damp
        dvx_dx = vx - np.roll(vx, 1, 0)
        dvz_dz = vz.copy()
        dvz_dz[:, 1:] -= vz[:, :-1]
        dvx_dz = np.zeros_like(vx)
        dvx_dz[:, :-1] = vx[:, 1:] - vx[:, :-1]
        dvz_dx = np.roll(vz, -1, 0) - vz
        sxx += idt * (lam2mu * dvx_dx + lam_ * dvz_dz)
        szz += idt * (lam_ * dvx_dx + lam2mu * dvz_dz)
        sxz += idt * mu_xz * (dvx_dz + dvz_dx)
        if viscous:
            exx, ezz, exz = dvx_dx / dx, dvz_dz / dx, (dvx_dz + dvz_dx) / dx
            sxx += eta_p * (exx - r_xx) + etal * (ezz - r_zz)
            szz += etal * (exx - r_xx) + eta_p * (ezz - r_zz)
            sxz += eta_xz * (exz - r_xz)
            r_xx, r_zz, r_xz = exx, ezz, exz
        sxx *= damp
        szz *= damp
        sxz *= damp
        ts = (n + 1) * dt
        if ts < T_env:
            sv = np.sin(np.pi * ts / T_env) ** 2 * np.sin(w * ts) * apod
            sxx[:, k_src] += sv
            szz[:, k_src] += sv
        p = -0.5 * (sxx[:, k_sens] + szz[:, k_sens])
        acc += p * np.exp(1j * w * ts)
    wall = time.time() - t0
    i0, i1 = n_sp, nx - n_sp
    if verbose:
        print(
            f"[fdtd2d tilted] angle {angle_deg} deg, cs {cs}, plate={with_plate}, dx {dx * 1e3} mm, grid {nx}x{nz}, dt "
            f"{dt * 1e9:.2f} ns, {nt} steps, {wall:.1f} s",
            flush=True,
        )
    return dict(P=acc[i0:i1], dt=dt, nt=nt, wall=wall, grid=[nx, nz], d_m=d_m, normal=(np.sin(th), 0.0, np.cos(th)))


def run_tilted(args, compare_spectra, save):
    dx = args.dx_mm * 1e-3
    lossy = not args.lossless
    rows = []
    for ang in args.angles_deg:
        w = simulate_tilted(ang, dx, args.cs, False, lossy=lossy, waist_m=args.waist_mm * 1e-3)
        p = simulate_tilted(ang, dx, args.cs, True, lossy=lossy, waist_m=args.waist_mm * 1e-3, dt=w["dt"])
        c = compare_spectra(p["P"], w["P"], dx, p["normal"], cs=max(args.cs, 1.0), lossy=lossy, fluid=args.cs == 0)
        row = dict(
            angle_deg=ang,
            **{k: v for k, v in c.items() if not isinstance(v, complex)},
            amp_engine_re=c["amp_engine"].real,
            amp_engine_im=c["amp_engine"].imag,
            amp_exact_re=c["amp_exact"].real,
            amp_exact_im=c["amp_exact"].imag,
            ratio_engine_over_exact=c["power_ratio_engine"] / c["power_ratio_exact"],
            grid=p["grid"],
            dt_s=p["dt"],
            n_steps=p["nt"],
            runtime_s=w["wall"] + p["wall"],
            plate_thickness_grid_mm=p["d_m"] * 1e3,
        )
        rows.append(row)
        print(
            f"angle {ang:5.1f} (tilted plate): engine |T|^2 {row['power_ratio_engine']:.4f}  exact "
            f"{row['power_ratio_exact']:.4f} (fluid plate {row['power_ratio_exact_fluid_plate']:.4f})  ratio "
            f"{row['ratio_engine_over_exact']:.3f}",
            flush=True,
        )
        save(
            args,
            rows,
            dict(
                engine="fdtd2d (this bench), Gaussian beam, staircased tilted plate",
                waist_mm=args.waist_mm,
                absorbing="20 mm quadratic sponges",
                precision="double",
            ),
        )
