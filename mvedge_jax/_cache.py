"""The persistent compilation cache that the library enables on import, and the store of
serialized stage executables beside it (`StageStore`)."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import logging
import os
import pickle
import tempfile
from importlib import metadata
from pathlib import Path

import jax

log = logging.getLogger(__name__)

#: Environment variable: the cache folder, or ``0``/``off``/``false`` to leave JAX's
#: compilation cache as the user configured it.
CACHE_ENV = "MVEDGE_JAX_CACHE"
_OFF = ("0", "off", "false", "no", "none")


def default_cache_dir() -> str:
    """``$MVEDGE_JAX_CACHE`` if set, else ``$XDG_CACHE_HOME/mvedge_jax`` (``~/.cache``)."""
    env = os.environ.get(CACHE_ENV, "").strip()
    if env and env.lower() not in _OFF:
        return os.path.expanduser(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "mvedge_jax")


def enable_compilation_cache(*, path: str | os.PathLike | None = None) -> str | None:
    """Store compiled XLA programs on disk so that a new process does not recompile.

    Called when `mvedge_jax` is imported. It does nothing when ``$MVEDGE_JAX_CACHE`` is
    ``0``, ``off`` or ``false``, or when a compilation cache folder is already configured
    (``jax_compilation_cache_dir``), unless ``path`` is given.

    Args:
        path: the cache folder (default `default_cache_dir`).

    Returns:
        The folder in use, or ``None`` when the cache was left alone.
    """
    if path is None:
        if os.environ.get(CACHE_ENV, "").strip().lower() in _OFF:
            return None
        if jax.config.jax_compilation_cache_dir:
            return str(jax.config.jax_compilation_cache_dir)
        path = default_cache_dir()
    path = os.fspath(path)
    jax.config.update("jax_compilation_cache_dir", path)
    # Cache every stage: the chain's compilations range from 0.2 s to minutes.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


# ---- exported stages on disk ---------------------------------------------------------------

#: Subfolder of the compilation cache folder that holds exported stages.
STAGES_SUBDIR = "mvedge-stages"
#: The store keeps at most this many bytes; the least recently used files go first.
STAGES_MAX_BYTES = 1 << 30
_FORMAT = 1


def _source_digest() -> str:
    """SHA-256 of every Python file of the installed `mvedge_jax` package (path and bytes),
    recomputed whenever a file's size or modification time changes (an edited and reloaded
    module gets new keys); empty when the files cannot be read (e.g. a zipped install):
    nothing is stored then."""
    root = Path(__file__).resolve().parent
    try:
        files = sorted(root.rglob("*.py"))
        stats = tuple((str(f), st.st_mtime_ns, st.st_size) for f in files for st in [f.stat()])
    except OSError:
        return ""
    return _hash_files(root, stats) if files else ""


@functools.lru_cache(maxsize=4)
def _hash_files(root: Path, stats: tuple) -> str:
    h = hashlib.sha256()
    try:
        for name, _, _ in stats:
            path = Path(name)
            h.update(path.relative_to(root).as_posix().encode())
            h.update(b"\0")
            h.update(path.read_bytes())
    except OSError:
        return ""
    return h.hexdigest()


@functools.cache
def _host_digest() -> str:
    """What a traced stage depends on beyond its arguments and the package's source: the
    versions of the libraries it calls and the devices it was lowered for."""
    versions = []
    for name in ("jax", "jaxlib", "equinox", "lineax", "optimistix", "optax", "numpy"):
        try:
            versions.append((name, metadata.version(name)))
        except metadata.PackageNotFoundError:
            versions.append((name, None))
    devices = [(d.platform, d.device_kind) for d in jax.devices()]
    return hashlib.sha256(repr((versions, devices)).encode()).hexdigest()


def _trace_config() -> tuple:
    """The JAX settings that change what a function traces to."""
    c = jax.config
    return (
        c.jax_enable_x64,
        str(c.jax_default_matmul_precision),
        c.jax_numpy_rank_promotion,
        c.jax_numpy_dtype_promotion,
        c.jax_debug_nans,
        c.jax_debug_infs,
        str(c.jax_default_prng_impl),
    )


def stages_dir() -> Path | None:
    """Where `StageStore` keeps exported stages: ``mvedge-stages`` inside JAX's compilation
    cache folder; ``None`` when that cache is off (no folder configured, or
    ``$MVEDGE_JAX_CACHE`` is ``0``/``off``/``false``)."""
    if os.environ.get(CACHE_ENV, "").strip().lower() in _OFF:
        return None
    base = jax.config.jax_compilation_cache_dir
    if not base:
        return None
    return Path(os.path.expanduser(str(base))) / STAGES_SUBDIR


def _sentinels() -> dict:
    """Singletons that a tree structure may hold and that must unpickle as themselves."""
    from equinox._module._flatten import MISSING  # marks absent fields of eqx.Module nodes

    return {"equinox.MISSING": MISSING}


class _Pickler(pickle.Pickler):
    def persistent_id(self, obj):
        for name, sentinel in _sentinels().items():
            if obj is sentinel:
                return name
        return None


class _Unpickler(pickle.Unpickler):
    def persistent_load(self, pid):
        try:
            return _sentinels()[pid]
        except KeyError:
            raise pickle.UnpicklingError(f"unknown persistent id {pid!r}") from None


class StageStore:
    """Traced stages kept on disk as portable programs (`jax.export`), so that a new process
    compiles a stage it has run before without tracing or lowering it.

    JAX's persistent compilation cache skips only XLA's compilation: to compute its key, a
    new process still traces and lowers every stage in Python (seconds for the whole chain).
    This store keeps each stage's StableHLO (``jax.export``, flat array arguments and
    results) with its output tree structure; compiling the stored program then hits the
    persistent cache. A stage is keyed by what determines it without tracing: the
    function's qualified name, the tree structure, shapes and dtypes of its array
    arguments, the ``repr`` of its static arguments, the bytes of the package's source
    files, the JAX settings that affect tracing, library versions and devices. A key whose
    static part is not a stable ``repr`` (one that shows an object's address) is not stored.
    Loading unpickles the output tree structure from the folder: it belongs to the user, as
    JAX's own cache does.

    Args:
        path: the folder; default `stages_dir` at each use (so it follows the compilation
            cache's configuration).
        max_bytes: size above which the least recently used stages are deleted.
    """

    def __init__(self, path: str | os.PathLike | None = None, *, max_bytes: int = STAGES_MAX_BYTES):
        self._path = None if path is None else Path(path)
        self.max_bytes = int(max_bytes)

    @property
    def path(self) -> Path | None:
        """The folder in use now, or ``None`` when storing is off."""
        return self._path if self._path is not None else stages_dir()

    def key(self, name: str, structure: str, static: str) -> str | None:
        """Hex key of a stage, or ``None`` when ``static`` is not a stable description or the
        package's source cannot be read.

        Args:
            name: the function's qualified name.
            structure: tree structure, shapes and dtypes of the array arguments.
            static: ``repr`` of the compile-time constant arguments.
        """
        if " at 0x" in static or " object at " in static or not _source_digest():
            return None
        text = repr(
            (_FORMAT, name, structure, static, _trace_config(), _source_digest(), _host_digest())
        )
        return hashlib.sha256(text.encode()).hexdigest()

    def load(self, key: str):
        """``(exported, out_tree)`` stored under ``key`` (a `jax.export.Exported` of the flat
        stage and the tree structure of its result), or ``None``: absent, or unreadable (the
        file is then deleted)."""
        folder = self.path
        if folder is None:
            return None
        file = folder / f"{key}.bin"
        try:
            blob = file.read_bytes()
        except OSError:
            return None
        try:
            program, out_tree = _Unpickler(io.BytesIO(blob)).load()
            exported = jax.export.deserialize(bytearray(program))
        except Exception as err:  # a truncated or foreign file is a cache miss
            log.info("dropping unreadable stage %s: %s", file, err)
            with contextlib.suppress(OSError):
                file.unlink()
            return None
        with contextlib.suppress(OSError):
            os.utime(file)
        return exported, out_tree

    def save(self, key: str, exported, out_tree) -> bool:
        """Store ``exported`` (a `jax.export.Exported`) and ``out_tree`` under ``key``,
        atomically. Returns whether it was stored (not when serialization fails or the
        folder is not writable)."""
        folder = self.path
        if folder is None:
            return False
        try:
            buffer = io.BytesIO()
            _Pickler(buffer).dump((bytes(exported.serialize()), out_tree))
            blob = buffer.getvalue()
        except Exception as err:  # e.g. an output node type that cannot be pickled
            log.info("stage not serializable: %s", err)
            return False
        tmp = None
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".bin")
            with os.fdopen(fd, "wb") as f:
                f.write(blob)
            os.replace(tmp, folder / f"{key}.bin")
        except OSError as err:
            log.info("cannot store stage in %s: %s", folder, err)
            if tmp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            return False
        self._prune(folder)
        return True

    def _prune(self, folder: Path) -> None:
        files = []
        for f in folder.glob("*.bin"):
            with contextlib.suppress(OSError):
                st = f.stat()
                files.append((st.st_mtime, st.st_size, f))
        total = sum(size for _, size, _ in files)
        for _, size, f in sorted(files, key=lambda t: t[0]):
            if total <= self.max_bytes:
                break
            with contextlib.suppress(OSError):
                f.unlink()
                total -= size
