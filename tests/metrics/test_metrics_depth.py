"""Depth accuracy metrics: hand-computed values, masks, numpy agreement, jit, bad input."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.metrics import badpix, depth_metrics, mse_x100, q25_x100

D = np.array([[0.0, 0.02, 0.05], [0.5, -1.0, 0.0]], np.float32)
GT = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.3]], np.float32)
# |errors| = 0, .02, .05, .5, 1, .3
MASK = np.array([[True, True, True], [True, False, False]])  # drops the 1.0 and 0.3 errors


def test_hand_computed_values():
    assert float(mse_x100(D, GT)) == pytest.approx(
        100 * (0.0004 + 0.0025 + 0.25 + 1 + 0.09) / 6, rel=1e-5
    )
    assert float(badpix(D, GT, 0.01)) == pytest.approx(100 * 5 / 6, rel=1e-6)
    assert float(badpix(D, GT, 0.07)) == pytest.approx(50.0)
    assert float(badpix(D, GT, 0.5)) == pytest.approx(100 / 6, rel=1e-6)  # > t, not >=
    # sorted errors 0, .02, .05, .3, .5, 1: position 0.25*5 = 1.25 → .02 + .25*.03
    assert float(q25_x100(D, GT)) == pytest.approx(2.75, rel=1e-4)


def test_masks():
    assert float(mse_x100(D, GT, MASK)) == pytest.approx(
        100 * (0.0004 + 0.0025 + 0.25) / 4, rel=1e-5
    )
    assert float(badpix(D, GT, 0.03, MASK)) == pytest.approx(50.0)
    # errors 0, .02, .05, .5: position .75 → .015
    assert float(q25_x100(D, GT, MASK)) == pytest.approx(1.5, rel=1e-4)
    empty = np.zeros_like(MASK)
    assert np.isnan(float(mse_x100(D, GT, empty))) and np.isnan(float(q25_x100(D, GT, empty)))


def test_agree_with_numpy_on_random_maps(key):
    k1, k2, k3 = jax.random.split(key, 3)
    d = np.asarray(jax.random.normal(k1, (37, 53)))
    gt = np.asarray(jax.random.normal(k2, (37, 53)))
    m = np.asarray(jax.random.uniform(k3, (37, 53)) > 0.3)
    err = np.abs(d - gt)[m]
    out = depth_metrics(d, gt, m)
    assert out["mse_x100"] == pytest.approx(100 * np.mean(err**2), rel=1e-5)
    assert out["q25_x100"] == pytest.approx(100 * np.percentile(err, 25), rel=1e-5)
    for t in (0.01, 0.03, 0.07, 0.1, 0.3, 0.7):
        assert out[f"badpix_{t}"] == pytest.approx(100 * np.mean(err > t), rel=1e-5)


def test_depth_metrics_keys_and_types():
    out = depth_metrics(D, GT)
    assert list(out) == [
        "mse_x100",
        "badpix_0.01",
        "badpix_0.03",
        "badpix_0.07",
        "badpix_0.1",
        "badpix_0.3",
        "badpix_0.7",
        "q25_x100",
    ]
    assert all(type(v) is float for v in out.values())
    assert out["badpix_0.07"] == pytest.approx(50.0)


def test_jit_vmap_and_traced_threshold(key):
    d = jax.random.normal(key, (4, 16, 16))
    gt = jnp.zeros((4, 16, 16))
    f = jax.jit(
        jax.vmap(
            lambda a, b, t: jnp.stack([mse_x100(a, b), badpix(a, b, t), q25_x100(a, b)]),
            in_axes=(0, 0, None),
        )
    )
    out = f(d, gt, 0.5)
    for i in range(4):
        np.testing.assert_allclose(out[i, 0], mse_x100(d[i], gt[i]), rtol=1e-5)
        np.testing.assert_allclose(out[i, 1], badpix(d[i], gt[i], 0.5), rtol=1e-5)
        np.testing.assert_allclose(out[i, 2], q25_x100(d[i], gt[i]), rtol=1e-5)
    # differentiable where it makes sense (MSE)
    g = jax.grad(lambda a: mse_x100(a, gt[0]))(d[0])
    np.testing.assert_allclose(g, 200 * d[0] / d[0].size, rtol=1e-5)


def test_bad_inputs():
    with pytest.raises(ValueError, match=r"\(2, 3\) vs \(3, 2\)"):
        mse_x100(D, GT.T)
    with pytest.raises(ValueError, match="mask shape"):
        badpix(D, GT, 0.1, MASK[:, :2])
    with pytest.raises(ValueError, match="boolean"):
        q25_x100(D, GT, MASK.astype(np.float32))
    with pytest.raises(ValueError, match="empty"):
        depth_metrics(np.zeros((0, 3)), np.zeros((0, 3)))
