"""rgb_to_lab, srgb_to_linear, linear_to_srgb: agreement with OpenCV and the sRGB standard,
shapes, dtype, jit and gradients."""

from __future__ import annotations

import cv2
import jax
import jax.numpy as jnp
import numpy as np
from jax.test_util import check_grads

from mvedge_jax.lightfield import linear_to_srgb, rgb_to_lab, srgb_to_linear


def _samples(key, n=4096):
    rgb = np.asarray(jax.random.uniform(key, (n, 3)), np.float32)
    # include dark values (linear sRGB segment, L* linear segment), greys, primaries, extremes
    extra = np.array(
        [
            [0, 0, 0],
            [1, 1, 1],
            [0.5, 0.5, 0.5],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [0.01, 0.02, 0.03],
            [0.03, 0.03, 0.03],
            [0.04, 0.05, 0.0],
        ],
        np.float32,
    )
    return np.concatenate([rgb, extra])


def test_matches_opencv_rgb2lab(key):
    rgb = _samples(key)
    ours = np.asarray(jax.jit(rgb_to_lab)(rgb))
    ref = cv2.cvtColor(rgb[None], cv2.COLOR_RGB2LAB)[0]
    err = np.abs(ours - ref)
    print("max |Δ| L, a, b:", err.max(axis=0))
    assert err.max() < 1.0
    assert err.mean() < 0.3
    # ranges
    assert ours[:, 0].min() >= -1e-3 and ours[:, 0].max() <= 100.0 + 1e-3


def test_shapes_dtype_and_jit(key):
    img = jax.random.uniform(key, (2, 5, 7, 3))
    lab = jax.jit(rgb_to_lab)(img)
    assert lab.shape == img.shape and lab.dtype == jnp.float32
    grey = jax.jit(rgb_to_lab)(jnp.full((3,), 0.5))
    assert abs(float(grey[1])) < 1e-3 and abs(float(grey[2])) < 1e-3


def test_gradients_float64(x64, key):
    # Away from the piecewise boundaries (sRGB 0.04045, CIE t = (6/29)^3) so that the finite
    # differences are smooth; includes the dark linear segment.
    rgb = np.asarray(0.1 + 0.8 * jax.random.uniform(key, (6, 3), dtype=jnp.float64))
    dark = np.array([[0.01, 0.02, 0.03]], np.float64)
    f = jax.jit(rgb_to_lab)
    check_grads(f, (rgb,), order=1, modes=("rev",), eps=1e-6)
    check_grads(f, (dark,), order=1, modes=("rev",), eps=1e-6)
    assert f(rgb).dtype == jnp.float64
    g = jax.jit(jax.grad(lambda x: rgb_to_lab(x).sum()))(np.zeros((2, 3)))
    assert np.isfinite(np.asarray(g)).all()  # black has finite gradients


def test_srgb_transfer_curve_values_and_round_trip(key):
    # IEC 61966-2-1: the linear segment below 0.04045 (0.0031308 in linear light), and
    # mid grey 0.5 -> 0.214041.
    x = np.array([0.0, 0.02, 0.04045, 0.5, 1.0], np.float32)
    lin = np.asarray(jax.jit(srgb_to_linear)(x))
    np.testing.assert_allclose(lin, [0.0, 0.02 / 12.92, 0.0031308, 0.2140411, 1.0], atol=2e-6)
    rgb = _samples(key)
    back = np.asarray(jax.jit(lambda v: linear_to_srgb(srgb_to_linear(v)))(rgb))
    np.testing.assert_allclose(back, rgb, atol=2e-6)
    assert np.all(np.diff(np.asarray(srgb_to_linear(jnp.linspace(0, 1, 1001)))) > 0)
    # The linear-light mean of black and white is brighter than the encoded mean.
    assert float(linear_to_srgb(0.5 * (srgb_to_linear(0.0) + srgb_to_linear(1.0)))) > 0.73


def test_srgb_transfer_gradients_float64(x64, key):
    rgb = np.asarray(0.1 + 0.8 * jax.random.uniform(key, (4, 3), dtype=jnp.float64))
    dark = np.array([[0.001, 0.02, 0.03]], np.float64)
    for f in (jax.jit(srgb_to_linear), jax.jit(linear_to_srgb)):
        check_grads(f, (rgb,), order=1, modes=("rev",), eps=1e-6)
        check_grads(f, (dark,), order=1, modes=("rev",), eps=1e-7)
        assert f(rgb).dtype == jnp.float64
