#!/usr/bin/env python3
"""The angles at which each element's straight ray to the target meets the skull of a CT scenario.

For every element, the line from its centre to the target is sampled every half voxel; its first
and last crossings of the CT's bone (HU >= 300, the conversion's default ``bone_from_hu``) are the
skull's outer and inner surfaces, whose normals are the gradient of the bone mask smoothed over
one voxel. Prints, per surface, the median, 90th percentile and largest angle of incidence and the
share of rays beyond 25° (where mode conversion to shear starts to matter) and 32° (the critical
angle from water into cortical bone). Needs scipy (``pip install -e ".[test]"``).

Usage::

    python docs/incidence_angles.py head.toml [--target-mm X Y Z]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import nibabel as nib
import numpy as np
import tomllib
from scipy.ndimage import gaussian_filter, map_coordinates

from arfi.scenario import Scenario
from arfi.simulation import Simulation


def incidence_angles(toml: Path, target_mm: np.ndarray | None) -> dict[str, np.ndarray]:
    cfg = tomllib.loads(toml.read_text())
    img = nib.load(toml.parent / cfg["ct"]["file"])
    to_transducer = np.array(cfg["ct"].get("patient_to_transducer_mm", np.eye(4)), float) @ img.affine
    to_voxel = np.linalg.inv(to_transducer)
    bone = (np.asarray(img.dataobj, dtype=np.float32) >= 300).astype(np.float32)
    gradients = np.gradient(gaussian_filter(bone, 1.0))
    sim = Simulation(Scenario.load(toml))
    target = np.asarray(sim.focus_mm if target_mm is None else target_mm, float)
    step = 0.5 * np.abs(np.linalg.svd(to_transducer[:3, :3], compute_uv=False)).min()
    angles: dict[str, list[float]] = {"outer": [], "inner": []}
    for element in sim.element_positions_mm:
        d = target - element
        length = np.linalg.norm(d)
        d /= length
        points = element[None, :] + np.arange(0.0, length, step)[:, None] * d[None, :]
        voxels = (to_voxel @ np.c_[points, np.ones(len(points))].T)[:3]
        crossings = np.flatnonzero(np.diff(map_coordinates(bone, voxels, order=0, mode="constant")) != 0)
        if len(crossings) < 2:
            continue
        for surface, k in (("outer", crossings[0]), ("inner", crossings[-1])):
            g = np.array([map_coordinates(c, voxels[:, k : k + 1], order=1)[0] for c in gradients])
            normal = np.linalg.solve(to_transducer[:3, :3].T, g)  # a gradient transforms covariantly
            if np.linalg.norm(normal) > 0:
                cosine = abs(normal @ d) / np.linalg.norm(normal)
                angles[surface].append(np.degrees(np.arccos(min(1.0, cosine))))
    return {k: np.array(v) for k, v in angles.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", type=Path)
    ap.add_argument("--target-mm", type=float, nargs=3, help="the target (default: the scenario's focus)")
    a = ap.parse_args()
    for surface, v in incidence_angles(a.scenario, None if a.target_mm is None else np.array(a.target_mm)).items():
        print(
            f"{surface}: {len(v)} rays, median {np.median(v):.0f}°, 90th percentile {np.percentile(v, 90):.0f}°, max "
            f"{v.max():.0f}°, beyond 25°: {100 * (v > 25).mean():.0f} %, beyond 32°: {100 * (v > 32).mean():.0f} %"
        )


if __name__ == "__main__":
    main()
