"""Writing the main job's outputs without ever losing data.

`check_output_dir` validates an output location before any work is done; `OutputWriter`
holds an exclusive lock on it for the whole run, stages every file in a hidden sibling
folder and swaps the staged folder into place on `OutputWriter.commit`, so that the
destination is at every instant either the complete old output or the complete new one.
Every output folder carries a marker file (`OUTPUT_MARKER`); ``--force`` replaces only
folders that have it (or are empty), never a folder this program did not write.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import json
import math
import os
import shutil
import sys
import tempfile
import uuid
from pathlib import Path

import numpy as np

from ._images import write_png
from ._pfm import write_pfm

#: Name of the marker file written into every output folder.
OUTPUT_MARKER = ".mvedge-output"
_MARKER_TEXT = (
    "This folder was written by mvedge_jax. `mvedge depth --force` may replace it as a whole.\n"
)


class OutputError(ValueError):
    """An output location that cannot or must not be written (the message says why)."""


def _resolve(path: str | os.PathLike) -> Path:
    """Absolute path with every symlink of its existing part resolved."""
    return Path(os.path.realpath(os.path.abspath(os.fspath(path))))


def _nearest_existing(path: Path) -> Path:
    p = path
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def is_output_folder(path: str | os.PathLike) -> bool:
    """True if ``path`` is a folder written by this program (it holds `OUTPUT_MARKER`)."""
    return os.path.isfile(os.path.join(os.fspath(path), OUTPUT_MARKER))


def _probe_writable(folder: Path) -> None:
    """Create and remove a folder in ``folder`` (a real test: ``os.access`` lies for root and
    on read-only mounts)."""
    try:
        probe = tempfile.mkdtemp(prefix=".mvedge-probe-", dir=folder)
    except OSError as e:
        raise OutputError(
            f"cannot write into {folder}: {e.strerror or e}; choose another output folder"
        ) from None
    os.rmdir(probe)


def check_output_dir(
    out: str | os.PathLike,
    source: str | os.PathLike | None,
    *,
    force: bool,
    probe: bool = True,
) -> Path:
    """Validate an output folder before any work is done.

    Paths are compared after resolving symlinks, so a link to the input is the input.

    Args:
        out: the output folder (need not exist; missing parents are created later).
        source: the input folder, or None (synthetic input).
        force: allow replacing an existing output folder written by this program.
        probe: also check that the folder that will hold the output is writable (by
            creating and removing a hidden folder in it).

    Returns:
        The resolved output path.

    Raises:
        OutputError: (a `ValueError`) if ``out`` is the input folder, is inside it or
            contains it (with or without ``force``); ``out`` or one of its parents is a file;
            ``out`` exists and ``force`` is False; ``out`` exists, is not empty and was not
            written by this program (no `OUTPUT_MARKER`); or the location is not writable.
    """
    out_p = _resolve(out)
    if out_p == out_p.parent:
        raise OutputError(f"refusing to write the output to the root folder {out_p}")
    if source is not None:
        src = _resolve(source)
        if out_p == src:
            raise OutputError(f"output folder {out_p} is the input folder; choose another")
        if src in out_p.parents:
            raise OutputError(
                f"output folder {out_p} is inside the input folder {src}; choose another"
            )
        if out_p in src.parents:
            raise OutputError(
                f"output folder {out_p} contains the input folder {src}; replacing it would "
                "delete the input; choose another"
            )
    if os.path.lexists(out_p):
        if not out_p.is_dir():
            raise OutputError(
                f"output path {out_p} exists and is not a folder; refusing to replace it"
            )
        if not force:
            raise OutputError(f"output folder {out_p} exists; pass --force to replace it")
        if not is_output_folder(out_p) and any(out_p.iterdir()):
            raise OutputError(
                f"output folder {out_p} exists and was not written by mvedge (it has no "
                f"{OUTPUT_MARKER} file); --force only replaces mvedge output folders. "
                "Choose another output folder or remove it yourself"
            )
        holder = out_p.parent
    else:
        holder = _nearest_existing(out_p.parent)
        if not holder.is_dir():
            raise OutputError(
                f"cannot create output folder {out_p}: {holder} is a file, not a folder"
            )
    if probe:
        _probe_writable(holder)
    return out_p


# ---- locking and the atomic swap -----------------------------------------------------------


def _acquire_lock(path: Path, out: Path) -> int:
    """Exclusive non-blocking ``flock`` on ``path`` (created); the file descriptor.

    A holder removes the lock file before releasing it, so after locking the path must
    still name the locked file (else another run has removed it meanwhile: retry).
    """
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputError(
                f"another mvedge run is writing {out} (its lock {path} is held); wait for it "
                "to finish or choose another output folder"
            ) from None
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            return fd
        os.close(fd)


def _release_lock(fd: int | None, path: Path) -> None:
    if fd is None:
        return
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    os.close(fd)


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two paths (Linux ``renameat2(RENAME_EXCHANGE)``); False if the
    system or file system cannot."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    fn.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint)
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, f"cannot swap {a} and {b}: {os.strerror(err)}")


def _make_parents(folder: Path) -> list[Path]:
    """``mkdir -p folder``; the folders created, outermost first."""
    missing = []
    p = folder
    while not os.path.lexists(p):
        missing.append(p)
        p = p.parent
    created = []
    for d in reversed(missing):
        try:
            os.mkdir(d)
        except FileExistsError:
            continue
        created.append(d)
    return created


def _json_safe(obj, path: str, bad: list[str]):
    """``obj`` with NumPy scalars as Python numbers and non-finite floats as None (their
    key paths appended to ``bad``)."""
    if isinstance(obj, dict):
        return {k: _json_safe(v, f"{path}.{k}" if path else str(k), bad) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v, f"{path}[{i}]", bad) for i, v in enumerate(obj)]
    if isinstance(obj, np.ndarray):
        return _json_safe(obj.tolist(), path, bad)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        v = float(obj)
        if not math.isfinite(v):
            bad.append(path or "<value>")
            return None
        return v
    return obj


class OutputWriter:
    """Stage outputs in a hidden sibling folder and swap it into place on `commit`.

    On construction the output location is checked (`check_output_dir`), missing parent
    folders are created, an exclusive lock (``.<name>.lock`` beside the output) is taken for
    the writer's lifetime (a second concurrent run on the same output fails at once), leftover
    staging folders of killed runs are removed, and the staging folder ``.<name>.stage-*``
    is created with normal permissions (``0o777 & ~umask``) and the `OUTPUT_MARKER` file.

    `commit` swaps the staged folder with the old output atomically (Linux
    ``renameat2(RENAME_EXCHANGE)``; elsewhere rename aside, rename in) and then deletes the
    old one; `abort` (also called when a ``with`` block raises) removes the staging folder,
    the lock and the parent folders this writer created. Nothing appears at the destination
    unless every file was written.

    Args:
        out: the output folder.
        force: replace an existing output folder written by this program.
        source: the input folder (the output must not be, contain or be inside it).

    Raises:
        OutputError: see `check_output_dir`; or another run holds the lock.
        OSError: if the file system refuses to create the folders.
    """

    def __init__(
        self,
        out: str | os.PathLike,
        *,
        force: bool = False,
        source: str | os.PathLike | None = None,
    ):
        self.force = force
        self.out = check_output_dir(out, source, force=force)
        name = self.out.name
        parent = self.out.parent
        self._lock_path = parent / f".{name}.lock"
        self._lock_fd: int | None = None
        self.tmp: Path | None = None
        self.committed = False
        self._created = _make_parents(parent)
        try:
            self._lock_fd = _acquire_lock(self._lock_path, self.out)
            check_output_dir(self.out, source, force=force, probe=False)  # under the lock
            self._remove_stale(parent, name)
            self.tmp = Path(tempfile.mkdtemp(prefix=f".{name}.stage-", dir=parent))
            os.chmod(self.tmp, 0o777 & ~_umask())
            (self.tmp / OUTPUT_MARKER).write_text(_MARKER_TEXT)
        except BaseException:
            self.abort()
            raise

    @staticmethod
    def _remove_stale(parent: Path, name: str) -> None:
        """Remove staging / set-aside folders of killed runs (none is live: we hold the lock)."""
        for prefix in (f".{name}.stage-", f".{name}.old-"):
            for p in parent.glob(prefix + "*"):
                if p.is_dir() and not p.is_symlink() and is_output_folder(p):
                    shutil.rmtree(p, ignore_errors=True)

    def check_source(self, source: str | os.PathLike | None) -> None:
        """Check the output against an input folder known only after loading.

        Raises:
            OutputError: if the output is, contains or is inside ``source``.
        """
        if source is not None:
            check_output_dir(self.out, source, force=True, probe=False)

    def path(self, name: str) -> Path:
        """The staged path of output file ``name`` (a relative path; parents created)."""
        if self.tmp is None:
            raise OutputError(f"the writer of {self.out} is closed")
        p = (self.tmp / name).resolve()
        if self.tmp.resolve() not in p.parents:
            raise ValueError(f"output file name {name!r} leaves the output folder")
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def png(self, name: str, rgb: np.ndarray) -> None:
        write_png(self.path(name), rgb)

    def pfm(self, name: str, image: np.ndarray) -> None:
        write_pfm(self.path(name), image)

    def json(self, name: str, obj) -> None:
        """Write strict JSON (no ``NaN``/``Infinity``): non-finite numbers are written as
        ``null`` and, when ``obj`` is a dict, listed under ``"non_finite_values"``."""
        bad: list[str] = []
        clean = _json_safe(obj, "", bad)
        if bad and isinstance(clean, dict):
            clean["non_finite_values"] = bad
        text = json.dumps(clean, indent=2, sort_keys=True, allow_nan=False)
        self.path(name).write_text(text + "\n")

    def npz(self, name: str, **arrays) -> None:
        np.savez_compressed(self.path(name), **arrays)

    def commit(self) -> Path:
        """Swap the staged folder into place, delete the old output, release the lock.

        Returns:
            The output folder.
        """
        if self.tmp is None:
            raise OutputError(f"the writer of {self.out} is closed")
        try:
            if os.path.lexists(self.out):
                check_output_dir(self.out, None, force=self.force, probe=False)
                if _exchange(self.tmp, self.out):
                    shutil.rmtree(self.tmp)  # now the old output
                else:
                    aside = self.out.parent / f".{self.out.name}.old-{uuid.uuid4().hex[:8]}"
                    os.rename(self.out, aside)
                    os.rename(self.tmp, self.out)
                    shutil.rmtree(aside, ignore_errors=True)
            else:
                os.rename(self.tmp, self.out)
        except BaseException:
            self.abort()
            raise
        self.tmp = None
        self.committed = True
        self._created = []
        _release_lock(self._lock_fd, self._lock_path)
        self._lock_fd = None
        return self.out

    def abort(self) -> None:
        """Remove the staging folder, the lock and the parent folders this writer created
        (idempotent; does nothing after `commit`)."""
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None
        _release_lock(self._lock_fd, self._lock_path)
        self._lock_fd = None
        for d in reversed(self._created):
            try:
                os.rmdir(d)
            except OSError:
                break
        self._created = []

    def __enter__(self) -> OutputWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None or not self.committed:
            self.abort()

    def __del__(self):  # a writer dropped without commit/abort must not keep the lock
        if getattr(self, "_lock_fd", None) is not None and not getattr(self, "committed", True):
            try:
                self.abort()
            except Exception:
                pass
