"""Splatting kernels (thesis eqs 7.4, 7.6): sub-pixel stability, support, shapes, gradients."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.diff import RenderConfig, label_kernel_1d, weight_kernel
from mvedge_jax.diff import splat as _splat_eager

splat = eqx.filter_jit(_splat_eager)


@jax.jit
def _splat_one(p):
    return splat(p[None], jnp.ones(1), jnp.zeros(1), (16, 16))


def _one(p):
    return _splat_one(jnp.asarray(p, jnp.float32))


def test_points_never_vanish_at_subpixel_positions():
    # Sweep a point across a pixel in x and diagonally: the total splatted label weight (eq 7.6)
    # stays within ±15% and some pixel always gets most of the weight (Fig. 7.3d/e).
    totals, peaks = [], []
    for t in np.linspace(0.0, 1.0, 21):
        for p in ([7.0 + t, 8.0], [7.0 + t, 8.0 + t]):
            w = _one(p).weight
            totals.append(float(w.sum()))
            peaks.append(float(w.max()))
    totals = np.array(totals)
    assert totals.min() / totals.max() > 0.8
    assert min(peaks) > 0.75
    # A plain Gaussian narrow enough to leak as little weight does vanish between pixels.
    narrow = [float(jnp.exp(-((0.5**2) * 2) / (2 * 0.25**2)))]  # pixel-corner position
    assert narrow[0] < 0.02


def test_weight_is_compact_and_scaled_by_exp_minus_r():
    w = splat(jnp.array([[8.0, 8.0]]), jnp.ones(1), jnp.array([0.7]), (16, 16)).weight
    np.testing.assert_allclose(float(w[8, 8]), np.exp(-0.7), rtol=1e-6)
    # super-Gaussian p=2, σ=0.71: 1 px away ≈ exp(-(1/1.0082)^2)
    np.testing.assert_allclose(
        float(w[8, 9]), np.exp(-0.7) * np.exp(-((1 / 1.0082) ** 2)), rtol=1e-3
    )
    assert float(w[8, 10]) < 1e-6 and float(w[10, 10]) < 1e-12


def test_label_kernel_support_and_continuity():
    g = label_kernel_1d(jnp.array([0.0, 1.0, 3.49, 3.5, 4.0]), 1.3, 3)
    assert float(g[0]) == pytest.approx(1.0)
    assert 0.7 < float(g[1]) < 0.75
    assert float(g[2]) < 1e-3 and float(g[3]) == 0.0 and float(g[4]) == 0.0
    # the whole splat is continuous when the point crosses a half pixel (support changes)
    a = _one([7.4999, 8.2])
    b = _one([7.5001, 8.2])
    assert float(jnp.abs(a.label_sum - b.label_sum).max()) < 1e-3
    assert float(jnp.abs(a.weight - b.weight).max()) < 1e-3


def test_label_map_of_isolated_points_is_exact():
    pos = jnp.array([[3.2, 4.7], [12.0, 11.5]])
    s = splat(pos, jnp.array([-1.25, 2.0]), jnp.zeros(2), (16, 16))
    lab = s.label
    assert float(lab[5, 3]) == pytest.approx(-1.25, abs=1e-6)
    assert float(lab[11, 12]) == pytest.approx(2.0, abs=1e-6)
    assert float(s.density.sum()) > 0


def test_invalid_and_out_of_image_points_are_dropped():
    pos = jnp.array([[-10.0, 5.0], [5.0, 5.0], [0.2, 0.3]])
    s = splat(pos, jnp.ones(3), jnp.zeros(3), (8, 8), valid=jnp.array([True, False, True]))
    ref = splat(pos[2:], jnp.ones(1), jnp.zeros(1), (8, 8))
    np.testing.assert_allclose(np.asarray(s.weight), np.asarray(ref.weight), atol=1e-7)


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        splat(jnp.zeros((3,)), jnp.zeros(3), jnp.zeros(3), (8, 8))
    with pytest.raises(ValueError, match="label"):
        splat(jnp.zeros((3, 2)), jnp.zeros(4), jnp.zeros(3), (8, 8))
    with pytest.raises(ValueError, match="shape"):
        splat(jnp.zeros((3, 2)), jnp.zeros(3), jnp.zeros(3), (8,))
    with pytest.raises(ValueError, match="sigma_weight"):
        RenderConfig(sigma_weight=-1.0)
    with pytest.raises(ValueError, match="weight_order"):
        RenderConfig(weight_order=0)


def test_jit_matches_eager(key):
    pos = jax.random.uniform(key, (20, 2), minval=0, maxval=15)
    lab = jnp.linspace(-1, 1, 20)
    a = _splat_eager(pos, lab, jnp.zeros(20), (16, 16))
    b = jax.jit(lambda p, z: _splat_eager(p, z, jnp.zeros(20), (16, 16)))(pos, lab)
    np.testing.assert_allclose(np.asarray(a.weight), np.asarray(b.weight), rtol=1e-5, atol=1e-7)


def test_kernels_grad(x64):
    d = jnp.array([0.3, -1.7, 2.2])
    check_grads(
        jax.jit(lambda d: label_kernel_1d(d, 1.3, 3)), (d,), order=1, modes=("rev",), eps=1e-6
    )
    check_grads(
        jax.jit(lambda r: weight_kernel(r, 0.71, 2)), (d**2,), order=1, modes=("rev",), eps=1e-6
    )


def test_splat_grad(x64):
    pos = jnp.array([[4.3, 5.2], [6.1, 4.6], [9.7, 9.9]], jnp.float64)
    lab = jnp.array([1.0, -0.5, 2.0], jnp.float64)
    R = jnp.array([0.1, -0.2, 0.3], jnp.float64)
    wts = jax.random.normal(jax.random.key(0), (3, 12, 12), jnp.float64)

    def f(pos, lab, R):
        s = splat(pos, lab, R, (12, 12))
        return jnp.sum(wts[0] * s.label_sum + wts[1] * s.density + wts[2] * s.weight)

    check_grads(f, (pos, lab, R), order=1, modes=("rev",), eps=1e-6)
