"""Hyperparameter sweeps of the chain: one compilation, ``vmap`` over values, sharded over
devices."""

from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P
from jaxtyping import Array, ArrayLike, Float

from .._memory import CHAIN_MAPPINGS, ensure_mapping_headroom
from ._chain import ChainOutput, estimate_disparity_arrays
from ._compile import STAGE_CACHE
from ._config import PipelineConfig, get_path, replace_paths


def _centre_disparity(out: ChainOutput) -> Array:
    U, V = out.disparity.shape[:2]
    return out.disparity[U // 2, V // 2]


@functools.lru_cache(maxsize=16)
def _program(
    paths: tuple[str, ...],
    d_max: float,
    reduce: Callable[[ChainOutput], object],
    batch_size: int | None,
    mesh: Mesh | None,
) -> Callable:
    """The jitted sweep ``(rows (n, k), views, config, key) -> reduce's pytree``. The base
    configuration and the key are arguments, not constants of the program: a later call with
    other hyperparameter values, another key or another grid of the same length reuses the
    compiled program (`jax.jit` keys it on shapes and the configuration's static fields).
    With a ``mesh`` (one axis ``"sweep"``) the rows are split over its devices."""

    def one(row, views, config, key):
        c = replace_paths(config, {p: row[i] for i, p in enumerate(paths)})
        return reduce(estimate_disparity_arrays(views, c, key=key, d_max=d_max))

    def local(rows, views, config, key):
        if batch_size is None:
            return jax.vmap(one, in_axes=(0, None, None, None))(rows, views, config, key)
        return jax.lax.map(lambda r: one(r, views, config, key), rows, batch_size=batch_size)

    if mesh is None:
        return jax.jit(local)
    return jax.jit(
        jax.shard_map(
            local,
            mesh=mesh,
            in_specs=(P("sweep"), P(), P(), P()),
            out_specs=P("sweep"),
            # the chain's solver loops start from replicated constants: no varying-axis typing
            check_vma=False,
        )
    )


def sweep(
    views: Float[ArrayLike, "U V H W 3"],
    config: PipelineConfig,
    values: dict[str, Float[ArrayLike, " n"]],
    *,
    key: Array,
    d_max: float,
    reduce: Callable[[ChainOutput], object] = _centre_disparity,
    batch_size: int | None = None,
    devices: list | None = None,
) -> object:
    """Run the chain for ``n`` settings of its hyperparameters in one compiled program.

    Setting ``i`` replaces the field at each dotted path ``p`` of ``values`` with
    ``values[p][i]`` (`replace_paths`); the chain (`estimate_disparity_arrays`) is mapped
    over the settings with ``jax.vmap`` (or ``jax.lax.map`` with ``batch_size``, to bound
    memory), and ``reduce`` keeps what is needed of each output. With more than one device
    the settings are split across them (``jax.shard_map`` over a one-axis mesh ``"sweep"``;
    the views are replicated), padded to a multiple of the device count. The program is
    compiled once for all ``n`` settings; the values, the base configuration's array fields
    and the key are traced, so a later call that changes only those (e.g. the same grid at
    another ``reconstruct.centre.omega``) reuses it. It is keyed on ``reduce`` too: pass a
    function defined once, not a new lambda per call.

    Args:
        views: ``(U, V, H, W, 3)`` RGB in [0, 1].
        config: the base `PipelineConfig`.
        values: ``{path: (n,) values}``, every array of the same length ``n >= 1``; the
            paths name array fields (`hyperparameter_paths`).
        key: PRNG key of the chain.
        d_max: the filter bank's half-range, pixels per view step (static).
        reduce: maps one `ChainOutput` to the pytree kept per setting (default: the centre
            view's ``(H, W)`` disparity). Must be jittable and hashable.
        batch_size: settings evaluated at once per device (``None``: all, with ``vmap``).
        devices: devices to shard over (default ``jax.devices()``).

    Returns:
        ``reduce``'s pytree with a leading axis of length ``n`` on every leaf.

    Raises:
        ValueError: on empty ``values``, arrays of different lengths or not 1-D, a path that
            is not an array field, or a batch size < 1.

    References:
        Thesis Fig. 6.10 (hyperparameter sweeps of the Ch. 6 reconstruction).
    """
    if not values:
        raise ValueError("values is empty: name at least one hyperparameter path to sweep")
    paths = list(values)
    columns = []
    for p in paths:
        leaf = get_path(config, p)  # raises AttributeError on a bad path
        if not isinstance(leaf, jax.Array | np.ndarray):
            raise ValueError(f"{p!r} is a static field; only array fields can be swept")
        col = np.asarray(values[p], dtype=np.float64)
        if col.ndim != 1 or col.size == 0:
            raise ValueError(f"values[{p!r}] must be a non-empty 1-D array; got shape {col.shape}")
        columns.append(col)
    n = columns[0].size
    if any(c.size != n for c in columns):
        raise ValueError(f"values must all have the same length; got {[c.size for c in columns]}")
    if batch_size is not None and batch_size < 1:
        raise ValueError(f"batch_size must be >= 1; got {batch_size}")
    views = jnp.asarray(views)
    dtype = jnp.result_type(views, jnp.float32)
    grid = np.stack(columns, axis=1)  # (n, k)

    devices = list(jax.devices() if devices is None else devices)
    mesh = Mesh(np.asarray(devices), ("sweep",)) if len(devices) > 1 else None
    # `jax.clear_caches` frees the executables of the jitted programs `_program` keeps
    ensure_mapping_headroom(CHAIN_MAPPINGS, release=STAGE_CACHE.clear)
    fn = _program(tuple(paths), float(d_max), reduce, batch_size, mesh)
    if mesh is None:
        return fn(jnp.asarray(grid, dtype), views, config, key)
    ndev = len(devices)
    padded = -(-n // ndev) * ndev
    grid = np.concatenate([grid, np.repeat(grid[-1:], padded - n, axis=0)])
    rows = jax.device_put(jnp.asarray(grid, dtype), NamedSharding(mesh, P("sweep")))
    views = jax.device_put(views, NamedSharding(mesh, P()))
    return jax.tree.map(lambda a: a[:n], fn(rows, views, config, key))
