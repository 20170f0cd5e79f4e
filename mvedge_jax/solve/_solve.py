"""`solve_poisson`: differentiable weighted screened-Poisson solve (SPEC §5, thesis eqs 4.8–4.11).

Forward: PCG on ``(Λ_d + L_w) D = Λ_d S`` with a Jacobi or multigrid preconditioner.
Backward (``jax.custom_vjp``): one adjoint solve ``A μ = x̄`` with the same operator and
preconditioner (``A`` is symmetric), to the same *relative* tolerance, then the VJP of
``r(θ) = Λ_d S − A(θ) x`` at the solution contracted with ``μ``:
``θ̄ = μᵀ ∂r/∂θ``. No iteration is ever differentiated.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from .._fields import check_fields, static
from ._multigrid import build_hierarchy, vcycle
from ._operator import diagonal, matvec
from ._pcg import pcg

PRECONDITIONERS = ("multigrid", "jacobi", "none")


class SolverConfig(eqx.Module):
    """Configuration of `solve_poisson`.

    Attributes:
        preconditioner: ``"multigrid"`` (2×2-aggregation V(2,2) cycle), ``"jacobi"`` or
            ``"none"``.
        max_iters: iteration cap of each PCG solve (forward and adjoint).
        rtol: relative residual target ``‖W (b − A x)‖ ≤ rtol ‖W b‖`` with
            ``W = diag(A)^(-1)``, the relative residual of the Jacobi-preconditioned
            system. (Unscaled, rows with data weight 1e6 dominate ``‖b‖``: at 1e-5 a
            "converged" inpainting solve was off by 1.9 on a 0–2.8 ramp; with ``W`` the
            error is 6e-4. For a constant diagonal the two criteria coincide.)

    Raises:
        TypeError: on a value of the wrong type (e.g. a string for ``max_iters``).
        ValueError: on an unknown preconditioner, ``max_iters < 1`` or ``rtol <= 0``.
    """

    preconditioner: str = static("multigrid", choices=PRECONDITIONERS)
    max_iters: int = static(500, lower=1)
    rtol: float = static(1e-5, lower=0.0, lower_open=True)

    def __check_init__(self):
        check_fields(self)


_DEFAULT_CONFIG = SolverConfig()


#: `SolveResult.status`: the relative residual met ``rtol`` (like ``lineax.RESULTS.successful``).
CONVERGED = 0
#: `SolveResult.status`: stopped at ``max_iters`` (or stalled at the precision floor) above
#: ``rtol`` (like ``lineax.RESULTS.max_steps_reached``).
MAX_STEPS = 1
#: `SolveResult.status`: NaN/Inf in the solution or residual (like
#: ``lineax.RESULTS.nonfinite_input``): non-finite or negative weights or targets.
NONFINITE = 2
#: Names of the status codes, indexed by code.
STATUS_NAMES = ("converged", "max-steps", "non-finite")


class SolveResult(eqx.Module):
    """Result of `solve_poisson`.

    Attributes:
        x: ``(..., H, W)`` solution.
        iterations: ``()`` int32 PCG iterations of the forward solve (per problem when
            batched).
        residual: ``()`` relative residual ``‖W (b − A x)‖ / ‖W b‖`` reached,
            ``W = diag(A)^(-1)`` (0 when ``b == 0``), recomputed from ``x``.
        status: ``()`` int32 per problem: `CONVERGED` (0), `MAX_STEPS` (1) or `NONFINITE`
            (2); `STATUS_NAMES` names them (`describe_status`).
    """

    x: Float[Array, "... H W"]
    iterations: Int[Array, ...]
    residual: Float[Array, ...]
    status: Int[Array, ...]


def solve_status(x: Array, residual: Array, rtol: float) -> Int[Array, ...]:
    """`CONVERGED` / `MAX_STEPS` / `NONFINITE` per problem from a solution ``(..., H, W)``
    and its relative residual ``(...)`` (the residual may exceed ``rtol`` by float32
    rounding of its recomputation: 1% slack)."""
    x, residual = jax.lax.stop_gradient((x, residual))
    finite = jnp.isfinite(residual) & jnp.all(jnp.isfinite(x), axis=(-2, -1))
    ok = residual <= 1.01 * rtol
    return jnp.where(finite, jnp.where(ok, CONVERGED, MAX_STEPS), NONFINITE).astype(jnp.int32)


def describe_status(status) -> str:
    """A summary of concrete status codes, e.g. ``"converged"`` or ``"2 of 8 max-steps"``.

    Raises:
        ValueError: on a code that is not a status.
    """
    codes = np.asarray(status).ravel()
    if codes.size and (codes.min() < 0 or codes.max() >= len(STATUS_NAMES)):
        raise ValueError(f"unknown solver status codes {sorted(set(codes.tolist()))}")
    parts = [
        f"{int((codes == k).sum())} of {codes.size} {name}" if codes.size > 1 else name
        for k, name in enumerate(STATUS_NAMES)
        if k != CONVERGED and (codes == k).any()
    ]
    return "; ".join(parts) if parts else "converged"


#: Weights down to ``-_NEGATIVE_SLACK * max(1, max |w|)`` count as zero (rounding).
_NEGATIVE_SLACK = 1e-5


def _check_values(**arrays) -> None:
    """Raise on NaN/Inf anywhere or negative weights, for concrete (non-traced) arrays."""
    for name, a in arrays.items():
        if a is None or isinstance(a, jax.core.Tracer):
            continue
        v = np.asarray(a)
        bad = ~np.isfinite(v)
        if bad.any():
            raise ValueError(
                f"{name} has {int(bad.sum())} NaN/Inf values (of {v.size}); the solve needs "
                "finite weights and targets"
            )
        if name in ("data_weight", "weight_x", "weight_y") and v.size:
            # rounding slack (finite-difference probes step weights of 0 slightly below it)
            floor = -_NEGATIVE_SLACK * max(1.0, float(np.abs(v).max()))
            neg = v < floor
            if neg.any():
                raise ValueError(
                    f"{name} has {int(neg.sum())} negative values (min {float(v.min()):.4g}); "
                    "weights must be >= 0"
                )


def _check_shapes(data_weight, target, weight_x, weight_y, x0):
    if data_weight.ndim < 2:
        raise ValueError(f"data_weight must have shape (..., H, W); got {data_weight.shape}")
    *batch, H, W = data_weight.shape
    batch = tuple(batch)
    expect = {
        "target": batch + (H, W),
        "weight_x": batch + (H, W - 1),
        "weight_y": batch + (H - 1, W),
    }
    got = {"target": target.shape, "weight_x": weight_x.shape, "weight_y": weight_y.shape}
    if x0 is not None:
        expect["x0"] = batch + (H, W)
        got["x0"] = x0.shape
    for name, shape in expect.items():
        if tuple(got[name]) != shape:
            raise ValueError(
                f"{name} must have shape {shape} for data_weight of shape "
                f"{tuple(data_weight.shape)}; got {tuple(got[name])}"
            )
    return batch


def _preconditioner_data(kind: str, lam: Array, wx: Array, wy: Array):
    """Preconditioner data (a pytree, under ``stop_gradient``), reused by the adjoint solve."""
    lam, wx, wy = jax.lax.stop_gradient((lam, wx, wy))
    if kind == "none":
        return None
    if kind == "jacobi":
        d = diagonal(lam, wx, wy)
        return jnp.where(d > 0, 1.0 / jnp.where(d > 0, d, 1.0), 0.0)
    return build_hierarchy(lam, wx, wy)


def _norm_weight(lam: Array, wx: Array, wy: Array) -> Array:
    """``diag(A)^(-1)`` (1 where the diagonal is 0): residuals are measured on the
    Jacobi-preconditioned system so that rows with huge data weights (1e6 on splatted labels)
    do not dominate the stopping test and leave inpainted regions unconverged."""
    d = jax.lax.stop_gradient(diagonal(lam, wx, wy))
    return jnp.where(d > 0, 1.0 / jnp.where(d > 0, d, 1.0), 1.0)


def _apply_preconditioner(kind: str, data, r: Array) -> Array:
    if kind == "none":
        return r
    if kind == "jacobi":
        return data * r
    return vcycle(data, r)


@functools.cache
def _make_solver(kind: str, max_iters: int, rtol: float):
    """A `custom_vjp` solve for one static configuration."""

    def forward(lam, S, wx, wy, x0):
        pdata = _preconditioner_data(kind, lam, wx, wy)
        b = lam * S
        x, k, res = pcg(
            lambda v: matvec(v, lam, wx, wy),
            b,
            x0,
            lambda r: _apply_preconditioner(kind, pdata, r),
            rtol=rtol,
            max_iters=max_iters,
            norm_weight=_norm_weight(lam, wx, wy),
        )
        return (x, k, res), pdata

    @jax.custom_vjp
    def solve(lam, S, wx, wy, x0):
        return forward(lam, S, wx, wy, x0)[0]

    def solve_fwd(lam, S, wx, wy, x0):
        out, pdata = forward(lam, S, wx, wy, x0)
        return out, (lam, S, wx, wy, out[0], pdata, x0)

    def solve_bwd(saved, cotangents):
        lam, S, wx, wy, x, pdata, x0 = saved
        xbar = cotangents[0]
        mu, _, _ = pcg(
            lambda v: matvec(v, lam, wx, wy),
            xbar,
            jnp.zeros_like(xbar),
            lambda r: _apply_preconditioner(kind, pdata, r),
            rtol=rtol,
            max_iters=max_iters,
            norm_weight=_norm_weight(lam, wx, wy),
        )

        def residual(lam, S, wx, wy):
            return lam * S - matvec(x, lam, wx, wy)

        _, vjp = jax.vjp(residual, lam, S, wx, wy)
        return (*vjp(mu), jnp.zeros_like(x0))

    solve.defvjp(solve_fwd, solve_bwd)
    # jit so that eager calls hit the compilation cache (inlined when traced under a jit).
    return jax.jit(solve)


def solve_poisson(
    data_weight: Float[ArrayLike, "... H W"],
    target: Float[ArrayLike, "... H W"],
    weight_x: Float[ArrayLike, "... H W-1"],
    weight_y: Float[ArrayLike, "... H-1 W"],
    *,
    x0: Float[ArrayLike, "... H W"] | None = None,
    config: SolverConfig = _DEFAULT_CONFIG,
) -> SolveResult:
    """Minimise a weighted screened-Poisson energy on an ``H×W`` grid.

    Minimises ``Σ λ_d (D − S)² + Σ_{horizontal pairs} w_x (D[y, x+1] − D[y, x])²
    + Σ_{vertical pairs} w_y (D[y+1, x] − D[y, x])²`` with natural (Neumann) boundaries, by
    PCG on ``(Λ_d + L_w) D = Λ_d S`` to a relative residual ``config.rtol`` of the
    Jacobi-preconditioned system (see `SolverConfig`; capped at ``config.max_iters`` iterations:
    check ``residual``).

    Each connected component of the grid graph (pixels joined by edges of positive weight)
    needs some positive data weight, otherwise the system is singular there. A component
    without data weight has a zero right-hand side, and the forward solve leaves it at zero
    (the minimum-norm solution) when ``x0`` is zero there; gradients that would flow into
    such a component are undefined. No regularisation is added to the operator (a relative
    shift large enough to matter in float32 would visibly bias inpainting far from the
    data); the multigrid coarsest level alone uses a 1e-4 relative diagonal shift, which
    only affects the preconditioner, never the solution.

    Differentiable (reverse mode, `jax.custom_vjp`) w.r.t. ``data_weight``, ``target``,
    ``weight_x`` and ``weight_y``: the backward pass is one adjoint PCG solve with the same
    operator and preconditioner (preconditioner data under ``stop_gradient``) to the same
    relative tolerance, then the VJP of the matrix-vector product. No gradient flows into
    ``x0``, ``iterations`` or ``residual``. Forward-mode differentiation is not supported.

    Leading batch dimensions (identical on every argument) are mapped with `jax.vmap`;
    equivalently, `jax.vmap` the function yourself. jit-able.

    Args:
        data_weight: ``(..., H, W)`` float, ``λ_d >= 0`` (zero = no data, inpainted).
        target: ``(..., H, W)`` float, ``S``.
        weight_x: ``(..., H, W-1)`` float, ``>= 0``, weight of the edge between
            ``[y, x]`` and ``[y, x+1]``.
        weight_y: ``(..., H-1, W)`` float, ``>= 0``, weight of the edge between
            ``[y, x]`` and ``[y+1, x]``.
        x0: optional ``(..., H, W)`` warm start (default zeros).
        config: `SolverConfig` (static: preconditioner, iteration cap, tolerance).

    Returns:
        `SolveResult` with ``x`` ``(..., H, W)`` in the floating dtype of the inputs,
        ``iterations`` ``(...)`` int32, ``residual`` ``(...)`` and ``status`` ``(...)``
        int32 (`CONVERGED`, `MAX_STEPS` or `NONFINITE`; under ``jit`` non-finite or
        negative inputs show here as `NONFINITE` or `MAX_STEPS`).

    Raises:
        ValueError: if the shapes disagree (the message quotes them); for concrete
            (non-traced) inputs also on NaN/Inf in any input or negative weights, before
            solving.

    References:
        Thesis Sec. 4.2 (eqs 4.8–4.11) and Ch. 6 (eqs 6.1, 6.4); SPEC §5.
    """
    data_weight = jnp.asarray(data_weight)
    target = jnp.asarray(target)
    weight_x = jnp.asarray(weight_x)
    weight_y = jnp.asarray(weight_y)
    x0 = None if x0 is None else jnp.asarray(x0)
    batch = _check_shapes(data_weight, target, weight_x, weight_y, x0)
    _check_values(
        data_weight=data_weight, target=target, weight_x=weight_x, weight_y=weight_y, x0=x0
    )
    dtype = jnp.result_type(data_weight, target, weight_x, weight_y, jnp.float32)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.float32
    lam, S, wx, wy = (a.astype(dtype) for a in (data_weight, target, weight_x, weight_y))
    x0 = jnp.zeros_like(S) if x0 is None else jax.lax.stop_gradient(x0.astype(dtype))
    solve = _make_solver(config.preconditioner, int(config.max_iters), float(config.rtol))
    for _ in batch:
        solve = jax.vmap(solve)
    x, k, res = solve(lam, S, wx, wy, x0)
    status = solve_status(x, res, float(config.rtol))
    return SolveResult(x=x, iterations=k, residual=res, status=status)


def solve_poisson_lineax(
    data_weight: Float[ArrayLike, "H W"],
    target: Float[ArrayLike, "H W"],
    weight_x: Float[ArrayLike, "H W-1"],
    weight_y: Float[ArrayLike, "H-1 W"],
    *,
    x0: Float[ArrayLike, "H W"] | None = None,
    config: SolverConfig = _DEFAULT_CONFIG,
) -> SolveResult:
    """The same problem as `solve_poisson`, solved with `lineax.CG` (reference / cross-check).

    The operator is a `lineax.FunctionLinearOperator` tagged symmetric and positive
    semidefinite, applied to the symmetrically Jacobi-scaled system; the preconditioner
    (same Jacobi / multigrid as `solve_poisson`, under ``stop_gradient``) is passed likewise.
    Stopping rule: two-norm of the scaled residual, ``rtol = 0``, constant ``atol`` on a
    normalised right-hand side (lineax's default element-wise rule stops early when ``b``
    is zero at most pixels) — i.e. ``‖W^½ r‖ ≤ rtol ‖W^½ b‖``, ``W = diag(A)^-1``.
    Gradients come from lineax's own implicit differentiation, whose adjoint solve uses the
    same *absolute* tolerance — inaccurate for losses of very different scale; prefer
    `solve_poisson` for gradients.

    Args, Returns, Raises: as `solve_poisson`, without batch dimensions (use `jax.vmap`).
    ``iterations`` is lineax's step count; ``residual`` is recomputed.

    References:
        lineax documentation (`lineax.CG`, `lineax.linear_solve`); SPEC §5.
    """
    data_weight = jnp.asarray(data_weight)
    if data_weight.ndim != 2:
        raise ValueError(
            f"solve_poisson_lineax takes one (H, W) problem (vmap for batches); "
            f"got data_weight of shape {tuple(data_weight.shape)}"
        )
    target, weight_x, weight_y = (jnp.asarray(a) for a in (target, weight_x, weight_y))
    _check_shapes(data_weight, target, weight_x, weight_y, None if x0 is None else jnp.asarray(x0))
    dtype = jnp.result_type(data_weight, target, weight_x, weight_y, jnp.float32)
    lam, S, wx, wy = (a.astype(dtype) for a in (data_weight, target, weight_x, weight_y))
    # lineax keeps the norm function as static data, so it cannot close over the traced
    # diag(A); instead solve the symmetrically Jacobi-scaled system  Â y = W^½ b  with
    # Â = W^½ A W^½, x = W^½ y (W = diag(A)^-1), whose plain residual is W^½ r. Divided by
    # ‖W^½ b‖ so that lineax's absolute tolerance is a constant (a traced atol fails under
    # jit). NB: this stops on ‖W^½ r‖ ≤ rtol ‖W^½ b‖, close to but not exactly
    # `solve_poisson`'s ‖W r‖ criterion; ``residual`` is reported in `solve_poisson`'s
    # definition.
    w = _norm_weight(lam, wx, wy)
    sw = jnp.sqrt(w)
    struct = jax.ShapeDtypeStruct(S.shape, dtype)
    tags = (lx.symmetric_tag, lx.positive_semidefinite_tag)
    op = lx.FunctionLinearOperator(lambda v: sw * matvec(sw * v, lam, wx, wy), struct, tags=tags)
    kind = config.preconditioner
    pdata = _preconditioner_data(kind, lam, wx, wy)
    options = {}
    if kind != "none":
        # M⁻¹ for Â is W^-½ M⁻¹ W^-½ (Jacobi on Â is the identity: pass the multigrid only).
        isw = jnp.where(sw > 0, 1.0 / sw, 0.0)
        options["preconditioner"] = lx.FunctionLinearOperator(
            lambda r: isw * _apply_preconditioner(kind, pdata, isw * r), struct, tags=tags
        )
    b = lam * S
    bh = sw * b
    bnorm = jnp.sqrt(jnp.sum(bh * bh))
    bscale = jax.lax.stop_gradient(jnp.where(bnorm > 0, bnorm, 1.0))
    if x0 is not None:
        options["y0"] = (
            jax.lax.stop_gradient(jnp.asarray(x0, dtype) * jnp.where(sw > 0, 1.0 / sw, 0.0))
            / bscale
        )
    solver = lx.CG(
        rtol=0.0,
        atol=float(config.rtol),
        norm=lx.internal.two_norm,
        max_steps=int(config.max_iters),
    )
    sol = lx.linear_solve(op, bh / bscale, solver, options=options, throw=False)
    x = sw * sol.value * bscale
    wb = w * b
    wbn = jnp.sqrt(jnp.sum(wb * wb))
    rr = w * (b - matvec(x, lam, wx, wy))
    res = jnp.sqrt(jnp.sum(rr * rr)) / jnp.where(wbn > 0, wbn, 1.0)
    steps = sol.stats.get("num_steps", jnp.zeros((), jnp.int32))
    status = solve_status(x, res, float(config.rtol))
    return SolveResult(x=x, iterations=jnp.asarray(steps, jnp.int32), residual=res, status=status)
