"""``arfi dicom``: an MR-ARFI image from the scanner's two phase series."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from arfi.cli.common import add_common, finish, load_scenario
from arfi.io.files import arfi_image_path, read_phases, write_arfi_image


def register(sub: Any) -> None:
    """Adds the verb to the subcommands ``sub``."""
    p = sub.add_parser(
        "dicom",
        help="MR-ARFI image (NIfTI) from the scanner's two phase series (DICOM)",
        description="Read the phase images acquired with opposite motion-encoding polarity (phi+, phi-), "
        "form the displacement phase 0.5*wrap(phi+ - phi-), carry the scanner geometry into the transducer frame with "
        "a rigid transform, and write it as arfi's MR-ARFI NIfTI (phase in rad, affine in the transducer frame, mm) "
        "and the matching scenario [mr] section. With --scenario, the image must match that scenario's MR geometry.",
        epilog="example: arfi dicom --plus series_plus/ --minus series_minus/ --transform patient_to_transducer.txt "
        "--out measured.nii.gz",
    )
    add_common(p)
    p.add_argument(
        "--plus",
        required=True,
        metavar="PATH",
        help="phase image with positive encoding: a DICOM file, or a directory of one",
    )
    p.add_argument("--minus", required=True, metavar="PATH", help="phase image with negative encoding")
    p.add_argument(
        "--transform",
        metavar="T",
        help="4x4 rigid transform patient (DICOM LPS, mm) -> transducer frame (mm): .npy, "
        'text (4 rows), or JSON {"patient_to_transducer_mm": [[...]]} (default: identity)',
    )
    p.add_argument(
        "--phase-units",
        dest="phase_units",
        choices=["auto", "rad", "mrad", "siemens"],
        default="auto",
        help="stored phase after the DICOM rescale: rad, mrad (GE) or siemens (-4096..4094 = -pi..pi); "
        "auto picks by Manufacturer (default)",
    )
    p.add_argument(
        "--known-phases",
        dest="known_phases",
        metavar="P",
        help="phases (rad) added to the steering for this acquisition, stored in the sidecar (applied_phases_rad)",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="M.nii.gz",
        help="the MR-ARFI image (.nii or .nii.gz) and its JSON sidecar beside it",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from arfi.io.dicom import read_dicom_arfi, read_transform

    out = args.out
    arfi_image_path(out)  # before reading the series
    transform = None if args.transform is None else read_transform(args.transform)
    measured = read_dicom_arfi(args.plus, args.minus, transform, args.phase_units)
    sidecar: dict[str, Any] = {
        "arfi_dicom": {
            "plus": measured.sources[0],
            "minus": measured.sources[1],
            "echo_time_ms": measured.echo_time_ms,
            "mr": measured.mr,
        }
    }
    if args.known_phases:
        sidecar["applied_phases_rad"] = read_phases(args.known_phases, "--known-phases")
    if args.scenario:  # the image must fit the scenario it will be used with (its outline: nothing is built)
        outline = load_scenario(args).outline()
        if "applied_phases_rad" in sidecar:
            outline.known_per_element(sidecar["applied_phases_rad"], f"--known-phases: {args.known_phases}")
        try:
            outline.check_image(measured.image_rad.shape, np.asarray(measured.affine_mm, dtype=np.float64))
        except ValueError:
            m = measured.mr
            raise ValueError(
                f"--scenario: {args.scenario}: its MR geometry does not match the DICOM image (plane {m['plane']}, "
                f"center_mm {np.round(m['center_mm'], 3).tolist()}, fov_mm {np.round(m['fov_mm'], 3).tolist()}, matrix "
                f"{m['matrix']}); run without --scenario to print the matching [mr] section"
            ) from None
    write_arfi_image(out, measured.image_rad, measured.affine_mm, measured.volume_shape, sidecar)
    m, peak = measured.mr, float(np.max(np.abs(measured.image_rad)))
    print(
        f"dicom: {m['matrix'][0]} x {m['matrix'][1]} MR-ARFI image on the {m['plane']} plane, |Δφ| up to {peak:.3f} "
        f"rad -> {out}"
    )
    if not args.scenario:
        print(f"dicom: the scenario's MR geometry for this image:\n{measured.mr_toml()}", end="")
    finish(
        args,
        {
            "out": out,
            "mr": m,
            "echo_time_ms": measured.echo_time_ms,
            "plus": measured.sources[0],
            "minus": measured.sources[1],
            "max_abs_arfi_rad": peak,
        },
    )
    return 0
