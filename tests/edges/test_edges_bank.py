"""Filter-bank properties (Alg. 1)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.edges import bank_width, blur_images, filter_disparities, prewitt_bank


def test_bank_shape_sums_and_symmetry():
    d = filter_disparities(61, 2.0)
    assert d.shape == (61,) and float(d[0]) == -2.0 and float(d[-1]) == 2.0
    assert abs(float(d[30])) < 1e-6
    w = bank_width(17, 2.0)
    b = np.asarray(prewitt_bank(d, 17, w))
    assert b.shape == (61, 17, w)
    np.testing.assert_allclose(b.sum(axis=(1, 2)), 0.0, atol=1e-5)
    np.testing.assert_allclose(np.maximum(b, 0).sum(axis=(1, 2)), 1.0, atol=1e-5)
    np.testing.assert_allclose(np.maximum(-b, 0).sum(axis=(1, 2)), 1.0, atol=1e-5)
    # Filter of -d is the filter of d mirrored in x and negated (sides swap).
    np.testing.assert_allclose(b[::-1], -b[:, :, ::-1], atol=1e-6)
    # d = 0: +1/h on column -1, -1/h on column +1 of every row.
    c = w // 2
    np.testing.assert_allclose(b[30][:, c - 1], 1 / 17, atol=1e-6)
    np.testing.assert_allclose(b[30][:, c + 1], -1 / 17, atol=1e-6)
    assert np.abs(b[30]).sum() == pytest.approx(2.0, abs=1e-5)


def test_bank_line_geometry():
    # Row offset a carries the positive side at column -a*d - 1 (anti-aliased between pixels).
    b = np.asarray(prewitt_bank(jnp.array([0.5]), 9, 11))[0]
    c = 5
    a = 2  # row index 4 + 2 = 6: line at column -1, + side at -2
    np.testing.assert_allclose(b[6, c - 2], 1 / 9, atol=1e-6)
    a = 1  # row 5: line at -0.5, + side at -1.5 split evenly between columns -1 and -2
    np.testing.assert_allclose(b[5, [c - 2, c - 1]], [0.5 / 9, 0.5 / 9], atol=1e-6)
    assert a == 1


def test_bank_bad_sizes():
    d = filter_disparities(5, 3.0)
    with pytest.raises(ValueError, match="cannot hold"):
        prewitt_bank(d, 17, 9)
    with pytest.raises(ValueError, match="odd"):
        prewitt_bank(d, 16, 41)
    with pytest.raises(ValueError):
        filter_disparities(2, 1.0)
    with pytest.raises(ValueError):
        filter_disparities(10, 0.0)


def test_bank_jit_and_blur():
    f = jax.jit(lambda d, s: prewitt_bank(d, 9, 21, shift=s))
    np.testing.assert_allclose(
        f(jnp.linspace(-1, 1, 7), 1.0), prewitt_bank(jnp.linspace(-1, 1, 7), 9, 21), atol=1e-7
    )
    img = jnp.zeros((1, 9, 9, 1)).at[0, 4, 4, 0].set(1.0)
    out = np.asarray(blur_images(img, 1.0, 3))[0, ..., 0]
    assert out.sum() == pytest.approx(1.0, abs=1e-5)
    assert out[4, 4] == out.max() and out[4, 3] == pytest.approx(out[3, 4], abs=1e-7)
