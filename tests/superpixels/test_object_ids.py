"""Per-view object-ID ground truth of the synthetic scenes (`mvedge_jax.synthetic`)."""

from __future__ import annotations

import numpy as np
import pytest

from mvedge_jax.synthetic import make_scene_with_objects, render_object_ids, scene_surfaces


def test_object_ids_match_gt_disparity():
    grid, size = (3, 3), (24, 20)
    lf, ids = make_scene_with_objects(5, grid=grid, size=size, n_objects=3)
    ids = np.asarray(ids)
    assert ids.shape == (3, 3, 24, 20) and ids.dtype == np.int32
    surfaces = scene_surfaces(5, grid=grid, size=size, n_objects=3)
    assert set(np.unique(ids)) <= set(range(len(surfaces)))
    assert len(np.unique(ids[1, 1])) >= 3  # wall, floor and at least one object visible
    planes = np.array([s.plane for s in surfaces])
    H, W = size
    y, x = np.meshgrid(np.arange(H) - (H - 1) / 2, np.arange(W) - (W - 1) / 2, indexing="ij")
    gt = np.asarray(lf.gt_disparity)
    for r in range(3):
        for c in range(3):
            a, b, cc = np.moveaxis(planes[ids[r, c]], -1, 0)
            d = (a + b * x + cc * y) / (1 - b * (c - 1) - cc * (r - 1))
            np.testing.assert_allclose(d, gt[r, c], atol=1e-4)


def test_object_ids_bad_input():
    with pytest.raises(ValueError, match="at least one surface"):
        render_object_ids([], grid=(3, 3), size=(4, 4))
    with pytest.raises(ValueError, match="grid"):
        render_object_ids(scene_surfaces(0), grid=(2, 3), size=(4, 4))
