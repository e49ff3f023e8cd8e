"""Output files: written atomically, and readable by whoever the user's umask lets read them (as a
plain ``open(path, "w")`` would), not only by their owner."""

import os
import stat
import subprocess
import sys

import numpy as np
import pytest

from arfi.io import files


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.fixture
def umask():
    """Sets the umask for one test and puts the old one back."""
    old = os.umask(0o022)
    os.umask(old)
    yield lambda m: os.umask(m)
    os.umask(old)


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077, 0o027])
def test_a_new_file_gets_the_mode_open_would_give_it(tmp_path, umask, mask):
    umask(mask)
    reference = tmp_path / "reference.txt"
    with open(reference, "w") as f:
        f.write("x")
    written = tmp_path / "written.json"
    files.write_json(written, {"a": 1})
    assert mode(written) == mode(reference) == 0o666 & ~mask
    nifti = tmp_path / "v.nii.gz"
    files.write_volume(nifti, np.zeros((2, 3, 4)), np.eye(4), "test")
    assert mode(nifti) == 0o666 & ~mask


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_a_rewritten_file_keeps_its_own_mode(tmp_path, umask):
    umask(0o022)
    path = tmp_path / "shared.txt"
    path.write_text("old")
    os.chmod(path, 0o660)
    files.atomic_write_text(path, "new")
    assert path.read_text() == "new" and mode(path) == 0o660


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_the_cli_writes_files_the_group_can_read(tmp_path):
    # The verb's own process, with a umask that lets the group and others read.
    ct, scenario = tmp_path / "ct.nii.gz", tmp_path / "head.toml"
    code = "import os, sys; os.umask(0o022); from arfi.cli import main; sys.exit(main(sys.argv[1:]))"
    r = subprocess.run(
        [sys.executable, "-c", code, "phantom", "--out", str(ct), "--scenario-out", str(scenario), "--voxel-mm", "2"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if r.returncode != 0:
        pytest.fail(r.stderr)
    assert mode(ct) == mode(scenario) == 0o644
