"""Plane-wave (wide, apodized beam) transmission through the 6.5 mm bone plate in
full-wave engines, compared with the exact solution (plate_exact.py) applied to the
same beam's angular spectrum.

Engines
  babel   BabelViscoFDTD 1.2.7, 3-D viscoelastic staggered-grid FDTD, OpenMP CPU.
  fdtd2d  this bench's own 2-D P-SV velocity-stress staggered-grid FDTD (NumPy,
          Virieux 1986, 2nd order, harmonic-mean shear modulus at the shear-stress
          nodes as in Babel) with periodic x boundaries: an exact infinite plane
          wave of the angle sin(theta) = m lambda / Lx, plate aligned with the grid.
          Lossless only.  (k-wave-python has no usable elastic solver: see README.)

Geometry (babel)
  aligned  the plate is aligned with the grid (z normal); the beam's wavefront is
           tilted by per-column delays of the source plane (no staircasing).
  tilted   the beam goes along z, the plate is tilted in the x-z plane by the angle
           (staircased faces).

Measurement: the 500 kHz component of the pressure on a plane behind the plate,
from a DFT over the whole record of a Hann tone burst (as the system is linear and
the record is long enough for the plate's ring-down, this is the CW steady-state
field).  Each plate run has a water-only run with the same grid and time step; the
ratio of their angular spectra is compared with the exact insertion transmission
T_ins(k_t) = T exp(-i kz_w d) (plate_exact.py, convention exp(-i omega t)).

Reported per angle:
  power_ratio_engine = sum |P_plate(k)|^2 cos / sum |P_water(k)|^2 cos  (propagating k)
  power_ratio_exact  = sum |T_ins(k)|^2 |P_water(k)|^2 cos / same denominator
  amp_engine = sum P_plate conj(P_water) cos / sum |P_water|^2 cos  (complex)
  amp_exact  = sum T_ins |P_water|^2 cos / sum |P_water|^2 cos
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import plate_exact as pe  # noqa: E402

F0 = pe.F0_HZ
C_W, RHO_W = pe.WATER["c"], pe.WATER["rho"]
RESULTS = os.path.join(HERE, "..", "results")


def tone_burst(t, n_cycles=4.0, f=F0):
    """Hann-windowed tone burst, starting at t = 0."""
    T = n_cycles / f
    s = np.sin(2 * np.pi * f * t) * np.sin(np.pi * np.clip(t, 0, T) / T) ** 2
    return np.where((t >= 0) & (t <= T), s, 0.0)


def dft_at(sig, t, f=F0):
    """Complex amplitude at f for the exp(-i omega t) convention: sum s(t) exp(+i w t)."""
    return (sig * np.exp(2j * np.pi * f * t)[None, :]).sum(axis=-1)


def compare_spectra(Pp, Pw, dx, plate_normal=(0.0, 0.0, 1.0), cs=1500.0, lossy=True, d_m=pe.D_M, fluid=False):
    """Angular-spectrum comparison on a measurement plane (2-D array x,y or 1-D x)."""
    k = 2 * np.pi * F0 / C_W
    if Pp.ndim == 1:
        Pp, Pw = Pp[:, None], Pw[:, None]
    nx, ny = Pp.shape
    kx = 2 * np.pi * np.fft.fftfreq(nx, dx)[:, None]
    ky = 2 * np.pi * np.fft.fftfreq(ny, dx)[None, :] if ny > 1 else np.zeros((1, 1))
    Sp, Sw = np.fft.fft2(Pp), np.fft.fft2(Pw)
    kt2 = kx**2 + ky**2
    prop = kt2 < k**2 * 0.999
    kz = np.sqrt(np.where(prop, k**2 - kt2, 0.0))
    wgt = np.where(prop, kz / k, 0.0)
    # tangential wavenumber relative to the plate
    n = np.asarray(plate_normal, float)
    kn = kx * n[0] + ky * n[1] + kz * n[2]
    ktp = np.sqrt(np.maximum(k**2 - kn**2, 0.0))
    Tins = pe.bench_plate_T_kx(ktp.ravel(), cs=cs, lossy=lossy, d_m=d_m, fluid=fluid).reshape(ktp.shape)
    Tins = np.nan_to_num(Tins * (wgt > 0))
    den = (np.abs(Sw) ** 2 * wgt).sum()
    return dict(
        power_ratio_engine=float((np.abs(Sp) ** 2 * wgt).sum() / den),
        power_ratio_exact=float((np.abs(Tins) ** 2 * np.abs(Sw) ** 2 * wgt).sum() / den),
        power_ratio_exact_fluid_plate=float(
            (
                np.abs(
                    np.nan_to_num(
                        pe.bench_plate_T_kx(ktp.ravel(), lossy=lossy, d_m=d_m, fluid=True).reshape(ktp.shape)
                        * (wgt > 0)
                    )
                )
                ** 2
                * np.abs(Sw) ** 2
                * wgt
            ).sum()
            / den
        ),
        amp_engine=complex((Sp * np.conj(Sw) * wgt).sum() / den),
        amp_exact=complex((Tins * np.abs(Sw) ** 2 * wgt).sum() / den),
        evanescent_power_fraction_water=float((np.abs(Sw[~prop]) ** 2).sum() / (np.abs(Sw) ** 2).sum()),
    )


# ============================================================== BabelViscoFDTD
def babel_import():
    import importlib.util

    spec = importlib.util.find_spec("BabelViscoFDTD")
    pkg_dir = os.path.dirname(spec.origin)
    if pkg_dir not in sys.path:
        sys.path.insert(0, pkg_dir)  # its CPU module imports the extension by top-level name
    import BabelViscoFDTD
    from BabelViscoFDTD.PropagationModel import PropagationModel

    return PropagationModel(), getattr(BabelViscoFDTD, "__version__", "1.2.7")


def babel_run(angle_deg, dx, geometry, cs, lossy, waist_m, with_plate, dt=None, verbose=True):
    PM, _ = babel_import()
    th = np.deg2rad(angle_deg)
    npml = 12
    margin = 4
    d_cells = int(round(pe.D_M / dx))
    d_m = d_cells * dx
    half = 2.3 * waist_m  # beam half-width kept in the domain
    if geometry == "aligned":
        gap_src, gap_sens = 4e-3, 3e-3
        walk = (gap_src + gap_sens + d_m) * np.tan(th)
        Lx = 2 * half + walk
        nz_in = int(np.ceil((gap_src + d_m + gap_sens + 2e-3) / dx))
        Lz_extra = 0.0
    else:
        gap_src, gap_sens = 3e-3, 3e-3
        walk = d_m * np.tan(th)  # lateral shift of the P wave inside a tilted plate, roughly
        Lx = 2 * half + walk
        Lz_extra = 2 * half * np.tan(th) + d_m / np.cos(th)
        nz_in = int(np.ceil((gap_src + Lz_extra + gap_sens + 2e-3) / dx))
    nx = int(np.ceil(Lx / dx)) + 2 * (npml + margin)
    ny = int(np.ceil(2 * half / dx)) + 2 * (npml + margin)
    nz = nz_in + 2 * (npml + margin)
    x = (np.arange(nx) - nx / 2) * dx
    y = (np.arange(ny) - ny / 2) * dx
    z = np.arange(nz) * dx
    iz_src = npml + margin
    mat = np.zeros((nx, ny, nz), np.uint32)
    if geometry == "aligned":
        iz_top = iz_src + int(round(gap_src / dx))
        iz_bot = iz_top + d_cells  # exclusive
        iz_sens = iz_bot + int(round(gap_sens / dx))
        if with_plate:
            mat[:, :, iz_top:iz_bot] = 1
        x_src_c = -walk / 2
        normal = (0.0, 0.0, 1.0)
    else:
        z_top_c = z[iz_src] + gap_src + half * np.tan(th)  # plate top face at x = 0
        # plate: 0 <= n.(r - r0) <= d, n = (sin, 0, cos), r0 = (0, ., z_top_c)
        X, Z = np.meshgrid(x, z, indexing="ij")
        s = X * np.sin(th) + (Z - z_top_c) * np.cos(th)
        if with_plate:
            mat[:, :, :] = ((s >= -1e-12) & (s < d_m - 1e-12))[:, None, :].astype(np.uint32)
        z_deep = z_top_c + half * np.tan(th) + d_m / np.cos(th)
        iz_sens = int(np.ceil((z_deep + gap_sens) / dx))
        x_src_c = 0.0
        normal = (np.sin(th), 0.0, np.cos(th))
    assert iz_sens < nz - npml - margin, (iz_sens, nz)
    # materials: rho, cp, cs, alpha_p (Np/m), alpha_s (Np/m)
    ap = pe.alpha_np_per_m(pe.BONE["alpha_p_db_cm"]) if lossy else 0.0
    as_ = pe.alpha_np_per_m(pe.BONE["alpha_s_db_cm"]) if (lossy and cs > 0) else 0.0
    props = np.array([[RHO_W, C_W, 0.0, 0.0, 0.0], [pe.BONE["rho"], pe.BONE["cp"], cs, ap, as_]])
    # source: plane z = iz_src, Gaussian apodization, per-column delay for the tilt
    src = np.zeros((nx, ny, nz), np.uint32)
    wts = np.zeros((nx, ny, nz), np.float32)
    ap_xy = np.exp(-(((x - x_src_c)[:, None]) ** 2 + (y[None, :]) ** 2) / waist_m**2)
    ap_xy[ap_xy < 1e-4] = 0.0
    cols = np.nonzero(ap_xy.max(axis=1) > 0)[0]
    src[cols, :, iz_src] = (np.arange(cols.size) + 1)[:, None] * (ap_xy[cols, :] > 0)
    wts[:, :, iz_src] = ap_xy
    tilt = geometry == "aligned"
    delays = ((x[cols] - x[cols].min()) * np.sin(th) / C_W) if tilt else np.zeros(cols.size)
    n_cyc = 4.0
    t_travel = (z[iz_sens] - z[iz_src]) / (C_W * np.cos(th) if tilt else C_W) + 6.5e-3 / 1500.0
    duration = n_cyc / F0 + delays.max() + t_travel + 25e-6
    # dt: Babel's own (CFL) for the bone, unless given (to share dt between runs)
    if dt is None:
        props_dt = np.array(
            [
                [RHO_W, C_W, 0.0, 0.0, 0.0],
                [pe.BONE["rho"], pe.BONE["cp"], 1500.0, pe.alpha_np_per_m(4.0), pe.alpha_np_per_m(4.0)],
            ]
        )
        mat_dt = mat.copy()
        mat_dt[nx // 2, ny // 2, nz // 2] = 1
        _, dt = PM.StaggeredFDTD_3D_with_relaxation(
            mat_dt,
            props_dt,
            F0,
            src,
            np.zeros((cols.size, 10)),
            dx,
            duration,
            np.ones_like(src),
            Ox=wts,
            Oy=np.array([1]),
            Oz=np.array([1]),
            TypeSource=2,
            CheckOnlyParams=True,
            USE_SINGLE=True,
            COMPUTING_BACKEND=0,
        )
        dt = float(dt)
    nt = int(np.ceil(duration / dt)) + 1
    t = np.arange(nt) * dt
    sf = np.stack([tone_burst(t - dly, n_cyc) for dly in delays]).astype(np.float32)
    sens = np.zeros((nx, ny, nz), np.uint32)
    i0, i1 = npml + 1, nx - npml - 1
    j0, j1 = npml + 1, ny - npml - 1
    sens[i0:i1, j0:j1, iz_sens] = 1
    nvox = nx * ny * nz
    if verbose:
        print(
            f"[babel] angle {angle_deg} deg, {geometry}, plate={with_plate}, dx {dx * 1e3} mm, grid {nx}x{ny}x{nz} = "
            f"{nvox / 1e6:.2f} M voxels, dt {dt * 1e9:.2f} ns, {nt} steps, est {nvox * nt * 80e-9:.0f} s",
            flush=True,
        )
    t0 = time.time()
    out = PM.StaggeredFDTD_3D_with_relaxation(
        mat,
        props,
        F0,
        src,
        sf,
        dx,
        duration,
        sens,
        Ox=wts,
        Oy=np.array([1]),
        Oz=np.array([1]),
        NDelta=npml,
        DT=dt,
        TypeSource=2,
        USE_SINGLE=True,
        COMPUTING_BACKEND=0,
        SelRMSorPeak=1,
        SelMapsRMSPeakList=["Pressure"],
        SelMapsSensorsList=["Pressure"],
        SensorSubSampling=1,
        SILENT=1,
    )
    wall = time.time() - t0
    sensor = out[0]
    p = sensor["Pressure"]
    ts = sensor["time"]
    idx = np.nonzero(np.transpose(sens).flatten() > 0)[0]
    ii, jj, _ = np.unravel_index(idx, sens.shape, order="F")
    P = np.zeros((i1 - i0, j1 - j0), complex)
    P[ii - i0, jj - j0] = dft_at(p.astype(float), ts)
    e = (p.astype(float) ** 2).sum(axis=0)
    tail = float(e[int(0.9 * e.size) :].sum() / e.sum())
    if verbose:
        print(f"[babel]   run time {wall:.1f} s; energy fraction in last 10 % of record {tail:.2e}", flush=True)
    return dict(
        P=P,
        dt=dt,
        nt=nt,
        wall=wall,
        grid=[nx, ny, nz],
        d_m=d_m,
        normal=normal,
        tail=tail,
        iz=[int(iz_src), int(iz_sens)],
    )


CACHE = os.environ.get("FW_CACHE", "/tmp/fw_cache")


def babel_water(ang, dx, geometry, waist_m):
    """Water-only run (cached on disk: it depends only on angle, grid, geometry, beam)."""
    os.makedirs(CACHE, exist_ok=True)
    path = os.path.join(CACHE, f"babel_water_{ang:g}_{dx * 1e3:g}_{geometry}_{waist_m * 1e3:g}.npz")
    if os.path.exists(path):
        z = np.load(path, allow_pickle=True)
        print(f"[babel] water run from cache {path}", flush=True)
        return z["w"].item()
    w = babel_run(ang, dx, geometry, 1500.0, True, waist_m, False)
    np.savez(path, w=np.array(w, dtype=object))
    return w


def run_babel(args):
    _, ver = babel_import()
    dx = args.dx_mm * 1e-3
    rows = []
    for ang in args.angles_deg:
        w = babel_water(ang, dx, args.geometry, args.waist_mm * 1e-3)
        p = babel_run(ang, dx, args.geometry, args.cs, not args.lossless, args.waist_mm * 1e-3, True, dt=w["dt"])
        c = compare_spectra(
            p["P"],
            w["P"],
            dx,
            p["normal"],
            cs=max(args.cs, 1.0),
            lossy=not args.lossless,
            d_m=p["d_m"],
            fluid=args.cs == 0,
        )
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
            record_tail_energy_fraction=p["tail"],
        )
        rows.append(row)
        print(
            f"angle {ang:5.1f}: engine |T|^2 {row['power_ratio_engine']:.4f}  exact {row['power_ratio_exact']:.4f}  "
            f"(fluid plate {row['power_ratio_exact_fluid_plate']:.4f})  ratio {row['ratio_engine_over_exact']:.3f}  "
            f"amp engine {abs(c['amp_engine']):.3f}<{np.angle(c['amp_engine'], True):.0f}  exact "
            f"{abs(c['amp_exact']):.3f}<{np.angle(c['amp_exact'], True):.0f}",
            flush=True,
        )
        save(
            args,
            rows,
            dict(
                engine="BabelViscoFDTD",
                engine_version=ver,
                geometry=args.geometry,
                waist_mm=args.waist_mm,
                source="additive stress, Hann 4-cycle burst",
                pml_cells=12,
                precision="single",
            ),
        )


def save(args, rows, meta):
    os.makedirs(RESULTS, exist_ok=True)
    tag = f"{args.engine}_{args.dx_mm:g}mm"
    if args.geometry != "aligned":
        tag += f"_{args.geometry}"
    if args.lossless:
        tag += "_lossless"
    if args.cs != 1500.0:
        tag += f"_cs{args.cs:g}"
    path = os.path.join(RESULTS, f"plate_transmission_{tag}.json")
    if os.path.exists(path):  # merge with earlier invocations (other angles)
        old = json.load(open(path)).get("rows", [])
        new_angles = {round(r["angle_deg"], 6) for r in rows}
        rows = sorted(
            [r for r in old if round(r["angle_deg"], 6) not in new_angles] + list(rows), key=lambda r: r["angle_deg"]
        )
    doc = dict(
        meta,
        dx_mm=args.dx_mm,
        f0_hz=F0,
        plate_thickness_nominal_mm=pe.D_M * 1e3,
        water=dict(c_m_s=C_W, rho_kg_m3=RHO_W),
        plate=dict(
            cp_m_s=pe.BONE["cp"],
            cs_m_s=args.cs,
            rho_kg_m3=pe.BONE["rho"],
            alpha_p_db_cm=0.0 if args.lossless else pe.BONE["alpha_p_db_cm"],
            alpha_s_db_cm=0.0 if args.lossless else pe.BONE["alpha_s_db_cm"],
        ),
        numpy_version=np.__version__,
        rows=rows,
    )
    with open(path, "w") as fh:
        json.dump(doc, fh, indent=1)
    print(f"wrote {path}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--engine", choices=["babel", "fdtd2d"], required=True)
    ap.add_argument("--dx-mm", type=float, default=0.5)
    ap.add_argument("--angles-deg", type=float, nargs="*", default=[0, 10, 20, 25, 30, 35, 40, 50])
    ap.add_argument("--geometry", choices=["aligned", "tilted"], default="aligned")
    ap.add_argument("--cs", type=float, default=1500.0, help="plate shear speed, m/s")
    ap.add_argument("--lossless", action="store_true", help="no attenuation in the plate")
    ap.add_argument("--record-us", type=float, default=160.0, help="record length (fdtd2d)")
    ap.add_argument(
        "--waist-mm", type=float, default=12.0, help="Gaussian beam waist (babel; fdtd2d --geometry tilted)"
    )
    args = ap.parse_args()
    t0 = time.time()
    if args.engine == "babel":
        run_babel(args)
    else:
        import fdtd2d

        if args.geometry == "tilted":
            fdtd2d.run_tilted(args, compare_spectra, save)
        else:
            fdtd2d.run(args, compare_spectra, save)
    print(f"total time {time.time() - t0:.1f} s")


if __name__ == "__main__":
    main()
