"""The 3-D pressure amplitude or intensity of a beam, as a volume file opens it:
``Simulation.pressure_volume`` and ``Field.pressure_volume`` return a :class:`PressureVolume`,
``Field.intensity_volume`` an :class:`IntensityVolume`; ``to_nifti`` writes either for 3D Slicer,
ITK-SNAP or FSLeyes."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from arfi.io.files import write_volume


class _OnVoxels:
    """What a volume's voxels share: ``affine_mm`` (4 x 4, voxel (i, j, k) to mm in ``frame``)."""

    affine_mm: NDArray[np.float64]
    frame: str

    def position_mm(self, index_kji: tuple[int, int, int]) -> NDArray[np.float64]:
        """The position (mm, in ``frame``) of the voxel ``[k, j, i]`` of the volume's array."""
        k, j, i = index_kji
        return (self.affine_mm @ np.array([i, j, k, 1.0]))[:3]

    def _write(self, path: str | os.PathLike[str], values: NDArray[np.float32], quantity: str) -> None:
        """Writes ``values`` as NIfTI-1 (``.nii`` or ``.nii.gz``) with the affine (mm) as qform and
        sform and ``quantity`` in the header, atomically (nothing is left behind on failure)."""
        where = "the CT's voxels, RAS" if self.frame == "ct" else "transducer frame"
        write_volume(path, values, self.affine_mm, f"arfi: {quantity}, {where}")


@dataclass(frozen=True)
class PressureVolume(_OnVoxels):
    """``|p|`` (Pa) on a box of the simulation grid, from one march.

    ``pressure_pa``: float32, shape (nk, nj, ni), indexed [k, j, i]; ``affine_mm``: 4 x 4, voxel
    (i, j, k) to mm in ``frame``: ``"transducer"`` (the simulation grid, i along x, j along y, k
    along z: the frame of ``focal_peak_mm``) or ``"ct"`` (the CT's voxels and its RAS+ affine)."""

    pressure_pa: NDArray[np.float32]
    affine_mm: NDArray[np.float64]
    frame: str = "transducer"

    def to_nifti(self, path: str | os.PathLike[str]) -> None:
        """Writes ``|p|`` (Pa) as NIfTI-1 (``.nii`` or ``.nii.gz``) with its affine (mm) as qform
        and sform, atomically (nothing is left behind on failure)."""
        self._write(path, self.pressure_pa, "|p| (Pa)")


@dataclass(frozen=True)
class IntensityVolume(_OnVoxels):
    """The pulse-average intensity I = ``|p|² / (2·ρ·c)`` (W/cm²) in 3-D, ρ and c the medium's at
    each voxel (the CT's conversion where it holds tissue), as the focal metrics' ``isppa_w_cm2``
    (I at the focal peak: the spatial peak, I_SPPA) and the hottest places take them.

    ``intensity_w_cm2``: float32, shape (nk, nj, ni), indexed [k, j, i]; ``affine_mm`` and
    ``frame`` as :class:`PressureVolume`'s."""

    intensity_w_cm2: NDArray[np.float32]
    affine_mm: NDArray[np.float64]
    frame: str = "transducer"

    def to_nifti(self, path: str | os.PathLike[str]) -> None:
        """Writes the intensity (W/cm²) as NIfTI-1 (``.nii`` or ``.nii.gz``) with its affine (mm) as
        qform and sform, atomically (nothing is left behind on failure)."""
        self._write(path, self.intensity_w_cm2, "I = p^2/(2 rho c) (W/cm2)")
