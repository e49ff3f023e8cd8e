"""Files: MR-ARFI images (one-slice NIfTI of the ARFI phase in rad, its affine in the transducer
frame in mm, and a JSON sidecar that may hold the ``applied_phases_rad``), phase vectors, field
archives.

Every writer goes through a temporary file in the target folder and an atomic rename, so a
failed or interrupted run leaves no partial file and never clobbers a good one.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import tempfile
import zlib
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yields a temporary path beside ``path`` (same suffixes); renamed onto ``path`` on success,
    removed on failure. The file gets the mode a plain ``open(path, "w")`` would give it (the
    replaced file's, else 0o666 less the umask), not the private 0o600 of the temporary file."""
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"{target}: folder {folder} does not exist")
    suffix = "".join(target.suffixes) or ".tmp"
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=folder)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, _mode_for(target))
        os.replace(tmp_path, target)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def _umask() -> int:
    """The process's umask, read without changing it where the system allows (Linux), else by
    setting and restoring it."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _mode_for(target: Path) -> int:
    """The permission bits a new or rewritten ``target`` should have: an existing file's own,
    else those of a newly created file (0o666 less the umask)."""
    try:
        return target.stat().st_mode & 0o7777
    except OSError:
        return 0o666 & ~_umask()


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Writes text atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(path: str | os.PathLike[str], data: dict[str, Any]) -> None:
    """Writes JSON atomically (NumPy scalars and arrays converted)."""

    def convert(o: Any) -> Any:
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")

    atomic_write_text(path, json.dumps(data, indent=2, default=convert, allow_nan=False) + "\n")


def sidecar_path(image_path: str | os.PathLike[str]) -> Path:
    """The BIDS-style sidecar of an image: same stem, ``.json``."""
    p = Path(image_path)
    name = p.name
    for ext in (".nii.gz", ".nii"):
        if name.endswith(ext):
            return p.with_name(name[: -len(ext)] + ".json")
    return p.with_suffix(".json")


def arfi_image_path(path: str | os.PathLike[str]) -> Path:
    """``path`` if it names an MR-ARFI image file (``.nii`` or ``.nii.gz``); else ``ValueError``.
    Callers check an output name with it before computing what they will write."""
    p = Path(path)
    if not p.name.endswith((".nii", ".nii.gz")):
        raise ValueError(f"out: {p}: an MR-ARFI image must be written as .nii or .nii.gz")
    return p


def volume_path(path: str | os.PathLike[str], name: str = "volume") -> Path:
    """``path`` if it names a NIfTI volume (``.nii`` or ``.nii.gz``) in a folder that exists; else
    ``ValueError`` naming ``name``. Checked before the volume is computed."""
    p = Path(path)
    if not p.name.endswith((".nii", ".nii.gz")):
        raise ValueError(f"{name}: {p}: a volume must be written as .nii or .nii.gz")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"{name}: {p}: folder {folder} does not exist")
    return p


def write_volume(path: str | os.PathLike[str], values: ArrayLike, affine_mm: ArrayLike, description: str) -> None:
    """Writes a 3-D volume given as [k, j, i] as NIfTI-1 (i fastest, as NIfTI orders voxels,
    float32) with its 4 x 4 affine (mm) as qform and sform, atomically."""
    save_nifti(volume_path(path), np.asarray(values, dtype=np.float32).transpose(2, 1, 0), affine_mm, description)


def save_nifti(path: Path, data: NDArray[np.float32], affine_mm: ArrayLike, description: str) -> None:
    """Writes ``data`` (indexed [i, j, k]) as NIfTI-1 with the 4 x 4 ``affine_mm`` as qform and
    sform, units mm and ``description`` in the header, atomically."""
    import nibabel as nib

    img = nib.Nifti1Image(data, np.asarray(affine_mm, dtype=np.float64))
    img.set_qform(img.affine, code=1)
    img.set_sform(img.affine, code=1)
    img.header.set_xyzt_units(xyz="mm")
    img.header["descrip"] = description.encode()[:79]
    with atomic_path(path) as tmp:
        if tmp.name.endswith(".gz"):
            with open(tmp, "wb") as f, ParallelGzip(f) as z:
                img.to_stream(z)
        else:
            nib.save(img, str(tmp))


class ParallelGzip(io.RawIOBase):
    """A write-only stream that gzips what it is given in blocks on a pool of threads (zlib
    releases the GIL), at level 1 as nibabel's default: each block one gzip member, written in
    order. A file of several members is a valid gzip file (RFC 1952 §2.2), read whole by gzip,
    zlib's ``gzread`` (ITK, FSL) and nibabel. At most two blocks per thread wait in memory."""

    BLOCK = 1 << 24

    def __init__(self, f: Any, threads: int | None = None) -> None:
        super().__init__()
        self.f = f
        self.threads = threads or min(4, os.cpu_count() or 1)
        self.pool = ThreadPoolExecutor(self.threads)
        self.pending: deque[Future[bytes]] = deque()
        self.buffer = bytearray()
        self.position = 0

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def tell(self) -> int:
        return self.position

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        """Only forward, as a writer of one pass does (nibabel seeks to where it writes next): the
        gap is written as zeros."""
        target = offset if whence == io.SEEK_SET else self.position + offset if whence == io.SEEK_CUR else -1
        if target < self.position:
            raise io.UnsupportedOperation("ParallelGzip: seeks forward only")
        self.write(bytes(target - self.position))
        return self.position

    def write(self, data: Any) -> int:
        view = memoryview(data).cast("B")
        self.position += view.nbytes
        self.buffer += view
        while len(self.buffer) >= self.BLOCK:
            with memoryview(self.buffer) as whole:
                block = bytes(whole[: self.BLOCK])
            del self.buffer[: self.BLOCK]
            self._submit(block)
        return view.nbytes

    def _submit(self, block: bytes) -> None:
        self.pending.append(self.pool.submit(gzip_member, block))
        while len(self.pending) > 2 * self.threads:
            self.f.write(self.pending.popleft().result())

    def close(self) -> None:
        """Writes what is left, in order (a worker's error is raised here)."""
        if not self.closed:
            try:
                if self.buffer:
                    self._submit(bytes(self.buffer))
                    self.buffer.clear()
                while self.pending:
                    self.f.write(self.pending.popleft().result())
            finally:
                self.abandon()

    def abandon(self) -> None:
        """Stops without writing what is pending (the file is left incomplete: the caller's
        atomic rename then does not happen)."""
        for future in self.pending:
            future.cancel()
        self.pending.clear()
        self.pool.shutdown(cancel_futures=True)
        super().close()

    def __exit__(self, kind: Any, value: Any, traceback: Any) -> None:
        if kind is None:
            self.close()
        else:
            self.abandon()


