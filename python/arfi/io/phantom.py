"""A synthetic head CT for tests, examples and users without a CT: a seeded skull-like shell.

The head is an ellipsoid (semi-axes 72 × 90 × 80 mm in x, y, z, patient frame, centred on the
brain) of scalp, skull and brain in air. The skull's thickness varies smoothly over the head
between ``thickness_mm`` bounds (a random smooth field on the sphere, fixed by ``seed``). Across
it, from outside in: an outer cortical table (30 % of the thickness, 1.2–2.5 mm), the diploë
(cancellous bone), and an inner table (20 %, 1–2 mm). Values are Hounsfield units as a clinical
scanner reports them: air −1000, scalp 40, brain 35, cortical bone about 1700, diploë about 800
(both varying smoothly over the head, the diploë also voxel by voxel with its porosity), plus
Gaussian noise (``noise_hu``, 20 HU by default), stored as int16.

The volume is written in the patient frame: the NIfTI affine maps voxels to RAS+ mm with the
brain's centre at the origin and the crown towards +z. :func:`placement` gives the rigid
``patient_to_transducer_mm`` that puts a point of the head at the focus with the crown facing the
array (the scenario's ``[ct]`` key).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

#: Semi-axes (mm) of the outer skull surface, x (left–right), y (front–back), z (up).
HEAD_SEMI_AXES_MM = (72.0, 90.0, 80.0)
#: Scalp thickness outside the skull, mm.
SCALP_MM = 5.0
#: The volume's extent (mm, patient frame): the head down to 40 mm below its centre.
EXTENT_MM = ((-80.0, 80.0), (-98.0, 98.0), (-40.0, 88.0))


@dataclass(frozen=True)
class HeadPhantom:
    """A synthetic head CT: ``hu`` (int16, shape (ni, nj, nk): x, y, z) and its affine (voxel →
    RAS+ mm), with the skull thickness (mm) the seed drew."""

    hu: NDArray[np.int16]
    affine: NDArray[np.float64]
    thickness_mm: tuple[float, float, float]
    seed: int

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the volume as NIfTI-1 (``.nii`` or ``.nii.gz``), atomically."""
        import nibabel as nib

        from arfi.io.files import atomic_path

        p = Path(path)
        if not p.name.endswith((".nii", ".nii.gz")):
            raise ValueError(f"out: {p}: a CT must be written as .nii or .nii.gz")
        img = nib.Nifti1Image(self.hu, self.affine)
        img.set_qform(self.affine, code=1)
        img.set_sform(self.affine, code=1)
        img.header.set_xyzt_units(xyz="mm")
        img.header.set_slope_inter(1.0, 0.0)
        img.header["descrip"] = f"arfi head phantom, seed {self.seed} (HU)".encode()
        with atomic_path(p) as tmp:
            nib.save(img, str(tmp))


#: Parameters of one smooth field on the sphere: axes, spatial frequencies, phases, weights.
_Smooth = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def _draw_smooth(rng: np.random.Generator, terms: int = 8) -> _Smooth:
    """A smooth random field on the unit sphere: ``terms`` cosines of the angle to random axes
    (wavelengths of a quarter to a half of the head)."""
    axes = rng.normal(size=(terms, 3))
    return (
        axes / np.linalg.norm(axes, axis=1, keepdims=True),
        rng.uniform(1.5, 4.0, terms),
        rng.uniform(0, 2 * np.pi, terms),
        rng.uniform(0.5, 1.0, terms),
    )


def _smooth(directions: NDArray[np.float64], field: _Smooth) -> NDArray[np.float64]:
    """The field at unit ``directions`` (..., 3), in [−1, 1]."""
    axes, freq, phase, weight = field
    out = np.zeros(directions.shape[:-1])
    for a, f, p, w in zip(axes, freq, phase, weight):
        out += w * np.cos(f * (directions @ a) + p)
    return out / weight.sum()


