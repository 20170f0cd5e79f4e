"""Tests of `guide_differences` and `guide_edge_weights`."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.solve import guide_differences, guide_edge_weights


def test_values_single_channel():
    g = np.array([[0.0, 0.5, 0.5], [0.0, 0.0, 1.0]], np.float32)
    wx, wy = guide_edge_weights(g, scale=2.0, eps=0.5)
    assert wx.shape == (2, 2) and wy.shape == (1, 3)
    np.testing.assert_allclose(wx, [[2 / 1.0, 2 / 0.5], [2 / 0.5, 2 / 1.5]], rtol=1e-6)
    np.testing.assert_allclose(wy, [[2 / 0.5, 2 / 1.0, 2 / 1.0]], rtol=1e-6)


def test_channel_norm_is_euclidean():
    g = np.zeros((1, 2, 3), np.float32)
    g[0, 1] = [0.3, 0.4, 0.0]  # |Δ| = 0.5
    wx, wy = guide_edge_weights(g, eps=0.01)
    np.testing.assert_allclose(wx, [[1 / 0.51]], rtol=1e-6)
    assert wy.shape == (0, 2)


def test_jit_and_bounded():
    g = jax.random.uniform(jax.random.key(0), (16, 20, 3))
    wx, wy = jax.jit(lambda g: guide_edge_weights(g, scale=3.0, eps=0.1))(g)
    assert wx.shape == (16, 19) and wy.shape == (15, 20)
    assert float(wx.max()) <= 30.0 + 1e-4 and float(wy.min()) > 0


def test_gradients(x64):
    g = np.random.default_rng(0).uniform(size=(5, 6, 3))

    def loss(g, scale, eps):
        wx, wy = guide_edge_weights(g, scale=scale, eps=eps)
        return jnp.sum(wx**2) + jnp.sum(jnp.sin(wy))

    check_grads(jax.jit(loss), (g, 1.5, 0.2), order=1, modes=("rev",), eps=1e-6)
    g[2, 3] = g[2, 2]  # a zero difference (a kink of the norm): the gradient stays finite
    assert bool(jnp.isfinite(jax.grad(loss)(g, 1.5, 0.2)).all())


def test_bad_input():
    with pytest.raises(ValueError, match=r"\(H, W\) or \(H, W, C\); got \(5,\)"):
        guide_edge_weights(np.zeros(5))
    with pytest.raises(ValueError, match="eps must be > 0"):
        guide_edge_weights(np.zeros((4, 4)), eps=0.0)


def test_guide_differences_values_and_dtype():
    g = np.zeros((2, 2, 3), np.uint8)
    g[0, 1] = [3, 4, 0]  # |Δ| = 5 to both neighbours
    dx, dy = guide_differences(g)
    assert dx.shape == (2, 1) and dy.shape == (1, 2) and dx.dtype == jnp.float32
    np.testing.assert_allclose(dx, [[5.0], [0.0]])
    np.testing.assert_allclose(dy, [[0.0, 5.0]])
    wx, wy = guide_edge_weights(g, scale=2.0, eps=1.0)
    np.testing.assert_allclose(wx, 2.0 / (dx + 1.0))
    np.testing.assert_allclose(wy, 2.0 / (dy + 1.0))


def test_guide_differences_bad_input():
    with pytest.raises(ValueError, match=r"\(H, W\) or \(H, W, C\); got \(2, 2, 2, 3\)"):
        guide_differences(np.zeros((2, 2, 2, 3)))
    with pytest.raises(ValueError, match=r"guide has no channel: shape \(4, 5, 0\)"):
        guide_differences(np.zeros((4, 5, 0)))
