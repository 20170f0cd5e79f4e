"""Transmittance compositing (thesis eqs 7.7–7.14): occlusion order, tiling, overflow, grads."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.diff import RenderConfig, label_kernel_1d, weight_kernel
from mvedge_jax.diff import render as _render_eager
from mvedge_jax.diff import splat as _splat_eager

render = eqx.filter_jit(_render_eager)
splat = eqx.filter_jit(_splat_eager)
_PAD = 8


def _r(pos, lab, R=None, cfg=RenderConfig(), shape=(16, 16), valid=None):  # noqa: B008
    """`render` with the point set padded to 8 invalid points: one compile for many tests."""
    pos, lab = jnp.asarray(pos, jnp.float32), jnp.asarray(lab, jnp.float32)
    n = pos.shape[0]
    R = jnp.zeros(n) if R is None else jnp.asarray(R, jnp.float32)
    v = jnp.ones(n, bool) if valid is None else jnp.asarray(valid)
    pad = _PAD - n
    return render(
        jnp.concatenate([pos, jnp.zeros((pad, 2))]),
        jnp.concatenate([lab, jnp.zeros(pad)]),
        jnp.concatenate([R, jnp.zeros(pad)]),
        shape,
        cfg,
        valid=jnp.concatenate([v, jnp.zeros(pad, bool)]),
    )


def _reference(pos, lab, R, shape, cfg: RenderConfig):
    """Brute force over all points and pixels (NumPy, float64), same model, no tiles."""
    pos, lab, R = (np.asarray(a, np.float64) for a in (pos, lab, R))
    H, W = shape
    r = cfg.radius
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    order = np.argsort(-lab if cfg.nearer == "larger" else lab, kind="stable")
    n = cfg.depth_samples
    L, rho, sz = float(cfg.depth_span), float(cfg.density), float(cfg.sigma_depth)
    v = -L + (np.arange(n) + 0.5) * 2 * L / n
    erf = np.vectorize(math.erf)
    kappa = rho * sz * math.sqrt(2 * math.pi) * math.erf(L / math.sqrt(2))
    log_acc = np.zeros((H, W))
    alpha = np.zeros((H, W))
    num = np.zeros((H, W))
    num_w = np.zeros((H, W))
    lam_z = np.zeros((H, W))
    for j in order:
        dx, dy = xs - pos[j, 0], ys - pos[j, 1]
        g = np.asarray(label_kernel_1d(dx, float(cfg.sigma_label), r)) * np.asarray(
            label_kernel_1d(dy, float(cfg.sigma_label), r)
        )
        inside = (np.abs(dx) < r + 0.5) & (np.abs(dy) < r + 0.5)
        lam = np.where(
            inside,
            np.asarray(weight_kernel(dx**2 + dy**2, float(cfg.sigma_weight), cfg.weight_order)),
            0,
        ) * np.exp(-R[j])
        # eq 7.14 midpoint quadrature, written directly
        tau = lambda vk: (
            rho * sz * math.sqrt(math.pi / 2) * (erf(vk / math.sqrt(2)) + erf(L / math.sqrt(2)))
        )  # noqa: E731
        q = (
            sum(rho * sz * (2 * L / n) * np.exp(-tau(vk) * g) * np.exp(-0.5 * vk**2) for vk in v)
            * g
        )
        tb = np.exp(log_acc)
        alpha += tb * q
        num += tb * q * lab[j]
        lam_z += tb * lam
        num_w += tb * lam * lab[j]
        log_acc -= kappa * g
    if cfg.label_mix == "opacity":
        return num / np.maximum(alpha, 1e-30), lam_z, alpha
    return num_w / np.maximum(lam_z, 1e-30), lam_z, alpha


@pytest.mark.parametrize("mix", ["weight", "opacity"])
def test_matches_brute_force_reference(key, mix):
    k1, k2 = jax.random.split(key)
    N, shape = 40, (21, 27)
    pos = jax.random.uniform(k1, (N, 2), minval=-2.0, maxval=28.0)
    lab = jax.random.uniform(k2, (N,), minval=-2.0, maxval=2.0)
    R = jnp.linspace(-0.5, 0.5, N)
    # two-level capacity: every tile 8 slots, the busiest half up to 24
    cfg = RenderConfig(tile_size=8, tile_levels=((8, 1.0), (16, 0.5), (24, 0.25)), label_mix=mix)
    out = render(pos, lab, R, shape, cfg)
    S, lam, alpha = _reference(pos, lab, R, shape, cfg)
    assert int(out.overflow) == 0
    np.testing.assert_allclose(np.asarray(out.alpha), alpha, atol=2e-5)
    np.testing.assert_allclose(np.asarray(out.weight), lam, atol=2e-5)
    m = (alpha if mix == "opacity" else lam) > 1e-3
    np.testing.assert_allclose(np.asarray(out.label)[m], S[m], atol=2e-4)


def test_tile_size_does_not_change_the_result(key):
    k1, k2 = jax.random.split(key)
    N, shape = 60, (30, 37)
    pos = jax.random.uniform(k1, (N, 2), minval=0.0, maxval=30.0)
    lab = jax.random.uniform(k2, (N,), minval=-2.0, maxval=2.0)
    outs = [
        render(pos, lab, jnp.zeros(N), shape, RenderConfig(tile_size=t, tile_levels=((N, 1.0),)))
        for t in (7, 32)
    ]
    for o in outs[1:]:
        np.testing.assert_allclose(np.asarray(o.weight), np.asarray(outs[0].weight), atol=1e-5)
        np.testing.assert_allclose(np.asarray(o.alpha), np.asarray(outs[0].alpha), atol=1e-5)
        np.testing.assert_allclose(np.asarray(o.label), np.asarray(outs[0].label), atol=1e-4)


def test_isolated_point_matches_additive_splat():
    pos = jnp.array([[7.3, 9.6]])
    out = _r(pos, [1.5], [0.2])
    ref = splat(pos, jnp.array([1.5]), jnp.array([0.2]), (16, 16))
    np.testing.assert_allclose(np.asarray(out.weight), np.asarray(ref.weight), atol=1e-6)
    m = np.asarray(out.weight) > 1e-6
    assert m.sum() >= 9
    np.testing.assert_allclose(np.asarray(out.label)[m], 1.5, atol=1e-4)
    # alpha ≈ 1 - exp(-κ g) at the point (opaque centre)
    assert 0.95 < float(out.alpha[10, 7]) <= 1.01


@pytest.mark.parametrize("nearer", ["larger", "smaller"])
def test_nearer_point_hides_farther_and_swapping_depths_swaps_winner(nearer):
    cfg = RenderConfig(nearer=nearer)
    pos = jnp.array([[8.0, 8.0], [8.4, 8.2]])  # overlapping, sub-pixel apart
    near, far = (2.0, -1.0) if nearer == "larger" else (1.0, 4.0)
    alone = max(float(_r(pos[i : i + 1], [far], cfg=cfg).weight.sum()) for i in range(2))
    for labels in ((near, far), (far, near)):
        out = _r(pos, labels, cfg=cfg)
        # the nearer label wins wherever the two overlap ...
        for yx, tol in (((8, 8), 0.02), ((8, 9), 0.07)):
            assert abs(float(out.label[yx]) - near) < tol * abs(near - far), (labels, yx)
        # ... and the farther point's label weight is almost entirely hidden
        assert float(out.weight.sum()) < 1.05 * alone
    # which point is "the winner" follows the labels: the weight map moves with it
    a = _r(pos, [near, far], cfg=cfg).weight
    b = _r(pos, [far, near], cfg=cfg).weight
    assert float(a[8, 8]) > float(b[8, 8]) and float(b[8, 9]) > float(a[8, 9])
    # without the nearer point the farther one shows normally
    c = _r(pos[1:], [far], cfg=cfg)
    assert abs(float(c.label[8, 8]) - far) < 1e-4 and float(c.weight[8, 8]) > 0.9


def test_occluder_far_away_in_xy_does_not_occlude():
    pos = jnp.array([[4.0, 8.0], [12.0, 8.0]])
    out = _r(pos, [2.0, -1.0])
    assert float(out.label[8, 12]) == pytest.approx(-1.0, abs=1e-4)
    assert float(out.weight[8, 12]) == pytest.approx(1.0, abs=1e-4)


def test_overflow_is_counted_and_farthest_points_are_dropped():
    # 12 points on one pixel, capacity 4: the 8 farthest are dropped in every tile
    pos = jnp.full((12, 2), 10.0)
    lab = jnp.arange(12.0)
    out = render(pos, lab, jnp.zeros(12), (20, 20), RenderConfig(tile_levels=((4, 1.0),)))
    assert int(out.overflow) == 8
    full = render(pos, lab, jnp.zeros(12), (20, 20), RenderConfig(tile_levels=((16, 1.0),)))
    assert int(full.overflow) == 0
    # the nearest label (11) dominates both renders at the point
    assert float(out.label[10, 10]) > 10.9 and float(full.label[10, 10]) > 10.9


def test_invalid_nonfinite_and_offimage_points_are_ignored():
    pos = jnp.array([[5.0, 5.0], [6.0, 5.0], [jnp.nan, 3.0], [-50.0, 3.0]])
    lab = jnp.array([1.0, 3.0, 5.0, 7.0])
    out = _r(pos, lab, valid=jnp.array([True, False, True, True]))
    ref = _r(pos[:1], lab[:1])
    for f in ("label", "weight", "alpha"):
        np.testing.assert_allclose(
            np.asarray(getattr(out, f)), np.asarray(getattr(ref, f)), atol=1e-6
        )
    assert np.isfinite(np.asarray(out.label)).all()


def test_exact_integral_is_the_limit_of_the_quadrature():
    pos = jnp.array([[5.0, 5.0], [6.5, 5.5], [8.0, 7.0]])
    lab = jnp.array([1.0, 0.0, -1.0])
    a = _r(pos, lab)
    b = _r(pos, lab, cfg=RenderConfig(depth_samples=0))
    assert float(jnp.abs(a.alpha - b.alpha).max()) < 5e-3
    assert float(jnp.abs(a.label - b.label).max()) < 1e-2


def test_shapes_and_bad_input():
    with pytest.raises(ValueError, match="tile_size"):
        RenderConfig(tile_size=5)
    with pytest.raises(ValueError, match="tile_levels"):
        RenderConfig(tile_levels=((48, 1.0), (32, 0.5)))
    with pytest.raises(ValueError, match="tile_levels"):
        RenderConfig(tile_levels=((48, 0.5),))
    with pytest.raises(ValueError, match="nearer"):
        RenderConfig(nearer="front")
    with pytest.raises(ValueError, match="density"):
        RenderConfig(density=0.0)
    with pytest.raises(ValueError, match=r"\(4,\)"):
        _render_eager(jnp.zeros((4, 2)), jnp.zeros(4), jnp.zeros(3), (8, 8))
    out = render(jnp.zeros((0, 2)), jnp.zeros(0), jnp.zeros(0), (9, 11))
    assert out.label.shape == (9, 11) and float(out.alpha.sum()) == 0.0


def test_vmap_over_density():
    pos = jnp.array([[5.0, 5.0], [6.0, 5.0]])
    lab = jnp.array([1.0, 0.0])

    def f(rho):
        return _render_eager(pos, lab, jnp.zeros(2), (12, 12), RenderConfig(density=rho)).weight

    w = jax.jit(jax.vmap(f))(jnp.array([0.5, 2.0, 8.0]))
    # denser occluders attenuate the farther point more
    assert float(w[0, 5, 6]) > float(w[1, 5, 6]) > float(w[2, 5, 6])


def test_render_grad(x64):
    pos = jnp.array([[4.3, 5.2], [5.6, 4.7], [9.7, 9.9], [8.2, 10.4]], jnp.float64)
    lab = jnp.array([1.0, -0.5, 2.0, 0.3], jnp.float64)
    R = jnp.array([0.1, -0.2, 0.3, 0.0], jnp.float64)
    wts = jax.random.normal(jax.random.key(1), (3, 14, 13), jnp.float64)
    cfg = RenderConfig(tile_size=8, tile_levels=((8, 1.0),))

    def f(pos, lab, R):
        out = _render_eager(pos, lab, R, (14, 13), cfg)
        return jnp.sum(wts[0] * out.label + wts[1] * out.weight + wts[2] * out.alpha)

    check_grads(jax.jit(f), (pos, lab, R), order=1, modes=("rev",), eps=1e-6)


def test_value_is_mixed_with_the_label_weights_and_keeps_the_depth_order():
    # `value` replaces the label only in the mixed map: weights, opacity and the depth order
    # stay the label's, so an affine function of the labels mixes to that function of S^Z.
    pos = jnp.array([[5.0, 5.0], [6.2, 5.4], [9.5, 8.8], [3.1, 10.0]])
    lab = jnp.array([1.0, -0.5, 2.0, 0.3])
    base = _render_eager(pos, lab, jnp.zeros(4), (14, 13))
    same = _render_eager(pos, lab, jnp.zeros(4), (14, 13), value=lab)
    for a, b in ((base.label, same.label), (base.weight, same.weight), (base.alpha, same.alpha)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    aff = _render_eager(pos, lab, jnp.zeros(4), (14, 13), value=3.0 * lab - 1.0)
    np.testing.assert_array_equal(np.asarray(aff.weight), np.asarray(base.weight))
    has = np.asarray(base.weight) > 1e-6
    np.testing.assert_allclose(
        np.asarray(aff.label)[has], 3.0 * np.asarray(base.label)[has] - 1.0, rtol=1e-5, atol=1e-5
    )
    with pytest.raises(ValueError, match="value must have"):
        _render_eager(pos, lab, jnp.zeros(4), (14, 13), value=jnp.zeros(3))


def test_render_value_grad(x64):
    pos = jnp.array([[4.3, 5.2], [5.6, 4.7], [9.7, 9.9]], jnp.float64)
    lab = jnp.array([1.0, -0.5, 2.0], jnp.float64)
    val = jnp.array([0.2, 0.1, -0.3], jnp.float64)
    wts = jax.random.normal(jax.random.key(2), (14, 13), jnp.float64)
    cfg = RenderConfig(tile_size=8, tile_levels=((8, 1.0),))

    def f(pos, val):
        out = _render_eager(pos, lab, jnp.zeros(3, jnp.float64), (14, 13), cfg, value=val)
        return jnp.sum(wts * out.label)

    check_grads(jax.jit(f), (pos, val), order=1, modes=("rev",), eps=1e-6)
