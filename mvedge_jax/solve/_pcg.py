"""Preconditioned conjugate gradients in ``lax.while_loop`` with a relative-residual stop."""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float, Int


def _dot(a: Array, b: Array) -> Array:
    return jnp.sum(a * b)


def pcg(
    matvec: Callable[[Array], Array],
    b: Float[Array, "H W"],
    x0: Float[Array, "H W"],
    precond: Callable[[Array], Array],
    *,
    rtol: float,
    max_iters: int,
    norm_weight: Array | None = None,
) -> tuple[Array, Int[Array, ""], Array]:
    """Solve ``A x = b`` for SPD ``A`` until ``‖w (b − A x)‖ ≤ rtol ‖w b‖`` or ``max_iters`` steps.

    ``w = norm_weight`` (default 1) weights the residual norm; `solve_poisson` uses
    ``diag(A)^(-1)``, the residual of the Jacobi-preconditioned system.

    Returns:
        ``(x, iterations, relative_residual)``; the residual is recomputed from ``x`` at the
        end (the true residual, not the recursively updated one). Whenever the recursive
        residual meets the tolerance it is replaced by the true one (and CG restarts if
        that is not converged), so a converged solve has really met it; when a restart does
        not halve the true residual of the previous one, the tolerance is unattainable in
        the working precision and the solve stops early (``relative_residual > rtol``
        tells). When ``b == 0`` the
        solution is ``0`` (``A`` is nonsingular) and no iteration is run.
    """
    w2 = 1.0 if norm_weight is None else norm_weight * norm_weight

    def wdot(a: Array) -> Array:
        return jnp.sum(w2 * a * a)

    bnorm = jnp.sqrt(wdot(b))
    zero_rhs = bnorm == 0
    x0 = jnp.where(zero_rhs, jnp.zeros_like(x0), x0)
    tol2 = (rtol * bnorm) ** 2
    r = b - matvec(x0)
    z = precond(r)
    rz = _dot(r, z)
    rr = wdot(r)

    def cond(state):
        _, _, _, _, _, rr, k, _, stalled = state
        return (k < max_iters) & (rr > tol2) & ~stalled

    def body(state):
        x, r, _, p, rz, _, k, last_true, stalled = state
        Ap = matvec(p)
        pAp = _dot(p, Ap)
        alpha = jnp.where(pAp > 0, rz / jnp.where(pAp > 0, pAp, 1.0), 0.0)
        x = x + alpha * p
        r = r - alpha * Ap
        # In float32 the recursive residual drifts away from the true one (measured 1e-5
        # recursive vs 9e-5 true after ~560 plain CG steps at 256²). Whenever it claims
        # convergence, replace it by the true b - A x and, if that is not converged yet,
        # restart CG from x (periodic replacement without restart was tried: it wrecked
        # convergence). The stopping test is therefore always decided on a true residual.
        # If a restart has not at least halved the true residual of the previous restart,
        # the tolerance is below what the precision can attain (float32 floor, e.g. 1.3e-4
        # for a dense adjoint right-hand side with edge weights 1..100): stop, and report.
        claimed = wdot(r) <= tol2
        r = lax.cond(claimed, lambda: b - matvec(x), lambda: r)
        rr = wdot(r)
        stalled = claimed & (rr > 0.25 * last_true)
        last_true = jnp.where(claimed, rr, last_true)
        z = precond(r)
        rz_new = _dot(r, z)
        beta = jnp.where(rz != 0, rz_new / jnp.where(rz != 0, rz, 1.0), 0.0)
        beta = jnp.where(claimed, 0.0, beta)
        p = z + beta * p
        return x, r, z, p, rz_new, rr, k + 1, last_true, stalled

    state = (x0, r, z, z, rz, rr, jnp.zeros((), jnp.int32), rr, jnp.zeros((), bool))
    x, *_, k, _, _ = lax.while_loop(cond, body, state)
    rtrue = b - matvec(x)
    res = jnp.sqrt(wdot(rtrue)) / jnp.where(zero_rhs, 1.0, bnorm)
    return x, k, res
