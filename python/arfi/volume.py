"""The 3-D pressure amplitude of a beam, as a volume file opens it: ``Simulation.pressure_volume``
returns a :class:`PressureVolume`, whose ``to_nifti`` writes it for 3D Slicer, ITK-SNAP or FSLeyes."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from arfi.io import write_volume


@dataclass(frozen=True)
class PressureVolume:
    """``|p|`` (Pa) on a box of the simulation grid, from one march.

    ``pressure_pa``: float32, shape (nk, nj, ni), indexed [k, j, i]; ``affine_mm``: 4 x 4, voxel
    (i, j, k) to mm in ``frame``: ``"transducer"`` (the simulation grid, i along x, j along y, k
    along z: the frame of ``focal_peak_mm``) or ``"ct"`` (the CT's voxels and its RAS+ affine)."""

    pressure_pa: NDArray[np.float32]
    affine_mm: NDArray[np.float64]
    frame: str = "transducer"

    def position_mm(self, index_kji: tuple[int, int, int]) -> NDArray[np.float64]:
        """The position (mm, in ``frame``) of the voxel ``pressure_pa[k, j, i]``."""
        k, j, i = index_kji
        return (self.affine_mm @ np.array([i, j, k, 1.0]))[:3]

    def to_nifti(self, path: str | os.PathLike[str]) -> None:
        """Writes ``|p|`` (Pa) as NIfTI-1 (``.nii`` or ``.nii.gz``) with its affine (mm) as qform
        and sform, atomically (nothing is left behind on failure)."""
        where = "the CT's voxels, RAS" if self.frame == "ct" else "transducer frame"
        write_volume(path, self.pressure_pa, self.affine_mm, f"arfi: |p| (Pa), {where}")
