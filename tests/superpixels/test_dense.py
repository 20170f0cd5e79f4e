"""Projection of the centre labels with a dense per-view disparity (`disparity=`)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.metrics import labels_per_pixel
from mvedge_jax.superpixels import SuperpixelConfig, superpixels
from mvedge_jax.superpixels._superpixels import _project_dense


def test_project_dense_fills_cracks_not_disocclusions():
    # 1x3 views of 2x6 px; row 0 a surface slanting 0.4 px/view per pixel, row 1 a near
    # object (d = 2) right of a far one (d = 0)
    centre_l = jnp.asarray([[10, 11, 12, 13, 14, 15], [20, 21, 22, 23, 24, 25]], jnp.int32)
    centre_d = np.array([[0, 0.4, 0.8, 1.2, 1.6, 2.0], [0, 0, 0, 2, 2, 2]], np.float32)
    d = np.zeros((1, 3, 2, 6), np.float32)
    d[0, 1] = centre_d
    # view (0, 0), dc = -1: row 0 lands at rint(x + d) = 0, 1, 3, 4 (5.6 and 7: outside);
    # the same plane seen there has d = 0.4 x / 1.4
    d[0, 0, 0] = 0.4 * np.arange(6) / 1.4
    # view (0, 2), dc = +1: row 1 lands at 0, 1, 2 and (nearer) 1, 2, 3; pixels 4, 5 see the
    # far surface (d = 0), hidden behind the object in the centre view
    d[0, 2, 1] = [0, 2, 2, 2, 0, 0]
    labels, ok = _project_dense(centre_l, jnp.asarray(d), 0.5)
    labels = np.asarray(labels)
    # pixel 2 (crack) looks back to rint(2 - 0.571) = 1, centre d 0.4 (same surface): 11;
    # pixel 5 (border) to rint(5 - 1.43) = 4, centre d 1.6: 14
    np.testing.assert_array_equal(labels[0, 0, 0], [10, 11, 11, 12, 13, 14])
    # pixels 4, 5 look back to 4, 5 where the centre sees d = 2, not 0: holes
    np.testing.assert_array_equal(labels[0, 2, 1], [20, 23, 24, 25, -1, -1])
    np.testing.assert_array_equal(np.asarray(ok), labels >= 0)
    np.testing.assert_array_equal(labels[0, 1], np.asarray(centre_l))


@pytest.fixture(scope="module")
def dense_runs(scene):
    lf, _, edges, offset = scene
    # one seed grid: the seed choice depends on the projecting disparity
    cfg = SuperpixelConfig(size=12, seed_candidates=1)
    gt = np.asarray(lf.gt_disparity)
    kw = dict(edges=edges, surface_offset=offset)
    return superpixels(lf, cfg, **kw), superpixels(lf, cfg, disparity=gt, **kw)


def test_dense_disparity_is_more_view_consistent(scene, dense_runs):
    # labels per pixel measured 1.288 (segments' disparity) -> 1.049 (GT disparity given)
    lf, *_ = scene
    gt = np.asarray(lf.gt_disparity)
    old, dense = dense_runs
    assert (np.asarray(dense.labels) >= 0).all()
    np.testing.assert_array_equal(np.asarray(dense.disparity), gt)
    lpp = labels_per_pixel(dense.labels, gt[2, 2], gt)
    assert lpp < 1.1
    assert lpp < labels_per_pixel(old.labels, gt[2, 2], gt) - 0.15
    # the centre view's labels are the same either way
    np.testing.assert_array_equal(np.asarray(dense.labels[2, 2]), np.asarray(old.labels[2, 2]))


def test_dense_disparity_bad_input(scene):
    lf, _, edges, offset = scene
    gt = np.asarray(lf.gt_disparity)
    cfg = SuperpixelConfig(size=12)
    with pytest.raises(ValueError, match="shape"):
        superpixels(lf, cfg, edges=edges, surface_offset=offset, disparity=gt[2, 2])
    with pytest.raises(ValueError, match="NaN"):
        bad = gt.copy()
        bad[0, 0, 0, 0] = np.nan
        superpixels(lf, cfg, edges=edges, surface_offset=offset, disparity=bad)
    with pytest.raises(ValueError, match="dense_tol"):
        SuperpixelConfig(dense_tol=-1.0)
