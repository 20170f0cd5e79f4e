"""`solve_poisson`'s status and its refusal of invalid weights (NaN/Inf, negative)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.solve import (
    CONVERGED,
    MAX_STEPS,
    NONFINITE,
    SolverConfig,
    describe_status,
    solve_poisson,
    solve_poisson_lineax,
)


def _problem(H=12, W=10, seed=0):
    rng = np.random.default_rng(seed)
    lam = (rng.uniform(0.5, 2.0, (H, W)) * (rng.uniform(size=(H, W)) < 0.3)).astype(np.float32)
    lam[0, 0] = 1.0
    S = rng.normal(size=(H, W)).astype(np.float32)
    wx = rng.uniform(0.1, 2.0, (H, W - 1)).astype(np.float32)
    wy = rng.uniform(0.1, 2.0, (H - 1, W)).astype(np.float32)
    return lam, S, wx, wy


def test_status_converged_and_max_steps():
    args = _problem()
    res = solve_poisson(*args)
    assert int(res.status) == CONVERGED and describe_status(res.status) == "converged"
    capped = solve_poisson(*args, config=SolverConfig(max_iters=1, preconditioner="none"))
    assert int(capped.status) == MAX_STEPS
    assert describe_status(capped.status) == "max-steps"
    lin = solve_poisson_lineax(*args, config=SolverConfig(max_iters=1, preconditioner="none"))
    assert int(lin.status) == MAX_STEPS


@pytest.mark.parametrize(
    ("arg", "value", "match"),
    [
        (0, np.nan, "data_weight has 1 NaN/Inf"),
        (1, np.inf, "target has 1 NaN/Inf"),
        (2, np.nan, "weight_x has 1 NaN/Inf"),
        (3, -1.0, "weight_y has 1 negative"),
        (0, -0.5, "data_weight has 1 negative"),
    ],
)
def test_invalid_concrete_inputs_raise_before_solving(arg, value, match):
    args = list(_problem())
    args[arg] = args[arg].copy()
    args[arg][1, 2] = value
    with pytest.raises(ValueError, match=match):
        solve_poisson(*args)


def test_non_finite_inputs_under_jit_flag_the_status():
    lam, S, wx, wy = _problem()
    S = S.copy()
    S[3, 3] = np.nan
    res = jax.jit(solve_poisson)(lam, S, wx, wy)
    assert int(res.status) == NONFINITE
    batched = jax.jit(solve_poisson)(
        jnp.stack([lam, lam]),
        jnp.stack([S, np.nan_to_num(S)]),
        jnp.stack([wx, wx]),
        jnp.stack([wy, wy]),
    )
    assert batched.status.tolist() == [NONFINITE, CONVERGED]
    assert describe_status(batched.status) == "1 of 2 non-finite"


def test_status_carries_no_gradient_and_keeps_the_vjp():
    lam, S, wx, wy = _problem()
    g = jax.grad(lambda s: jnp.sum(solve_poisson(lam, s, wx, wy).x ** 2))(S)
    assert np.isfinite(np.asarray(g)).all() and float(jnp.abs(g).max()) > 0