def head_phantom(
    seed: int = 0, voxel_mm: float = 0.5, thickness_mm: tuple[float, float] = (4.0, 9.0), noise_hu: float = 20.0
) -> HeadPhantom:
    """The seeded head CT (see the module docs). ``voxel_mm``: isotropic voxel size (0.2–2 mm);
    ``thickness_mm``: the skull's thinnest and thickest (1–15 mm); ``noise_hu`` ≥ 0."""
    if not (np.isfinite(voxel_mm) and 0.2 <= voxel_mm <= 2.0):
        raise ValueError(f"voxel_mm: must lie in 0.2…2 mm, got {voxel_mm}")
    lo_t, hi_t = (float(v) for v in thickness_mm)
    if not (np.isfinite(lo_t) and np.isfinite(hi_t) and 1.0 <= lo_t <= hi_t <= 15.0):
        raise ValueError(f"thickness_mm: need 1 <= thinnest <= thickest <= 15 mm, got {thickness_mm}")
    if not (np.isfinite(noise_hu) and noise_hu >= 0):
        raise ValueError(f"noise_hu: must be a finite number >= 0, got {noise_hu}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: must be an integer >= 0, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    thickness_field, cortical_field, diploe_field = (_draw_smooth(rng) for _ in range(3))
    axes = [np.arange(lo + 0.5 * voxel_mm, hi, voxel_mm) for lo, hi in EXTENT_MM]
    hu = np.empty(tuple(len(a) for a in axes), dtype=np.int16)
    semi = np.asarray(HEAD_SEMI_AXES_MM)
    # Filled slice by slice along z: memory stays at a few slices of float64.
    x, y = np.meshgrid(axes[0], axes[1], indexing="ij")
    thickness_range = []
    for k, z in enumerate(axes[2]):
        p = np.stack([x, y, np.full_like(x, z)], axis=-1)
        r = np.linalg.norm(p, axis=-1)
        safe = np.maximum(r, 1e-9)
        directions = p / safe[..., None]
        r_ell = np.linalg.norm(p / semi, axis=-1)
        depth = safe * (1.0 - r_ell) / np.maximum(r_ell, 1e-9)  # below the outer skull surface, mm
        t = lo_t + (hi_t - lo_t) * 0.5 * (1.0 + _smooth(directions, thickness_field))
        thickness_range.append((t.min(), t.max()))
        outer = np.clip(0.3 * t, 1.2, 2.5)
        inner = np.clip(0.2 * t, 1.0, 2.0)
        cortical = 1700.0 + 150.0 * _smooth(directions, cortical_field)
        diploe = 800.0 + 150.0 * _smooth(directions, diploe_field) + 120.0 * rng.standard_normal(x.shape)
        v = np.full(x.shape, -1000.0)
        v[depth >= -SCALP_MM] = 40.0
        v[depth >= 0] = cortical[depth >= 0]
        mid = (depth >= outer) & (depth < t - inner)
        v[mid] = diploe[mid]
        v[depth >= t] = 35.0
        if noise_hu > 0:
            v += noise_hu * rng.standard_normal(x.shape)
        hu[:, :, k] = np.clip(np.rint(v), -1024, 3071).astype(np.int16)
    affine = np.diag([voxel_mm, voxel_mm, voxel_mm, 1.0])
    affine[:3, 3] = [a[0] for a in axes]
    t_all = np.asarray(thickness_range)
    thick = (float(t_all[:, 0].min()), float(t_all[:, 1].max()), float(0.5 * (lo_t + hi_t)))
    return HeadPhantom(hu=hu, affine=affine, thickness_mm=thick, seed=int(seed))


#: The hemisphere's focus (its centre) in the transducer frame, mm, and its scenario lines.
HEMISPHERE_FOCUS_MM = (0.0, 0.0, 150.0)
HEMISPHERE_TOML = (
    'frequency_hz = 650000.0\n\n[transducer]\nkind = "hemisphere"\nradius_of_curvature_mm = 150.0\n'
    "polar_angle_max_deg = 60.0\nelements = 1024\n\n[focus]\nposition_mm = [0.0, 0.0, 150.0]\n"
)


def array_focus_mm(array: str) -> tuple[float, float, float]:
    """The focus of ``array`` (``planar``: the paper's array, 85 mm in front of it; ``hemisphere``:
    its centre), transducer frame, mm."""
    return HEMISPHERE_FOCUS_MM if array == "hemisphere" else (0.0, 0.0, 85.0)


def scenario_for(ct_path: str, seed: int, array: str) -> str:
    """The scenario (TOML) of the phantom written to ``ct_path`` (as the scenario's ``[ct] file``,
    relative to its folder) with ``array`` focused at :func:`array_focus_mm`: the head placed by
    :func:`placement`, conversion ``aubry2003``, water around it."""
    rows = ", ".join("[" + ", ".join(f"{v:g}" for v in row) + "]" for row in placement(focus_mm=array_focus_mm(array)))
    return (
        f'name = "head-phantom-seed{seed}"\n'
        + (HEMISPHERE_TOML if array == "hemisphere" else "")
        + f'\n[ct]\nfile = "{ct_path}"\nconversion = "aubry2003"\npatient_to_transducer_mm = [{rows}]\n'
    )


def placement(
    target_mm: tuple[float, float, float] = (0.0, 0.0, 20.0), focus_mm: tuple[float, float, float] = (0.0, 0.0, 85.0)
) -> NDArray[np.float64]:
    """The rigid ``patient_to_transducer_mm`` putting the head's point ``target_mm`` (patient frame,
    LPS mm: x and y negated from the NIfTI's RAS) at ``focus_mm`` with the crown facing the array
    (a half turn about x: the patient's up is the beam's −z)."""
    t = np.diag([1.0, -1.0, -1.0, 1.0])
    target = np.asarray(target_mm, dtype=np.float64)
    t[:3, 3] = np.asarray(focus_mm, dtype=np.float64) - t[:3, :3] @ target
    return t