def gzip_member(block: bytes) -> bytes:
    """``block`` as one gzip member at compression level 1."""
    z = zlib.compressobj(1, zlib.DEFLATED, 31)
    return z.compress(block) + z.flush()


def npz_path(path: str | os.PathLike[str]) -> Path:
    """``path`` if it names a field archive (``.npz``); else ``ValueError``."""
    p = Path(path)
    if p.suffix != ".npz":
        raise ValueError(f"out: {p}: a field archive must be written as .npz")
    return p


def write_arfi_image(
    path: str | os.PathLike[str],
    image: ArrayLike,
    affine_mm: ArrayLike,
    volume_shape: tuple[int, int, int],
    sidecar: dict[str, Any] | None = None,
) -> None:
    """Writes an MR-ARFI phase image (rad) as NIfTI with its affine (mm, transducer frame), and
    the sidecar JSON when given; pixels without MR signal are NaN."""
    p = arfi_image_path(path)
    save_nifti(
        p,
        np.asarray(image, dtype=np.float32).reshape(volume_shape),
        affine_mm,
        "arfi: MR-ARFI displacement phase (rad)",
    )
    if sidecar is not None:
        write_json(sidecar_path(p), sidecar)


def read_arfi_image(path: str | os.PathLike[str]) -> tuple[NDArray[np.float64], NDArray[np.float64], dict[str, Any]]:
    """Reads an MR-ARFI image: (image as 2-D float64 with the singleton axis removed, 4x4 affine
    in mm, sidecar dict or {}). NaN marks a pixel without MR signal (bone, air, a masked-out
    pixel); fits leave it out. Raises FileNotFoundError or ValueError naming the file."""
    import nibabel as nib

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"image: {p}: no such file")
    try:
        img = nib.load(str(p))
        if not isinstance(img, nib.spatialimages.SpatialImage):
            raise ValueError(f"a {type(img).__name__}, not an image")
        data = np.asarray(img.get_fdata(dtype=np.float64))
    except Exception as e:  # nibabel raises many types for corrupt files
        raise ValueError(f"image: {p}: not a readable NIfTI file ({e})") from None
    squeezed = data.reshape([n for n in data.shape if n != 1]) if data.ndim > 2 else data
    if squeezed.ndim != 2:
        raise ValueError(f"image: {p}: must hold one 2-D slice, got shape {data.shape}")
    if np.any(np.isinf(squeezed)):
        raise ValueError(
            f"image: {p}: contains infinite pixels (NaN marks a pixel without MR signal; infinity is no phase)"
        )
    if not np.any(np.isfinite(squeezed)):
        raise ValueError(f"image: {p}: every pixel is NaN (no MR signal anywhere)")
    side: dict[str, Any] = {}
    sp = sidecar_path(p)
    if sp.is_file():
        try:
            side = json.loads(sp.read_text(encoding="utf-8"))
        except (ValueError, UnicodeDecodeError) as e:
            raise ValueError(f"sidecar: {sp}: not valid JSON ({e})") from None
        if not isinstance(side, dict):
            raise ValueError(f"sidecar: {sp}: must hold a JSON object")
    return squeezed, np.asarray(img.affine, dtype=np.float64), side


