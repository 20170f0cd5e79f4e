"""Angular crop (central U'×V', centre preserved) and spatial downscale (INTER_AREA, GT × scale)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mvedge_jax.io import crop_window, load_light_field, load_light_field_with_info, write_pfm

H, W = 48, 64


@pytest.mark.parametrize(
    "grid, views, window",
    [
        ((9, 9), (7, 7), (1, 1, 7, 7)),
        ((9, 9), (9, 9), (0, 0, 9, 9)),
        ((9, 9), (4, 4), (2, 2, 4, 4)),  # even crop: old centre 4 -> new centre 2
        ((10, 10), (7, 7), (2, 2, 7, 7)),
        ((10, 10), (9, 9), (1, 1, 9, 9)),
        ((5, 7), (3, 5), (1, 1, 3, 5)),
        ((9, 9), None, (0, 0, 9, 9)),
    ],
)
def test_crop_window_keeps_centre(grid, views, window):
    assert crop_window(grid, views) == window
    if views is not None:
        r0, c0, u, v = window
        assert (r0 + u // 2, c0 + v // 2) == (grid[0] // 2, grid[1] // 2)


def test_crop_hci4d_with_gt(tmp_path, synth):
    v = synth.views(9, 9, H, W)
    gt = np.random.default_rng(0).normal(size=(H, W)).astype(np.float32)
    folder = synth.hci4d(tmp_path / "s", v, gt=gt, drange=(-1.0, 3.0))
    write_pfm(folder / "gt_disp_lowres_Cam000.pfm", gt + 5)  # outside a 7x7 crop
    write_pfm(folder / "gt_disp_lowres_Cam010.pfm", gt + 7)  # (1, 1): inside
    full = load_light_field(folder)
    lf, info = load_light_field_with_info(folder, views=7)
    assert lf.grid == (7, 7) and info.window == (1, 1, 7, 7)
    np.testing.assert_array_equal(np.asarray(lf.views), np.asarray(full.views)[1:8, 1:8])
    np.testing.assert_array_equal(np.asarray(lf.centre_view), np.asarray(full.centre_view))
    np.testing.assert_array_equal(np.asarray(lf.centre_gt), gt)
    np.testing.assert_array_equal(np.asarray(lf.gt_disparity)[0, 0], gt + 7)
    assert np.asarray(lf.gt_mask).reshape(49, -1).any(axis=1).sum() == 2
    assert lf.disparity_range == (-1.0, 3.0)


def test_crop_even_grid_and_partial(tmp_path, synth):
    v = synth.views(10, 10, H, W)
    folder = synth.grid(
        tmp_path / "g", v, lambda r, c: f"L_{r + 1:02d}_{c + 1:02d}.png", skip=[(0, 0), (3, 3)]
    )
    lf = load_light_field(folder, views=(7, 7), transpose=False)
    present = np.asarray(lf.view_mask)[:, :, None, None, None]
    np.testing.assert_array_equal(np.asarray(lf.views), v[2:9, 2:9] / np.float32(255) * present)
    assert not bool(lf.view_mask[1, 1]) and int(lf.view_mask.sum()) == 48


def test_downscale_views_and_gt(tmp_path, synth):
    v = synth.views(3, 3, H, W)
    gt = np.zeros((H, W), np.float32)
    gt[:, W // 2 :] = 2.0
    folder = synth.hci4d(tmp_path / "s", v, gt=gt, drange=(-1.0, 3.0))
    lf = load_light_field(folder, scale=0.5)
    assert lf.size == (H // 2, W // 2)
    expect = cv2.resize(
        v[1, 2].astype(np.float32) / 255, (W // 2, H // 2), interpolation=cv2.INTER_AREA
    )
    np.testing.assert_allclose(np.asarray(lf.views)[1, 2], expect, atol=1e-6)
    g = np.asarray(lf.centre_gt)
    np.testing.assert_allclose(g[:, : W // 4], 0.0)
    np.testing.assert_allclose(g[:, W // 4 :], 1.0)  # disparity in pixels halves
    assert bool(lf.centre_gt_mask.all())
    assert lf.disparity_range == (-0.5, 1.5)


def test_downscale_odd_size_and_scale_one(tmp_path, synth):
    folder = synth.grid(tmp_path / "g", synth.views(3, 3, 47, 63))
    # round(23.5) = 24, round(31.5) = 32 (half to even)
    assert load_light_field(folder, scale=0.5, transpose=False).size == (24, 32)
    assert load_light_field(folder, scale=1.0, transpose=False).size == (47, 63)
    assert load_light_field(folder, scale=0.4, transpose=False).size == (19, 25)


def test_downscale_gt_mask_footprint(tmp_path, synth):
    """A downscaled GT pixel is valid only if its whole footprint was; values average valid
    pixels only."""
    disp = np.full((H, W), 2.0, np.float32)
    disp[0, 0] = 50.0  # invalid pixel with a wild value: must not leak into the average
    mask = np.ones((H, W), bool)
    mask[0, 0] = False
    folder = synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), disp, mask=mask)
    lf = load_light_field(folder, scale=0.5)
    m = np.asarray(lf.centre_gt_mask)
    assert not m[0, 0] and m.sum() == m.size - 1
    np.testing.assert_allclose(np.asarray(lf.centre_gt)[m], 1.0, atol=1e-3)
    np.testing.assert_allclose(float(lf.centre_gt[0, 0]), 1.0, atol=1e-3)


def test_crop_and_scale_together(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(9, 9, H, W), gt=np.ones((H, W), np.float32))
    lf = load_light_field(folder, views=(5, 3), scale=0.5)
    assert lf.views.shape == (5, 3, H // 2, W // 2, 3)
    np.testing.assert_allclose(np.asarray(lf.centre_gt), 0.5)
