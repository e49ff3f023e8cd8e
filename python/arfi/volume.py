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

    ``pressure_pa``: float32, shape (nz, ny, nx), indexed [z, y, x]; ``affine_mm``: 4 x 4, voxel
    (i, j, k) = (x, y, z index) to the transducer frame in mm (the frame of ``focal_peak_mm``)."""

    pressure_pa: NDArray[np.float32]
    affine_mm: NDArray[np.float64]

    def position_mm(self, index_zyx: tuple[int, int, int]) -> NDArray[np.float64]:
        """The transducer-frame position (mm) of the voxel ``pressure_pa[z, y, x]``."""
        k, j, i = index_zyx
        return (self.affine_mm @ np.array([i, j, k, 1.0]))[:3]

    def to_nifti(self, path: str | os.PathLike[str]) -> None:
        """Writes ``|p|`` (Pa) as NIfTI-1 (``.nii`` or ``.nii.gz``) with the affine in the
        transducer frame (mm), atomically (nothing is left behind on failure)."""
        write_volume(path, self.pressure_pa, self.affine_mm, "arfi: |p| (Pa), transducer frame")
