"""Preconditioners for the 5-point operator: Jacobi and a 2×2-aggregation multigrid V-cycle.

Multigrid (unsmoothed aggregation): the prolongation ``P`` copies a coarse value to the 2×2
block of fine pixels it aggregates (the last block is 1 wide/high on odd sizes); restriction is
``Pᵀ`` (block sum). The Galerkin coarse operator ``Pᵀ A P`` is again a 5-point operator of the
same form: coarse data weight = block sum of ``λ_d``, coarse edge weight = sum of the fine
edges that cross the boundary between the two blocks (edges inside a block cancel). Smoother:
damped Jacobi (ω = 0.8), ``nu`` sweeps before and after the coarse correction, inside
``lax.fori_loop``. Coarsest level (≤ ``coarse_size`` unknowns): the explicit inverse (via
Cholesky) of the stencil matrix with a small relative diagonal shift (so that a component
without data weight does not make the factorisation fail; the shift only weakens the
preconditioner there).
The V-cycle with equal pre/post sweeps and ``R = Pᵀ`` is a symmetric positive definite
preconditioner, as PCG requires.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float

from ._operator import diagonal, matvec, stencil_matrix

OMEGA = 0.8
# Over-correction of the coarse-grid update (a standard remedy for the too-smooth piecewise-
# constant interpolation of unsmoothed aggregation). Measured on backgammon 512² (eq 6.1-like
# problem, rtol 1e-5): V(2,2) 20 → 13 PCG iterations with 1.5 (1.3: 14, 1.7: 13); V(1,1)
# 25 → 16. The error propagation keeps eigenvalues in (-1, 1) for factors < 2, so the
# preconditioner stays SPD.
COARSE_CORRECTION = 1.5
COARSE_SHIFT = 1e-4  # relative diagonal shift of the coarsest dense matrix


def _ceil2(n: int) -> int:
    return (n + 1) // 2


def _pair_sum(a: Array, axis: int, nc: int) -> Array:
    """Sum neighbouring pairs along ``axis`` (zero-padding an odd length) → length ``nc``.

    Strided slices: on XLA CPU they are ~40× faster than a reshape-and-sum.
    """
    n = a.shape[axis]
    if 2 * nc != n:
        pad = [(0, 0)] * a.ndim
        pad[axis] = (0, 2 * nc - n)
        a = jnp.pad(a, pad)
    if axis == 0:
        return a[0::2] + a[1::2]
    return a[:, 0::2] + a[:, 1::2]


def _block_sum(a: Array, Hc: int, Wc: int) -> Array:
    """Sum over 2×2 blocks, zero-padding odd sizes: ``(H, W) -> (Hc, Wc)``."""
    return _pair_sum(_pair_sum(a, 0, Hc), 1, Wc)


def _prolong(e: Array, H: int, W: int) -> Array:
    """Copy each coarse value to its 2×2 block, cropped to ``(H, W)``."""
    Hc, Wc = e.shape
    full = jnp.broadcast_to(e[:, None, :, None], (Hc, 2, Wc, 2)).reshape(2 * Hc, 2 * Wc)
    return full[:H, :W]


def coarsen(lam: Array, wx: Array, wy: Array) -> tuple[Array, Array, Array]:
    """Galerkin coarse operator ``Pᵀ A P`` of the 2×2 aggregation, as stencil weights."""
    H, W = lam.shape
    Hc, Wc = _ceil2(H), _ceil2(W)
    lam_c = _block_sum(lam, Hc, Wc)
    # Horizontal fine edge j joins columns j and j+1: it crosses a block boundary iff j is odd.
    wx_c = _pair_sum(wx[:, 1::2], 0, Hc)  # (Hc, Wc - 1)
    wy_c = _pair_sum(wy[1::2, :], 1, Wc)  # (Hc - 1, Wc)
    return lam_c, wx_c, wy_c


class Level(eqx.Module):
    """One level of the hierarchy: stencil weights and the inverse diagonal."""

    lam: Array
    wx: Array
    wy: Array
    dinv: Array


class Hierarchy(eqx.Module):
    """Multigrid hierarchy: levels fine → coarse, plus the coarsest Cholesky factor."""

    levels: list[Level]
    coarse_inv: Array  # (n, n) inverse of the (shifted) coarsest operator
    coarse_shape: tuple[int, int] = eqx.field(static=True)


def _safe_inverse(d: Array) -> Array:
    return jnp.where(d > 0, 1.0 / jnp.where(d > 0, d, 1.0), 0.0)


def build_hierarchy(
    lam: Float[Array, "H W"],
    wx: Float[Array, "H W-1"],
    wy: Float[Array, "H-1 W"],
    *,
    coarse_size: int = 64,
) -> Hierarchy:
    """Build the aggregation hierarchy until at most ``coarse_size`` unknowns remain."""
    levels = []
    while lam.shape[0] * lam.shape[1] > coarse_size:
        levels.append(Level(lam, wx, wy, _safe_inverse(diagonal(lam, wx, wy))))
        lam, wx, wy = coarsen(lam, wx, wy)
    A = stencil_matrix(lam, wx, wy)
    d = jnp.diagonal(A)
    # Relative shift (weakens the preconditioner slightly, keeps Cholesky defined); an
    # all-zero row (isolated unknown with no data and no edges) gets a unit diagonal.
    shift = COARSE_SHIFT * d + jnp.where(d > 0, 0.0, 1.0)
    A = A + jnp.diag(shift)
    # An explicit inverse: a small matmul per cycle is much faster than two triangular solves
    # on XLA CPU; symmetrised so that the preconditioner stays symmetric.
    chol = jnp.linalg.cholesky(A)
    inv = jax.scipy.linalg.cho_solve((chol, True), jnp.eye(A.shape[0], dtype=A.dtype))
    inv = 0.5 * (inv + inv.T)
    return Hierarchy(levels=levels, coarse_inv=inv, coarse_shape=tuple(lam.shape))


def _smooth(level: Level, x: Array, r: Array, sweeps: int) -> Array:
    def body(_, x):
        return x + OMEGA * level.dinv * (r - matvec(x, level.lam, level.wx, level.wy))

    return lax.fori_loop(0, sweeps, body, x)


def _coarse_solve(h: Hierarchy, r: Array) -> Array:
    x = jnp.matmul(h.coarse_inv, r.reshape(-1), precision=lax.Precision.HIGHEST)
    return x.reshape(h.coarse_shape)


def vcycle(h: Hierarchy, r: Float[Array, "H W"], *, nu: int = 2) -> Float[Array, "H W"]:
    """Apply one V(nu, nu) cycle to ``r`` (zero initial guess): ``z ≈ A⁻¹ r``."""

    def cycle(i: int, r: Array) -> Array:
        if i == len(h.levels):
            return _coarse_solve(h, r)
        lv = h.levels[i]
        H, W = r.shape
        x = OMEGA * lv.dinv * r  # first sweep from x = 0
        x = _smooth(lv, x, r, nu - 1)
        res = r - matvec(x, lv.lam, lv.wx, lv.wy)
        Hc, Wc = _ceil2(H), _ceil2(W)
        x = x + COARSE_CORRECTION * _prolong(cycle(i + 1, _block_sum(res, Hc, Wc)), H, W)
        return _smooth(lv, x, r, nu)

    return cycle(0, r)
