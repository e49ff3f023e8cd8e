"""Three-layer skull caps with a textured diploë, read from CTs, for checking the march against a
full-wave engine: there is no exact solution through random bone.

The cap is concentric with the focus of the ITRUSST source SC1 (500 kHz bowl, radius of curvature
64 mm, aperture 64 mm), as ``arfi validate``'s ``shell`` case, and layered as the benchmark's flat
skull BM4 seen from the bowl: 1.5 mm of outer cortical bone (radii 35-36.5 mm about the focus), 4 mm
of diploë (31-35 mm), 1 mm of inner cortical bone (30-31 mm), over a cone of 80° half-angle. The CT
has 0.25 mm voxels; cortical bone is the porosity conversion's dense bone (HU 2000: 2800 m/s,
1850 kg/m³), and the diploë's porosity is ``0.5 + 0.15·g`` (clipped to 0.1-0.9), ``g`` a Gaussian
random field of unit variance whose correlation falls to 1/e at ``correlation_mm`` (none: uniform,
porosity 0.5). Trabecular bone's porosity is 0.3-0.9 and its marrow spaces span about 0.5-2 mm;
the cases span a uniform diploë and textures from 1 mm to the wavelength in water (3 mm). Voxels of
porosity above 0.85 (HU below the conversion's bone threshold of 300, about 1 % of a textured
diploë) are read as soft tissue, as a clinical CT's marrow-filled spaces are.

As solids, the scenarios' bone has the dense bone's shear speed 1500 m/s (the porosity conversion
scales it by ``1 - ψ``) and 8 dB/cm/MHz of shear loss: the values of the exact solid plate of
``docs/physics.md``. The march reads the same CT as a fluid.

The random field is made from a counter-based hash (splitmix64) of each voxel's index, not from a
library's random generator, so that the same case gives the same CT on every machine and NumPy
version (to the last bits of ``log``, ``cos`` and the FFT): the stored full-wave results
(``arfi/validation/data/fullwave_caps.json``, made by ``benches/fullwave/caps_fdtd.py``) record the
:func:`fingerprint` of the CT they were made on, and ``arfi validate`` refuses a CT that differs.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from arfi.io.files import save_nifti

#: CT voxel size (mm).
VOXEL_MM = 0.25
#: The focus (and the caps' centre) on the axis (mm).
CENTRE_MM = 64.0
#: Radii about the focus (mm): inner cortical from, diploë from, outer cortical from, to.
RADII_MM = (30.0, 31.0, 35.0, 36.5)
#: Half-angle of the cap about the direction towards the bowl (degrees).
CAP_DEG = 80.0
#: HU of dense (cortical) bone: the porosity conversion's ``hu_max``.
BONE_HU = 2000.0
#: The diploë's mean porosity and the standard deviation of its texture.
DIPLOE_POROSITY = 0.5
DIPLOE_POROSITY_STD = 0.15
#: Dense bone's shear speed (m/s) and shear attenuation (dB/cm/MHz) in the solid scenarios.
SHEAR_M_S = 1500.0
SHEAR_DB_CM_MHZ = 8.0
#: How far past the focus the CT reaches along z (mm): it must cover the focal region.
PAST_FOCUS_MM = 10.5


@dataclass(frozen=True)
class TexturedCap:
    """One case: its name, the diploë's correlation length (mm; None: uniform) and the seed of
    its texture."""

    name: str
    correlation_mm: float | None
    seed: int

    @property
    def description(self) -> str:
        texture = (
            "uniform diploë (porosity 0.5)"
            if self.correlation_mm is None
            else f"diploë textured over {self.correlation_mm:g} mm (porosity 0.5 +- 0.15, seed {self.seed})"
        )
        return (
            "three-layer cap about the focus from a CT (cortical 1.5 mm, diploë 4 mm, cortical 1 mm; radii 30-36.5 "
            f"mm), {texture}"
        )


#: The cases, in the order they run.
CAPS = (
    TexturedCap("cap_uniform", None, 0),
    TexturedCap("cap_texture1", 1.0, 1),
    TexturedCap("cap_texture3", 3.0, 3),
)


def case(name: str) -> TexturedCap:
    """The case called ``name``; ValueError naming the known ones otherwise."""
    for c in CAPS:
        if c.name == name:
            return c
    raise ValueError(f"textured cap: unknown {name}; known: {', '.join(c.name for c in CAPS)}")


def _splitmix64(x: NDArray[np.uint64]) -> NDArray[np.uint64]:
    """The splitmix64 finaliser (Steele, Lea & Flood 2014), elementwise: a bijection of 64-bit
    integers whose outputs pass BigCrush for consecutive inputs."""
    with np.errstate(over="ignore"):
        z = x + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def white_noise(shape: tuple[int, ...], seed: int) -> NDArray[np.float64]:
    """Standard normal values, one per index of ``shape`` (C order), by Box-Muller from two hashed
    uniforms: the same on every machine."""
    n = int(np.prod(shape))
    index = np.arange(n, dtype=np.uint64) + np.uint64(seed) * np.uint64(1 << 40)
    to_unit = 1.0 / float(1 << 53)
    u1 = ((_splitmix64(2 * index) >> np.uint64(11)).astype(np.float64) + 0.5) * to_unit
    u2 = ((_splitmix64(2 * index + np.uint64(1)) >> np.uint64(11)).astype(np.float64) + 0.5) * to_unit
    return (np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)).reshape(shape)


def gaussian_field(
    shape: tuple[int, int, int], voxel_mm: float, correlation_mm: float, seed: int
) -> NDArray[np.float64]:
    """A Gaussian random field of unit variance on ``shape`` whose correlation is
    ``exp(-r²/ℓ²)`` (``ℓ = correlation_mm``): white noise smoothed by a Gaussian kernel of standard
    deviation ``ℓ/2`` (periodic, by FFT), rescaled to unit variance by the kernel's norm."""
    noise = white_noise(shape, seed)
    s = 0.5 * correlation_mm / voxel_mm  # kernel std in voxels
    spectrum = np.fft.rfftn(noise)
    k = [np.fft.fftfreq(n) for n in shape[:-1]] + [np.fft.rfftfreq(shape[-1])]
    kk = sum(np.meshgrid(*[(2 * np.pi * ki) ** 2 for ki in k], indexing="ij", sparse=True))
    smoothed = np.fft.irfftn(spectrum * np.exp(-0.5 * s * s * kk), s=shape, axes=tuple(range(len(shape))))
    # The variance of white noise through a unit-sum Gaussian kernel of std s (in 3-D):
    # 1 / (4·π·s²)^(3/2) for s well above a voxel.
    return smoothed * (4.0 * np.pi * s * s) ** 0.75


