"""Superpixel metrics against hand-computed values (thesis Sec. 5.2.3)."""

from __future__ import annotations

import numpy as np
import pytest

from mvedge_jax.metrics import (
    achievable_segmentation_accuracy,
    boundary_mask,
    boundary_recall,
    compactness,
    labels_per_pixel,
    self_similarity_error,
    superpixel_metrics,
    undersegmentation_error,
)

LAB = np.array([[0, 0, 1, 1]])
GT = np.array([[0, 0, 0, 1]])


def test_asa_hand():
    # superpixel 0: 2 px in object 0; superpixel 1: 1 px each -> (2 + 1) / 4
    assert achievable_segmentation_accuracy(LAB, GT) == pytest.approx(0.75)
    assert achievable_segmentation_accuracy(GT, GT) == 1.0


def test_undersegmentation_hand():
    # S0 (3 px): P0 min(2, 0) + P1 min(1, 1) = 1 -> 1/3; S1 (1 px): P1 min(1, 1) = 1 -> 1/1
    assert undersegmentation_error(LAB, GT) == pytest.approx((1 / 3 + 1) / 2)
    assert undersegmentation_error(GT, GT) == 0.0


def test_boundary_recall_hand():
    gt = np.zeros((1, 8), int)
    gt[0, 4:] = 1  # boundary pixels 3 and 4
    sp = np.zeros((1, 8), int)
    sp[0, 7:] = 1  # boundary pixels 6 and 7
    np.testing.assert_array_equal(boundary_mask(gt)[0], [0, 0, 0, 1, 1, 0, 0, 0])
    assert boundary_recall(sp, gt, distance=2) == pytest.approx(0.5)  # only pixel 4
    assert boundary_recall(sp, gt, distance=3) == pytest.approx(1.0)
    assert boundary_recall(sp, gt, distance=1) == pytest.approx(0.0)
    assert boundary_recall(sp, np.zeros_like(gt)) == 1.0  # no GT boundary


def test_compactness_hand():
    one = np.zeros((4, 4), int)
    assert compactness(one) == pytest.approx(np.pi / 4)  # square: 4π·16 / 16²
    halves = np.zeros((4, 4), int)
    halves[:, 2:] = 1  # two 4x2 rectangles: A = 8, L = 12 -> Q = 32π/144, weight 1/2 each
    assert compactness(halves) == pytest.approx(32 * np.pi / 144)
    # mean over views
    assert compactness(np.stack([one, halves])) == pytest.approx((np.pi / 4 + 32 * np.pi / 144) / 2)


def test_self_similarity_hand():
    lab = np.zeros((3, 3, 8, 8), int)
    lab[..., 4:] = 1
    d = np.zeros(lab.shape)
    assert self_similarity_error(lab, d) == pytest.approx(0.0)
    lab[0, 0, :, 4] = 0  # one view's boundary moved by a pixel
    # each label: 8 views at x, one at x + 0.5 -> mean deviation (8/18 + 8/18) / 9 = 8/81
    assert self_similarity_error(lab, d) == pytest.approx(8 / 81)


def test_self_similarity_follows_disparity_sign():
    U = V = 3
    lab = np.zeros((U, V, 12, 12), int)
    d = np.full(lab.shape, np.nan)
    for r in range(U):
        for c in range(V):
            dr, dc = r - 1, c - 1
            # a square at disparity 1: in view (r, c) it sits at x - dc, y - dr (SPEC §0)
            lab[r, c, 4 - dr : 8 - dr, 4 - dc : 8 - dc] = 1
            d[r, c, 4 - dr : 8 - dr, 4 - dc : 8 - dc] = 1.0
    assert self_similarity_error(lab, d) == pytest.approx(0.0, abs=1e-12)
    assert self_similarity_error(lab, -d) > 1.0  # wrong sign: centroids spread


def test_labels_per_pixel_hand():
    lab = np.zeros((3, 3, 6, 6), int)
    d = np.zeros((6, 6))
    assert labels_per_pixel(lab, d) == 1.0
    lab[0, 0] = 7  # one view disagrees everywhere
    assert labels_per_pixel(lab, d) == 2.0
    vd = np.zeros((3, 3, 6, 6))
    vd[0, 0] = 5.0  # ...but the point is occluded there: that view does not count
    assert labels_per_pixel(lab, d, vd) == 1.0


def test_superpixel_metrics_keys_and_bad_input():
    lab = np.zeros((3, 3, 6, 6), int)
    m = superpixel_metrics(lab, gt_ids=lab, gt_disparity=np.zeros(lab.shape))
    assert set(m) == {
        "compactness",
        "asa",
        "boundary_recall",
        "undersegmentation_error",
        "self_similarity_error",
        "labels_per_pixel",
    }
    assert set(superpixel_metrics(lab)) == {"compactness"}
    with pytest.raises(ValueError, match="shapes differ"):
        achievable_segmentation_accuracy(lab, lab[0])
    with pytest.raises(ValueError, match="integer"):
        undersegmentation_error(lab.astype(float), lab)
    with pytest.raises(ValueError, match=r"\(U, V, H, W\)"):
        self_similarity_error(lab[0], np.zeros(lab[0].shape))
    with pytest.raises(ValueError, match="NaN"):
        labels_per_pixel(lab, np.full((6, 6), np.nan))
