"""The persistent compilation cache that the library enables on import."""

from __future__ import annotations

import os

import jax

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
