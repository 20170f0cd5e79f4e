"""rgb_to_lab: agreement with OpenCV, shapes, dtype, jit and gradients."""

from __future__ import annotations

import cv2
import jax
import jax.numpy as jnp
import numpy as np
from jax.test_util import check_grads

from mvedge_jax.lightfield import rgb_to_lab


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
