"""View consistency of per-view disparity maps (thesis eqs 6.9–6.10)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ..lightfield import forward_project_views


@functools.partial(jax.jit, static_argnames=("fill_cracks", "per_pixel"))
def _consistency(disparity, view_mask, target, *, fill_cracks: bool, per_pixel: bool):
    U, V, H, W = disparity.shape
    rows, cols = jnp.meshgrid(jnp.arange(U), jnp.arange(V), indexing="ij")
    # Destination (target) offset relative to each source view.
    offs = jnp.stack([target[0] - rows, target[1] - cols], axis=-1).reshape(-1, 2)
    offs = offs.astype(disparity.dtype)
    proj, valid = forward_project_views(disparity.reshape(-1, H, W), offs, fill_cracks=fill_cracks)
    valid = valid & view_mask.reshape(-1, 1, 1)
    n = jnp.sum(valid, axis=0)
    nn = jnp.maximum(n, 1).astype(disparity.dtype)
    mu = jnp.sum(jnp.where(valid, proj, 0.0), axis=0) / nn
    var = jnp.sum(jnp.where(valid, (proj - mu) ** 2, 0.0), axis=0) / nn
    covered = n > 0
    if per_pixel:
        return var, n
    return jnp.sum(jnp.where(covered, var, 0.0)) / jnp.maximum(jnp.sum(covered), 1)


def view_consistency(
    disparity: Float[ArrayLike, "U V H W"],
    *,
    target: tuple[int, int] | None = None,
    view_mask: Bool[ArrayLike, "U V"] | None = None,
    fill_cracks: bool = True,
    per_pixel: bool = False,
) -> Float[Array, ""] | tuple[Float[Array, "H W"], Array]:
    """View-consistency error of a light field's per-view disparity maps.

    Every view's disparity map is forward-projected into the target view (z-buffer, larger
    disparity wins, `forward_project` with crack filling); at each target pixel ``s`` the
    projections ``ρ_i(s)`` that land there (the target's own map always does) give the
    population variance ``C(s) = 1/n Σ_i (ρ_i(s) - μ_s)²`` (eq 6.9); the result is the mean
    of ``C(s)`` over the target pixels (eq 6.10). Perfectly consistent maps (e.g. exact ground
    truth) give ~0 up to rounding of the projection at depth edges and on slanted surfaces.

    Args:
        disparity: ``(U, V, H, W)`` float disparity of every view (pixels per view step).
        target: ``(row, col)`` of the target view; default the centre ``(U // 2, V // 2)``.
            May be traced (no recompilation per target).
        view_mask: optional ``(U, V)`` bool of the views to include (partial grids).
        fill_cracks: passed to `forward_project`.
        per_pixel: return ``(C (H, W), n (H, W) int)`` instead of the mean.

    Returns:
        ``()`` float: mean per-pixel variance, in (pixels per view step)²; or the per-pixel map
        and the number of projections per pixel when ``per_pixel``.

    Raises:
        ValueError: if ``disparity`` is not 4-D, ``view_mask`` is not ``(U, V)``, or a concrete
            ``target`` lies outside the grid.

    References:
        Thesis Sec. 6.2.3, eqs 6.9–6.10.
    """
    disparity = jnp.asarray(disparity)
    if disparity.ndim != 4:
        raise ValueError(f"disparity must have shape (U, V, H, W); got {disparity.shape}")
    if not jnp.issubdtype(disparity.dtype, jnp.floating):
        disparity = disparity.astype(jnp.float32)
    U, V = disparity.shape[:2]
    if target is None:
        target = (U // 2, V // 2)
    if isinstance(target, (tuple, list)) and all(isinstance(t, int) for t in target):
        if len(target) != 2 or not (0 <= target[0] < U and 0 <= target[1] < V):
            raise ValueError(f"target {tuple(target)} is outside the {U}x{V} view grid")
    target = jnp.asarray(target, jnp.int32)
    if target.shape != (2,):
        raise ValueError(f"target must be (row, col); got shape {target.shape}")
    if view_mask is None:
        view_mask = jnp.ones((U, V), bool)
    view_mask = jnp.asarray(view_mask, bool)
    if view_mask.shape != (U, V):
        raise ValueError(f"view_mask must have shape {(U, V)}; got {view_mask.shape}")
    return _consistency(disparity, view_mask, target, fill_cracks=fill_cracks, per_pixel=per_pixel)