def read_phases(path: str | os.PathLike[str], name: str = "phases") -> NDArray[np.float64]:
    """Reads a phase vector (rad): ``.npy``, or text with one value per line."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{name}: {p}: no such file")
    try:
        if p.suffix == ".npy":
            a = np.load(p, allow_pickle=False)
        else:
            lines = [ln.strip() for ln in p.read_text(encoding="utf-8").splitlines()]
            a = np.array([float(ln) for ln in lines if ln and not ln.startswith("#")], dtype=np.float64)
    except Exception as e:  # numpy raises many types (EOFError, UnpicklingError, ...) for corrupt files
        raise ValueError(f"{name}: {p}: not a phase vector ({e})") from None
    a = np.asarray(a)
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{name}: {p}: must hold real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64).ravel() if a.ndim <= 1 else a
    if a.ndim != 1 or a.size == 0:
        raise ValueError(f"{name}: {p}: must hold a non-empty 1-D vector, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: {p}: contains NaN or infinite values")
    return a


def csv_text(rows: Sequence[dict[str, Any]]) -> str:
    """Rows of one dict each as CSV text, with a header of the first row's keys."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def write_npz(path: str | os.PathLike[str], arrays: dict[str, Any]) -> None:
    """Writes a compressed ``.npz`` atomically."""
    with atomic_path(npz_path(path)) as tmp:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)


#: The columns of a targets file, in mm in the transducer frame.
TARGET_COLUMNS = ("x_mm", "y_mm", "z_mm")


def read_targets(path: str | os.PathLike[str]) -> list[tuple[float, float, float]]:
    """Points from a CSV file with a header naming the columns ``x_mm``, ``y_mm`` and ``z_mm``
    (transducer frame; other columns ignored), one point per row; blank lines skipped.
    ``ValueError`` naming the file (and the line) when it holds none or a value is not a finite
    number."""
    import csv

    with open(path, newline="", encoding="utf-8") as f:
        rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
    if not rows:
        raise ValueError(f"{path}: holds no targets (a header x_mm,y_mm,z_mm and one row per target)")
    header = [c.strip() for c in rows[0]]
    missing = [c for c in TARGET_COLUMNS if c not in header]
    if missing:
        raise ValueError(f"{path}: the header must name the columns x_mm, y_mm, z_mm; it lacks {', '.join(missing)}")
    index = [header.index(c) for c in TARGET_COLUMNS]
    out = []
    for line, row in enumerate(rows[1:], 2):
        try:
            x, y, z = (float(row[i]) for i in index)
        except (IndexError, ValueError):
            raise ValueError(f"{path}: line {line}: needs a number in each of x_mm, y_mm, z_mm, got {row}") from None
        if not np.all(np.isfinite((x, y, z))):
            raise ValueError(f"{path}: line {line}: the target must be finite, got {row}")
        out.append((x, y, z))
    if not out:
        raise ValueError(f"{path}: holds no targets below its header")
    return out
