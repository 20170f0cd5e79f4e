"""Tests of `solve_poisson`: dense agreement, gradients, batching, caps, preconditioners."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.solve import SolverConfig, SolveResult, solve_poisson, solve_poisson_lineax
from mvedge_jax.solve._operator import dense_matrix, stencil_matrix

PRECONDITIONERS = ("none", "jacobi", "multigrid")


def _problem(rng, H, W, dtype=np.float64, density=0.3):
    lam = rng.uniform(0.5, 2.0, (H, W)) * (rng.uniform(size=(H, W)) < density)
    lam[0, 0] = 1.0
    S = rng.normal(size=(H, W))
    wx = rng.uniform(0.1, 2.0, (H, W - 1))
    wy = rng.uniform(0.1, 2.0, (H - 1, W))
    return tuple(np.asarray(a, dtype) for a in (lam, S, wx, wy))


def _dense_solve(lam, S, wx, wy):
    H, W = lam.shape
    A = dense_matrix(lam, wx, wy)
    return jnp.linalg.solve(A, (lam * S).reshape(-1)).reshape(H, W)


@pytest.mark.parametrize(
    ("shape", "preconditioner"),
    [((9, 13), p) for p in PRECONDITIONERS]
    + [((7, 5), "multigrid"), ((1, 17), "multigrid"), ((16, 1), "jacobi"), ((17, 33), "multigrid")],
)
def test_matches_dense_solve(x64, shape, preconditioner):
    rng = np.random.default_rng(0)
    lam, S, wx, wy = _problem(rng, *shape)
    ref = _dense_solve(lam, S, wx, wy)
    cfg = SolverConfig(preconditioner=preconditioner, rtol=1e-10)
    out = solve_poisson(lam, S, wx, wy, config=cfg)
    assert isinstance(out, SolveResult)
    assert out.x.shape == shape and out.x.dtype == jnp.float64
    assert float(out.residual) <= 1e-10
    np.testing.assert_allclose(out.x, ref, rtol=0, atol=1e-8 * float(jnp.abs(ref).max()))


def test_stencil_matrix_equals_dense_matrix(x64):
    rng = np.random.default_rng(1)
    lam, _, wx, wy = _problem(rng, 5, 6)
    np.testing.assert_allclose(stencil_matrix(lam, wx, wy), dense_matrix(lam, wx, wy), atol=1e-14)
    A = np.asarray(dense_matrix(lam, wx, wy))
    np.testing.assert_allclose(A, A.T)
    assert np.linalg.eigvalsh(A).min() > 0


def test_energy_is_minimised(x64):
    # The solution is a stationary point of the stated energy (checks factor/sign conventions).
    rng = np.random.default_rng(2)
    lam, S, wx, wy = _problem(rng, 6, 8)

    def energy(D):
        return (
            jnp.sum(lam * (D - S) ** 2)
            + jnp.sum(wx * (D[:, 1:] - D[:, :-1]) ** 2)
            + jnp.sum(wy * (D[1:, :] - D[:-1, :]) ** 2)
        )

    x = solve_poisson(lam, S, wx, wy, config=SolverConfig(rtol=1e-12)).x
    assert float(jnp.abs(jax.grad(energy)(x)).max()) < 1e-9
    assert float(energy(x)) < float(energy(x + 1e-3 * rng.normal(size=x.shape)))


@pytest.mark.parametrize("preconditioner", ["none", "multigrid"])
def test_check_grads(x64, preconditioner):
    rng = np.random.default_rng(3)
    lam, S, wx, wy = _problem(rng, 6, 7)
    probe = rng.normal(size=(6, 7))
    cfg = SolverConfig(preconditioner=preconditioner, rtol=1e-12, max_iters=1000)

    def loss(lam, S, wx, wy):
        return jnp.sum(probe * solve_poisson(lam, S, wx, wy, config=cfg).x)

    check_grads(loss, (lam, S, wx, wy), order=1, modes=("rev",), eps=1e-6)


def test_grads_match_dense_autodiff(x64):
    rng = np.random.default_rng(4)
    lam, S, wx, wy = _problem(rng, 5, 9)
    probe = rng.normal(size=(5, 9))
    cfg = SolverConfig(rtol=1e-12)
    ours = jax.grad(
        lambda *a: jnp.sum(probe * solve_poisson(*a, config=cfg).x ** 2), argnums=(0, 1, 2, 3)
    )(lam, S, wx, wy)
    ref = jax.grad(lambda *a: jnp.sum(probe * _dense_solve(*a) ** 2), argnums=(0, 1, 2, 3))(
        lam, S, wx, wy
    )
    for g, r in zip(ours, ref, strict=True):
        np.testing.assert_allclose(g, r, rtol=1e-7, atol=1e-9 * float(jnp.abs(r).max()))


def test_tiny_loss_scale_gradients_float32():
    # A relative tolerance in the adjoint solve: scaling the loss by 1e-8 scales the gradient.
    rng = np.random.default_rng(5)
    lam, S, wx, wy = _problem(rng, 24, 20, dtype=np.float32)
    probe = rng.normal(size=(24, 20)).astype(np.float32)

    def grads(scale):
        f = lambda *a: scale * jnp.sum(probe * solve_poisson(*a).x)
        return jax.grad(f, argnums=(0, 1, 2, 3))(lam, S, wx, wy)

    for g1, g2 in zip(grads(1.0), grads(1e-8), strict=True):
        np.testing.assert_allclose(
            np.asarray(g2) * 1e8, g1, rtol=1e-3, atol=1e-4 * np.abs(g1).max()
        )


def test_no_gradient_through_x0(x64):
    rng = np.random.default_rng(6)
    lam, S, wx, wy = _problem(rng, 5, 5)
    g = jax.grad(lambda x0: jnp.sum(solve_poisson(lam, S, wx, wy, x0=x0).x))(jnp.ones((5, 5)))
    assert float(jnp.abs(g).max()) == 0.0


def test_vmap_batch_of_epis_and_leading_dims():
    rng = np.random.default_rng(7)
    probs = [_problem(rng, 9, 64, dtype=np.float32, density=0.1) for _ in range(16)]
    lam, S, wx, wy = (np.stack(a) for a in zip(*probs, strict=True))
    batched = jax.jit(jax.vmap(lambda *a: solve_poisson(*a)))(lam, S, wx, wy)
    assert batched.x.shape == (16, 9, 64)
    assert batched.iterations.shape == (16,) and batched.residual.shape == (16,)
    assert float(batched.residual.max()) <= 1e-5
    direct = solve_poisson(lam, S, wx, wy)  # leading batch dims are vmapped internally
    np.testing.assert_allclose(direct.x, batched.x, atol=1e-5)
    one = solve_poisson(*probs[3])
    np.testing.assert_allclose(batched.x[3], one.x, atol=1e-4)
    assert int(one.iterations) == int(batched.iterations[3])


def test_vmap_gradients():
    rng = np.random.default_rng(8)
    probs = [_problem(rng, 9, 32, dtype=np.float32) for _ in range(4)]
    lam, S, wx, wy = (np.stack(a) for a in zip(*probs, strict=True))
    f = lambda S: jnp.sum(solve_poisson(lam, S, wx, wy).x ** 2)
    g = jax.grad(f)(S)
    g1 = jax.grad(lambda s: jnp.sum(solve_poisson(lam[1], s, wx[1], wy[1]).x ** 2))(S[1])
    np.testing.assert_allclose(g[1], g1, rtol=1e-4, atol=1e-5)


def test_jit_and_residual_reported():
    rng = np.random.default_rng(9)
    lam, S, wx, wy = _problem(rng, 33, 47, dtype=np.float32)
    f = jax.jit(lambda *a: solve_poisson(*a, config=SolverConfig(rtol=1e-5)))
    out = f(lam, S, wx, wy)
    assert out.x.dtype == jnp.float32
    # The residual of the Jacobi-preconditioned system, recomputed independently in float64.
    A = np.asarray(dense_matrix(*(jnp.asarray(a, jnp.float32) for a in (lam, wx, wy))), np.float64)
    b = (lam * S).reshape(-1).astype(np.float64)
    dinv = 1.0 / np.diag(A)
    r = dinv * (b - A @ np.asarray(out.x, np.float64).reshape(-1))
    true = np.linalg.norm(r) / np.linalg.norm(dinv * b)
    assert float(out.residual) <= 1e-5
    assert true <= 1.5e-5
    np.testing.assert_allclose(float(out.residual), true, rtol=0.05, atol=1e-7)


@pytest.mark.parametrize("preconditioner", PRECONDITIONERS)
def test_iteration_cap_honoured(preconditioner):
    rng = np.random.default_rng(10)
    lam, S, wx, wy = _problem(rng, 40, 40, dtype=np.float32, density=0.02)
    cfg = SolverConfig(preconditioner=preconditioner, max_iters=3, rtol=1e-8)
    out = solve_poisson(lam, S, wx, wy, config=cfg)
    assert int(out.iterations) == 3
    assert float(out.residual) > 1e-8  # not converged, and it says so


def test_warm_start(x64):
    rng = np.random.default_rng(11)
    lam, S, wx, wy = _problem(rng, 20, 30)
    cfg = SolverConfig(preconditioner="jacobi", rtol=1e-8)
    cold = solve_poisson(lam, S, wx, wy, config=cfg)
    warm = solve_poisson(lam, S, wx, wy, x0=cold.x, config=cfg)
    assert int(warm.iterations) <= 1
    np.testing.assert_allclose(warm.x, cold.x, atol=1e-7)


def test_zero_rhs_gives_zero():
    z = jnp.zeros((8, 9))
    out = solve_poisson(z + 1.0, z, jnp.ones((8, 8)), jnp.ones((7, 9)), x0=z + 5.0)
    assert int(out.iterations) == 0 and float(out.residual) == 0.0
    assert float(jnp.abs(out.x).max()) == 0.0


def test_inpainting_large_zero_data_region():
    # Data only in a 4-px border of a 96² grid: the interior is inpainted (harmonic).
    H = W = 96
    lam = np.zeros((H, W), np.float32)
    lam[:4], lam[-4:], lam[:, :4], lam[:, -4:] = 1e6, 1e6, 1e6, 1e6
    yy, xx = np.mgrid[:H, :W].astype(np.float32)
    S = 0.02 * xx + 0.01 * yy  # a plane is harmonic: the inpainted interior reproduces it
    out = solve_poisson(lam, S, np.ones((H, W - 1), np.float32), np.ones((H - 1, W), np.float32))
    assert float(out.residual) <= 1e-5
    np.testing.assert_allclose(out.x, S, atol=2e-3)  # needs the diag(A)^-1-weighted residual


def test_isolated_component_without_data_stays_finite():
    # Columns 0..9 have data; columns 10.. are cut off (zero edge weights) and have none.
    H, W = 12, 20
    lam = np.zeros((H, W), np.float32)
    lam[:, :10] = 1.0
    S = np.ones((H, W), np.float32)
    wx = np.ones((H, W - 1), np.float32)
    wx[:, 9] = 0.0
    wy = np.ones((H - 1, W), np.float32)
    for p in PRECONDITIONERS:
        out = solve_poisson(lam, S, wx, wy, config=SolverConfig(preconditioner=p))
        assert bool(jnp.isfinite(out.x).all())
        np.testing.assert_allclose(out.x[:, :10], 1.0, atol=1e-5)
        np.testing.assert_allclose(out.x[:, 10:], 0.0, atol=1e-6)


def test_multigrid_cuts_iterations():
    rng = np.random.default_rng(12)
    N = 128
    lam = (rng.uniform(size=(N, N)) < 0.02).astype(np.float32)
    S = rng.normal(size=(N, N)).astype(np.float32)
    w = rng.uniform(0.5, 5.0, (N // 8, N // 8)).repeat(8, 0).repeat(8, 1).astype(np.float32)
    wx, wy = w[:, 1:], w[1:, :]
    its = {
        p: int(solve_poisson(lam, S, wx, wy, config=SolverConfig(preconditioner=p)).iterations)
        for p in PRECONDITIONERS
    }
    assert its["multigrid"] * 5 <= its["none"], its
    assert its["multigrid"] <= 20, its


def test_lineax_agrees(x64):
    rng = np.random.default_rng(13)
    lam, S, wx, wy = _problem(rng, 19, 23)
    for p in ("none", "multigrid"):
        cfg = SolverConfig(preconditioner=p, rtol=1e-10)
        ours = solve_poisson(lam, S, wx, wy, config=cfg)
        theirs = solve_poisson_lineax(lam, S, wx, wy, config=cfg)
        assert float(theirs.residual) <= 1e-9
        np.testing.assert_allclose(theirs.x, ours.x, atol=1e-8 * float(jnp.abs(ours.x).max()))


@pytest.mark.slow
def test_lineax_agrees_float32_multigrid():
    rng = np.random.default_rng(14)
    lam, S, wx, wy = _problem(rng, 64, 48, dtype=np.float32, density=0.05)
    ours = solve_poisson(lam, S, wx, wy)
    theirs = jax.jit(lambda *a: solve_poisson_lineax(*a))(lam, S, wx, wy)
    assert float(theirs.residual) <= 2e-5
    np.testing.assert_allclose(theirs.x, ours.x, atol=1e-3 * float(jnp.abs(ours.x).max()))


def test_bad_shapes_raise():
    z = jnp.zeros((4, 5))
    with pytest.raises(ValueError, match=r"weight_x must have shape \(4, 4\).*got \(4, 5\)"):
        solve_poisson(z, z, z, jnp.zeros((3, 5)))
    with pytest.raises(ValueError, match=r"weight_y"):
        solve_poisson(z, z, jnp.zeros((4, 4)), jnp.zeros((4, 5)))
    with pytest.raises(ValueError, match=r"target"):
        solve_poisson(z, jnp.zeros((5, 4)), jnp.zeros((4, 4)), jnp.zeros((3, 5)))
    with pytest.raises(ValueError, match=r"x0"):
        solve_poisson(z, z, jnp.zeros((4, 4)), jnp.zeros((3, 5)), x0=jnp.zeros(3))
    with pytest.raises(ValueError, match=r"data_weight"):
        solve_poisson(jnp.zeros(4), z, z, z)


def test_bad_config_raises():
    with pytest.raises(ValueError, match="preconditioner"):
        SolverConfig(preconditioner="ilu")
    with pytest.raises(ValueError, match="max_iters"):
        SolverConfig(max_iters=0)
    with pytest.raises(ValueError, match="rtol"):
        SolverConfig(rtol=0.0)
    with pytest.raises(TypeError, match="SolverConfig.max_iters must be an integer"):
        SolverConfig(max_iters="5")
    with pytest.raises(ValueError, match="SolverConfig.rtol must be finite"):
        SolverConfig(rtol=float("nan"))
