"""Differentiable diffusion (eq 7.2) and the full render → solve → loss chain."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.diff import (
    DiffParams,
    LossConfig,
    ModelConfig,
    RenderConfig,
    initial_params,
    initial_q,
    predict,
    sample_bilinear,
    self_supervised_loss,
    smoothness_weights,
    supervised_loss,
)
from mvedge_jax.solve import SolverConfig

_predict = eqx.filter_jit(predict)


def test_constant_labels_diffuse_to_a_constant():
    pos = jnp.array([[3.0, 4.0], [12.5, 10.2], [7.0, 14.0], [18.0, 2.0]])
    img = jnp.zeros((16, 20, 3))
    p = initial_params(pos, jnp.full(4, 0.75), img)
    d = _predict(p).disparity
    np.testing.assert_allclose(np.asarray(d), 0.75, atol=1e-4)


def test_two_regions_separated_by_an_image_edge():
    # left half / right half with different labels and a strong image edge between them:
    # Q = q_scale |∇I| cuts the smoothness, so each side keeps its own label.
    H, W = 16, 20
    img = jnp.zeros((H, W, 3)).at[:, 10:].set(1.0)
    pos = jnp.array([[3.0, 5.0], [4.0, 11.0], [15.0, 4.0], [16.0, 12.0]])
    lab = jnp.array([-1.0, -1.0, 1.0, 1.0])
    d = np.asarray(_predict(initial_params(pos, lab, img)).disparity)
    assert np.abs(d[:, :9] + 1).max() < 0.05 and np.abs(d[:, 11:] - 1).max() < 0.05
    # without the edge stopping, the transition is gradual
    flat = np.asarray(_predict(initial_params(pos, lab, jnp.zeros_like(img))).disparity)
    assert np.abs(flat[:, 8] + 1).min() > 0.2


def test_smoothness_weights_and_initial_q():
    Q = jnp.array([[0.0, np.log(2.0)], [np.log(4.0), 0.0]])
    wx, wy = smoothness_weights(Q, 2.0)
    np.testing.assert_allclose(np.asarray(wx), [[1.5], [1.25]], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(wy), [[1.25, 1.5]], rtol=1e-6)
    img = jnp.zeros((8, 8, 3)).at[:, 4:].set(0.5)
    q = initial_q(img, ModelConfig(q_scale=10.0))
    assert float(q[:, 0].max()) == 0.0 and float(q[3, 3]) == pytest.approx(
        10 * 0.5 / 2 * np.sqrt(3)
    )
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        smoothness_weights(jnp.zeros(5))


def test_sample_bilinear():
    img = jnp.arange(12.0).reshape(3, 4)
    v = sample_bilinear(img, jnp.array([[1.5, 1.0], [0.0, 0.5], [10.0, 10.0]]))
    np.testing.assert_allclose(np.asarray(v), [5.5, 2.0, 11.0])


def test_bad_config_and_params():
    with pytest.raises(ValueError, match="label_weight"):
        ModelConfig(label_weight=-1.0)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        initial_params(jnp.zeros(4), jnp.zeros(4), jnp.zeros((8, 8, 3)))
    with pytest.raises(ValueError, match="label"):
        initial_params(jnp.zeros((4, 2)), jnp.zeros(3), jnp.zeros((8, 8, 3)))


def _tiny_lightfield(H=14, W=15):
    """Two views of a fronto-parallel textured plane at disparity 0.6 plus a nearer patch."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)

    def tex(x, y):
        return np.stack(
            [
                0.5 + 0.4 * np.sin(0.9 * x + 0.3 * y),
                0.5 + 0.4 * np.cos(0.7 * y),
                0.5 + 0.3 * np.sin(0.5 * x - 0.8 * y),
            ],
            -1,
        )

    d = 0.6
    centre = tex(xs, ys)
    # view at offset (0, 1): centre(x, y) = view(x - d, y)  →  view(u, y) = tex(u + d, y)
    right = tex(xs + d, ys)
    left = tex(xs - d, ys)
    return (
        jnp.asarray(centre),
        jnp.asarray(np.stack([left, right])),
        jnp.array([[0.0, -1.0], [0.0, 1.0]]),
    )


