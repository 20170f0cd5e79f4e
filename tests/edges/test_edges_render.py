"""Rasterising, overlays and per-point errors of an `EdgeSet`."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.edges import EdgeSet, point_errors, render_overlay, render_sparse_disparity


def _set(x, y, d, conf, valid, visible=None):
    n = len(x)
    e = EdgeSet.empty(n)
    vis = np.ones(n, bool) if visible is None else np.asarray(visible)
    return EdgeSet(
        x=jnp.asarray(x, jnp.float32),
        y=jnp.asarray(y, jnp.float32),
        disparity=jnp.asarray(d, jnp.float32),
        confidence=jnp.asarray(conf, jnp.float32),
        visible=jnp.asarray(vis),
        lab=e.lab,
        direction=e.direction,
        intercepts=e.intercepts,
        valid=jnp.asarray(valid),
        n_dropped=e.n_dropped,
    )


def test_render_sparse_disparity_collisions_and_masks():
    e = _set(
        x=[1.2, 0.8, 3.0, 4.0, 9.0, 2.0],
        y=[2.0, 2.3, 0.0, 4.0, 1.0, 3.0],
        d=[0.5, -0.25, 1.0, 2.0, 3.0, 4.0],
        conf=[0.1, 0.9, 1.0, 1.0, 1.0, 1.0],
        valid=[True, True, True, False, True, True],
        visible=[True, True, True, True, True, False],
    )
    d, m = render_sparse_disparity(e, (5, 6))
    assert d.shape == (5, 6) and m.shape == (5, 6)
    # (1, 2): two points, the more confident (-0.25) wins; invalid, off-image (x=9) and
    # invisible points are not drawn.
    assert np.asarray(m).sum() == 2
    assert float(d[2, 1]) == -0.25 and float(d[0, 3]) == 1.0
    d2, m2 = render_sparse_disparity(e, (5, 6), visible_only=False)
    assert np.asarray(m2).sum() == 3 and float(d2[3, 2]) == 4.0
    with pytest.raises(ValueError):
        render_sparse_disparity(e, (5,))


def test_overlay_and_point_errors():
    e = _set(x=[1.0, 3.0], y=[1.0, 2.0], d=[0.5, 1.0], conf=[1, 1], valid=[True, True])
    img = np.full((4, 5, 3), 0.5, np.float32)
    ov = render_overlay(e, img)
    assert ov.dtype == np.uint8 and ov.shape == (4, 5, 3)
    assert not np.array_equal(ov[1, 1], ov[0, 0])  # points are coloured, the rest grey
    assert ov[0, 0, 0] == ov[0, 0, 1] == ov[0, 0, 2]
    with pytest.raises(ValueError):
        render_overlay(e, img[..., 0])
    gt = np.zeros((4, 5), np.float32)
    gt[1, 2] = 0.45  # in the 3x3 neighbourhood of (1, 1)
    gt[2, 3] = 5.0
    err = np.asarray(point_errors(e, gt))
    # (1, 1) sees 0.45 at (y=1, x=2); so does (x=3, y=2): |1 - 0.45|.
    np.testing.assert_allclose(err, [0.05, 0.55], atol=1e-6)
    mask = np.ones((4, 5), bool)
    mask[1, 2] = False
    err = np.asarray(point_errors(e, gt, mask))
    np.testing.assert_allclose(err, [0.5, 1.0], atol=1e-6)
