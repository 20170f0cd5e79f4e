"""Line fitting in confidence order with perpendicular-distance suppression (thesis 4.1.2)."""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float


def fit_lines(
    u: Float[ArrayLike, " K"],
    x: Float[ArrayLike, " K"],
    d: Float[ArrayLike, " K"],
    valid: Bool[ArrayLike, " K"],
    lam: Float[ArrayLike, ""],
) -> Bool[Array, " K"]:
    """Greedy line fitting on one EPI.

    Candidates must be sorted by decreasing confidence. Candidate ``i`` (EPI row ``u_i``,
    column ``x_i``, disparity ``d_i``) starts a line ``x(u) = x_i - (u - u_i) d_i`` unless an
    earlier line suppressed it; a new line suppresses every later candidate whose perpendicular
    distance to it, ``|x_j - x_i + d_i (u_j - u_i)| / sqrt(1 + d_i^2)``, is below ``lam``.
    Runs as a ``lax.fori_loop`` over the fixed-capacity candidate list; ``vmap`` over EPIs.

    Args:
        u: ``(K,)`` EPI row of each candidate (view index).
        x: ``(K,)`` EPI column (pixels).
        d: ``(K,)`` disparity (pixels per view step).
        valid: ``(K,)`` candidate mask.
        lam: suppression distance λ in pixels (thesis 0.2 × EPI height).

    Returns:
        ``(K,)`` bool, the candidates that became lines.

    References:
        Thesis Sec. 4.1.2.
    """
    u, x, d = (jnp.asarray(a, jnp.float32) for a in (u, x, d))
    valid = jnp.asarray(valid, bool)
    K = x.shape[0]

    def body(i, carry):
        alive, accepted = carry
        take = alive[i]
        dist = jnp.abs(x - x[i] + d[i] * (u - u[i])) / jnp.sqrt(1.0 + d[i] ** 2)
        later = jnp.arange(K) > i
        alive = alive & ~(take & later & (dist < lam))
        return alive, accepted.at[i].set(take)

    _, accepted = lax.fori_loop(0, K, body, (valid, jnp.zeros((K,), bool)))
    return accepted
