"""LightField container: validation, cross-hair, offsets and EPI slicing (SPEC §0)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.lightfield import LightField, horizontal_epis, vertical_epis, view_offsets

U, V, H, W = 5, 7, 6, 8


def _lf(key, **kw):
    views = jax.random.uniform(key, (U, V, H, W, 3))
    return LightField(views=views, view_mask=jnp.ones((U, V), bool), **kw)


def test_geometry_properties(key):
    lf = _lf(key)
    assert lf.grid == (U, V) and lf.size == (H, W) and lf.centre_index == (2, 3)
    np.testing.assert_array_equal(lf.centre_view, lf.views[2, 3])
    assert lf.centre_gt is None and lf.centre_gt_mask is None


def test_cross_hair_is_centre_row_and_column(key):
    lf = _lf(key)
    row, col = lf.cross_hair()
    assert row.shape == (V, H, W, 3) and col.shape == (U, H, W, 3)
    np.testing.assert_array_equal(row, lf.views[2])
    np.testing.assert_array_equal(col, lf.views[:, 3])


def test_view_offsets():
    dr, dc = view_offsets(U, V)
    assert dr.shape == (U, V) and dc.dtype == jnp.float32
    assert float(dr[0, 0]) == -2 and float(dr[-1, 0]) == 2 and float(dc[0, 0]) == -3
    assert float(dc[0, -1]) == 3 and float(dr[2, 3]) == 0 and float(dc[2, 3]) == 0


def test_epi_slicing_matches_direct_indexing(key):
    lf = _lf(key)
    v = np.asarray(lf.views)
    he = np.asarray(horizontal_epis(lf.views))
    ve = np.asarray(vertical_epis(lf.views))
    assert he.shape == (H, V, W, 3) and ve.shape == (W, U, H, 3)
    for y in range(H):
        for col in range(V):
            np.testing.assert_array_equal(he[y, col], v[2, col, y])
    for x in range(W):
        for row in range(U):
            np.testing.assert_array_equal(ve[x, row], v[row, 3, :, x])
    np.testing.assert_array_equal(np.asarray(lf.horizontal_epis()), he)
    # Custom channels (e.g. LAB or one channel)
    one = lf.views[..., :1]
    assert lf.vertical_epis(one).shape == (W, U, H, 1)


def test_gt_properties(key):
    gt = jax.random.normal(key, (U, V, H, W))
    lf = _lf(key, gt_disparity=gt, gt_mask=jnp.ones((U, V, H, W), bool))
    np.testing.assert_array_equal(lf.centre_gt, gt[2, 3])
    assert lf.centre_gt_mask.shape == (H, W)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"views": np.zeros((U, V, H, W))}, r"\(U, V, H, W, 3\)"),
        ({"views": np.zeros((U, V, H, W, 4))}, r"\(U, V, H, W, 3\)"),
        ({"views": np.zeros((2, V, H, W, 3)), "view_mask": np.ones((2, V), bool)}, "at least 3"),
        ({"view_mask": np.ones((U, V + 1), bool)}, "view_mask"),
        (
            {
                "gt_disparity": np.zeros((U, V, H, W + 1)),
                "gt_mask": np.ones((U, V, H, W + 1), bool),
            },
            "gt_disparity",
        ),
        ({"gt_disparity": np.zeros((U, V, H, W))}, "together"),
        ({"gt_disparity": np.zeros((U, V, H, W)), "gt_mask": np.ones((U, V, H), bool)}, "gt_mask"),
    ],
)
def test_shape_errors_quote_shapes(kwargs, match):
    args = {"views": np.zeros((U, V, H, W, 3), np.float32), "view_mask": np.ones((U, V), bool)}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        LightField(**{k: jnp.asarray(v) for k, v in args.items()})


def test_incomplete_cross_hair_is_rejected_but_off_cross_views_may_be_missing():
    views = jnp.zeros((U, V, H, W, 3))
    mask = np.ones((U, V), bool)
    mask[0, 0] = False  # off the cross-hair: fine (partial grids like dino_star33)
    LightField(views=views, view_mask=jnp.asarray(mask))
    mask[2, 5] = False  # on the centre row
    with pytest.raises(ValueError, match=r"\(2, 5\)"):
        LightField(views=views, view_mask=jnp.asarray(mask))


def test_lightfield_is_a_pytree_that_jits(key):
    lf = _lf(key)
    f = jax.jit(lambda lf: lf.views.mean(axis=(0, 1)))
    np.testing.assert_allclose(f(lf), lf.views.mean(axis=(0, 1)), rtol=1e-6)