def hounsfield(cap: TexturedCap) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """The case's CT: HU indexed [i, j, k] (x, y, z) and its 4 x 4 affine (mm, RAS), the voxel
    centres ``x = (i - (n-1)/2)·h`` as the validation suite's CTs."""
    h = VOXEL_MM
    a, b = RADII_MM[0], RADII_MM[-1]
    sin_cap, cos_cap = np.sin(np.radians(CAP_DEG)), np.cos(np.radians(CAP_DEG))
    half = b * sin_cap + 2 * h
    z_lo = CENTRE_MM - b - 2 * h
    z_hi = max(CENTRE_MM - a * cos_cap, CENTRE_MM + PAST_FOCUS_MM) + 2 * h
    n = int(np.ceil(2 * half / h)) + 1
    nk = int(np.ceil((z_hi - z_lo) / h)) + 1
    x = (np.arange(n) - 0.5 * (n - 1)) * h
    z = z_lo + np.arange(nk) * h
    X, Y, Z = np.meshgrid(x, x, z - CENTRE_MM, indexing="ij", sparse=True)
    r = np.sqrt(X * X + Y * Y + Z * Z)
    in_cone = -Z >= cos_cap * r
    bone = in_cone & (r >= a) & (r <= b)
    diploe = in_cone & (r >= RADII_MM[1]) & (r < RADII_MM[2])
    if cap.correlation_mm is None:
        porosity = np.full((n, n, nk), DIPLOE_POROSITY)
    else:
        g = gaussian_field((n, n, nk), h, cap.correlation_mm, cap.seed)
        porosity = np.clip(DIPLOE_POROSITY + DIPLOE_POROSITY_STD * g, 0.1, 0.9)
    hu = np.where(bone, BONE_HU, -1000.0)
    hu = np.where(diploe, BONE_HU * (1.0 - porosity), hu).astype(np.float32)
    # RAS x = -LPS x (and y), as the suite's CTs.
    c = 0.5 * (n - 1) * h
    affine = np.array([[-h, 0, 0, c], [0, -h, 0, c], [0, 0, h, z_lo], [0, 0, 0, 1.0]])
    return hu, affine


def fingerprint(hu: NDArray[np.float32]) -> str:
    """The SHA-256 of a CT's HU rounded to integers (int16, C order): what a stored reference
    records of the CT it was made on, blind to the last bits that libraries may round apart."""
    return hashlib.sha256(np.ascontiguousarray(np.round(hu).astype(np.int16)).tobytes()).hexdigest()


def write_ct(cap: TexturedCap, path: str | Path) -> str:
    """Writes the case's CT to ``path`` (NIfTI) and returns its :func:`fingerprint`."""
    hu, affine = hounsfield(cap)
    save_nifti(Path(path), hu, affine, f"arfi: {cap.name} (HU)")
    return fingerprint(hu)


def scenario_toml(cap: TexturedCap, ct_file: str, solid: bool = True) -> str:
    """The scenario through the case's CT ``ct_file`` (a path relative to the scenario's folder):
    the suite's source and medium, the porosity conversion with the benchmark's cortical bone and,
    ``solid``, the dense bone's shear (:data:`SHEAR_M_S`, :data:`SHEAR_DB_CM_MHZ`)."""
    shear = (
        f"bone_shear_sound_speed_m_s = {SHEAR_M_S}\nbone_shear_attenuation_db_cm_mhz = {SHEAR_DB_CM_MHZ}\n"
        if solid
        else ""
    )
    return (
        f'name = "{cap.name}"\nfrequency_hz = 500000.0\nacoustic_power_w = 70.0\n\n[transducer]\nkind = "bowl"\n'
        "radius_of_curvature_mm = 64.0\naperture_diameter_mm = 64.0\n\n[focus]\nposition_mm = [0.0, 0.0, "
        f"{CENTRE_MM}]\n\n"
        '[[material]]\nname = "water"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\nattenuation_db_cm_mhz = 0.0\n'
        'attenuation_power = 1.0\n\n[medium]\nbackground = "water"\n\n'
        f'[ct]\nfile = "{ct_file}"\nconversion = "aubry2003"\nhu_max = {BONE_HU}\nbone_sound_speed_m_s = 2800.0\n'
        "bone_density_kg_m3 = 1850.0\nwater_sound_speed_m_s = 1500.0\nwater_density_kg_m3 = "
        f"1000.0\nbone_attenuation_min_db_cm_mhz = 8.0\n{shear}"
    )
