"""Visualisation helpers return uint8 RGB arrays of the right shape and colours."""

import numpy as np
import pytest

from mvedge_jax import viz


def test_colorize_range_and_mask():
    d = np.linspace(0, 1, 20).reshape(4, 5)
    mask = np.ones_like(d, bool)
    mask[0, 0] = False
    img = viz.colorize_disparity(d, vmin=0, vmax=1, mask=mask)
    assert img.shape == (4, 5, 3) and img.dtype == np.uint8
    assert (img[0, 0] == 0).all()
    assert not np.array_equal(img[1, 0], img[3, 4])  # different values, different colours
    with pytest.raises(ValueError, match="expects"):
        viz.colorize_disparity(np.zeros((2, 2, 2)))


def test_badpix_map_marks_bad_pixels_red():
    gt = np.zeros((3, 3))
    d = gt.copy()
    d[1, 1] = 0.5
    img = viz.badpix_map(d, gt, threshold=0.07)
    assert tuple(img[1, 1]) == (220, 30, 30)
    assert tuple(img[0, 0]) == (255, 255, 255)


def test_mosaic_layout():
    imgs = np.arange(2 * 3 * 2 * 2).reshape(2, 3, 2, 2).astype(np.float32)
    m = viz.mosaic(imgs, gap=1)
    assert m.shape == (2 * 2 + 1, 3 * 2 + 2)
    assert m[3, 3] == imgs[1, 1, 0, 0]


def test_epi_lines_are_drawn():
    epi = np.zeros((9, 40, 3), np.float32)
    img = viz.epi_with_lines(epi, np.array([10.0]), np.array([20.0]), row_scale=4)
    assert img.shape == (36, 40, 3)
    assert img[..., 0].sum() > 0 and img[:, :5].sum() == 0