@pytest.mark.parametrize("with_prior", [False, True])
def test_full_chain_grad(x64, with_prior):
    """check_grads through render → diffusion (adjoint solve) → supervised + eq 7.16 loss
    (also with the residual diffusion from a prior map)."""
    centre, others, offsets = _tiny_lightfield()
    H, W = centre.shape[:2]
    pos = jnp.array([[3.3, 4.2], [9.6, 3.7], [5.2, 10.4], [11.7, 9.1], [7.4, 7.2]], jnp.float64)
    lab = jnp.array([0.5, 0.7, 0.4, 0.8, 0.6], jnp.float64)
    cfg = ModelConfig(
        render=RenderConfig(tile_size=8, tile_levels=((8, 1.0),)),
        solver=SolverConfig(preconditioner="jacobi", rtol=1e-12, max_iters=2000),
    )
    p0 = initial_params(pos, lab, centre, cfg)
    p0 = eqx.tree_at(lambda p: p.R, p0, jnp.array([0.1, -0.2, 0.0, 0.3, -0.1]))
    target = jnp.asarray(np.random.default_rng(0).uniform(0.3, 0.9, (H, W)))
    lcfg = LossConfig(occlusion_tolerance=0.25)
    prior = None
    if with_prior:
        yy = jnp.arange(H, dtype=jnp.float64)[:, None] * jnp.ones((1, W))
        prior = 0.4 + 0.03 * yy

    def loss(pos, lab, R, Q):
        p = DiffParams(position=pos, label=lab, R=R, Q=Q)
        d = predict(p, cfg, prior=prior).disparity
        return supervised_loss(d, target) + self_supervised_loss(d, centre, others, offsets, lcfg)

    check_grads(
        jax.jit(loss), (p0.position, p0.label, p0.R, p0.Q), order=1, modes=("rev",), eps=1e-6
    )


def test_prior_keeps_the_slope_between_sparse_labels():
    # A steep ramp (0.1 per row) known only at a few weak points. Plain diffusion (eq 7.2)
    # flattens it between them; diffusing the labels' residuals from a prior that has the
    # right slope (but a wrong offset) keeps the slope and takes the offset from the labels.
    H, W = 32, 24
    yy = np.arange(H, dtype=np.float32)[:, None] * np.ones((1, W), np.float32)
    ramp = 0.1 * (yy - H / 2)
    pos = jnp.array([[4.0, 6.0], [18.0, 9.0], [10.0, 20.0], [5.0, 27.0], [20.0, 25.0]])
    lab = sample_bilinear(jnp.asarray(ramp), pos)
    cfg = ModelConfig(label_weight=1.0)
    p = initial_params(pos, lab, jnp.zeros((H, W, 3)), cfg)
    plain = np.asarray(_predict(p, cfg).disparity)
    assert np.abs(plain - ramp).max() > 0.5  # flattened towards the labels' mean
    prior = jnp.asarray(ramp + 0.3)
    d = np.asarray(_predict(p, cfg, prior=prior).disparity)
    assert np.abs(d - ramp).max() < 0.05
    # labels equal to the prior reproduce it exactly
    same = initial_params(pos, sample_bilinear(prior, pos), jnp.zeros((H, W, 3)), cfg)
    np.testing.assert_allclose(
        np.asarray(_predict(same, cfg, prior=prior).disparity), np.asarray(prior), atol=1e-5
    )
    with pytest.raises(ValueError, match="prior must have shape"):
        predict(p, cfg, prior=jnp.zeros((H, W + 1)))


def test_prior_with_a_depth_edge_is_reproduced_by_labels_equal_to_it():
    # Points on both sides of a step of the prior, one pixel from it: their 7x7 splats reach
    # across the step. Each point carries its departure from the prior under it (zero), so
    # the map is the prior exactly; splatting the labels and subtracting the prior per pixel
    # put the foreground's labels on the background beside the step (a halo of ~1 px·0.6).
    H, W = 24, 24
    prior = np.where(np.arange(W)[None, :] < 12, 0.2, 1.2) * np.ones((H, 1))
    prior = jnp.asarray(prior, jnp.float32)
    ys = np.arange(2.0, 22.0, 3.0)
    pos = jnp.asarray([[x, y] for y in ys for x in (3.0, 10.6, 13.4, 20.0)], jnp.float32)
    cfg = ModelConfig(label_weight=100.0)
    p = initial_params(pos, sample_bilinear(prior, pos), jnp.zeros((H, W, 3)), cfg)
    d = np.asarray(_predict(p, cfg, prior=prior).disparity)
    np.testing.assert_allclose(d, np.asarray(prior), atol=1e-5)
    # a departure of one point stays a local, smooth bump on top of the prior
    moved = eqx.tree_at(lambda q: q.label, p, p.label.at[9].add(0.3))
    bump = np.asarray(_predict(moved, cfg, prior=prior).disparity) - np.asarray(prior)
    y9, x9 = int(round(float(pos[9, 1]))), int(round(float(pos[9, 0])))
    assert bump[y9, x9] > 0.1
    assert np.abs(bump).max() <= 0.3 + 1e-5 and bump.min() > -1e-5
