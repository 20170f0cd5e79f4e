"""The seed-grid choice of `superpixels` and `kmeans_superpixels` (``seed_candidates``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import csr_matrix

from mvedge_jax.metrics import self_similarity_error
from mvedge_jax.superpixels import SuperpixelConfig, kmeans_superpixels, superpixels
from mvedge_jax.superpixels._config import SEED_SHIFTS
from mvedge_jax.superpixels._superpixels import (
    _centre_visibility,
    _predicted_self_similarity,
    _project_centre,
    _uniform_seeds,
    _view_offsets,
)


def test_predicted_self_similarity_hand_computed():
    # 1x4 centre view, labels [0 0 1 1]; view 0 sees every pixel, view 1 all but pixel 3,
    # view 2 all but pixel 0. Label 0's centroids x: 0.5, 0.5, 1 (mean 2/3): deviations
    # 1/6, 1/6, 1/3 -> 2/9 per view. Label 1: 2.5, 2, 2.5 (mean 7/3) -> 2/9. Mean 2/9.
    seen = np.array([[1, 1, 1, 1], [1, 1, 1, 0], [0, 1, 1, 1]], np.float64)
    vis = csr_matrix(seen)
    labels = np.array([[0, 0, 1, 1]])
    assert _predicted_self_similarity(labels, vis) == pytest.approx(2 / 9)
    # label values do not matter, only the partition
    assert _predicted_self_similarity(labels * 7 + 3, vis) == pytest.approx(2 / 9)
    # every pixel visible everywhere: no deviation
    assert _predicted_self_similarity(labels, csr_matrix(np.ones((3, 4)))) == 0.0


def test_centre_visibility_counts_frame_and_occlusion():
    # 3x3 views of 4x6 px; left half at disparity 0, right half at 1 (nearer): in view
    # (0, +1) the right half moves one pixel left, covers column 2 and leaves column 5 empty
    d = np.zeros((4, 6), np.float32)
    d[:, 3:] = 1.0
    vis = _centre_visibility(d, 3, 3).toarray().reshape(9, 4, 6)
    np.testing.assert_array_equal(vis[4], 1)  # the centre view sees itself
    right = vis[5]  # view (0, +1)
    np.testing.assert_array_equal(right[:, [0, 1, 3, 4, 5]], 1)
    np.testing.assert_array_equal(right[:, 2], 0)  # hidden behind the nearer half
    left = vis[3]  # view (0, -1): the right half moves right, column 5 leaves the frame
    np.testing.assert_array_equal(left[:, :5], 1)
    np.testing.assert_array_equal(left[:, 5], 0)


def test_prediction_equals_the_metric_on_the_projected_labels(scene):
    # With integer disparities the projection is exact: the prediction is the metric of the
    # centre labels forward-projected into every view, holes (NaN disparity) left out.
    lf, ids, *_ = scene
    U, V = lf.grid
    H, W = lf.size
    centre_d = np.rint(np.asarray(lf.centre_gt)).astype(np.float32)
    centre_l = np.asarray(ids[U // 2, V // 2]) * 4 + (np.arange(W)[None, :] * 4 // W)
    labels, disp = _project_centre(centre_l, centre_d, _view_offsets(U, V))
    labels = np.asarray(labels).reshape(U, V, H, W)
    disp = np.where(labels >= 0, np.asarray(disp).reshape(U, V, H, W), np.nan)
    expect = self_similarity_error(np.maximum(labels, 0), disp)
    got = _predicted_self_similarity(centre_l, _centre_visibility(centre_d, U, V))
    assert expect > 0.05
    assert got == pytest.approx(expect, rel=1e-9)


def test_seed_grids_are_shifted_and_inside():
    base = _uniform_seeds(64, 64, 16)
    assert base.shape == (16, 2)
    for shift in SEED_SHIFTS[1:]:
        moved = _uniform_seeds(64, 64, 16, shift)
        assert moved.shape == base.shape
        assert (moved >= 0).all() and (moved <= 63).all()
        assert not np.array_equal(moved, base)


@pytest.mark.parametrize("n", [0, len(SEED_SHIFTS) + 1])
def test_seed_candidates_out_of_range(n):
    with pytest.raises(ValueError, match="seed_candidates"):
        SuperpixelConfig(seed_candidates=n)


def _score(result, centre_d):
    U, V = result.labels.shape[:2]
    return _predicted_self_similarity(
        np.asarray(result.labels[U // 2, V // 2]), _centre_visibility(centre_d, U, V)
    )


def test_more_candidates_never_predict_worse(scene):
    # the candidates of n grids include those of n - 1, and the lowest prediction is kept
    lf, ids, edges, offset = scene
    gt = np.asarray(lf.gt_disparity)
    runs = [
        superpixels(
            lf,
            SuperpixelConfig(size=12, seed_candidates=n),
            edges=edges,
            surface_offset=offset,
            disparity=gt,
        )
        for n in (1, 2, 4, 6)
    ]
    scores = [_score(r, gt[2, 2]) for r in runs]
    assert all(b <= a + 1e-12 for a, b in zip(scores, scores[1:], strict=False))
    assert scores[-1] < scores[0] - 0.01
    for r in runs:
        assert (np.asarray(r.labels) >= 0).all()
    # measured (ground-truth disparity): prediction 0.548 -> 0.505 px, self-similarity error
    # 1.001 -> 0.895 px (SLIC's grid -> 6 grids)
    sse = [self_similarity_error(r.labels, gt) for r in (runs[0], runs[-1])]
    assert sse[1] < sse[0] - 0.05


def test_kmeans_baseline_selection(scene):
    lf, *_ = scene
    gt_c = np.asarray(lf.centre_gt)
    one = kmeans_superpixels(lf, gt_c, SuperpixelConfig(size=12, seed_candidates=1))
    six = kmeans_superpixels(lf, gt_c, SuperpixelConfig(size=12, seed_candidates=6))
    # measured: prediction 0.573 -> 0.496 px, self-similarity error 1.032 -> 0.910 px
    assert _score(six, gt_c) < _score(one, gt_c) - 0.02
    assert (np.asarray(six.labels) >= 0).all()
    assert six.labels.shape == one.labels.shape
