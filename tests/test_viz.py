"""Visualisations: colour-mapped arrays, and figures whose PNGs carry a colour bar of the
right colour map and their value range in the PNG metadata."""

import io

import matplotlib
import numpy as np
import pytest
from PIL import Image

from mvedge_jax import viz


def _png(fig_md) -> tuple[np.ndarray, dict]:
    fig, md = fig_md
    im = Image.open(io.BytesIO(viz.png_bytes(fig, md)))
    return np.asarray(im.convert("RGB")).astype(np.float64), dict(im.text)


def _cmap_distance(pixels: np.ndarray, cmap) -> tuple[np.ndarray, np.ndarray]:
    """Distance (0-255 RGB) of each pixel to the nearest colour of ``cmap``, and that colour's
    position in [0, 1]."""
    cm = matplotlib.colormaps[cmap] if isinstance(cmap, str) else cmap
    ramp = cm(np.linspace(0, 1, 256))[:, :3] * 255
    d = np.linalg.norm(pixels[:, None, :] - ramp[None], axis=-1)
    return d.min(axis=1), d.argmin(axis=1) / 255


def _colour_bar_columns(img: np.ndarray, cmap, min_len: int) -> list[int]:
    """Columns in the right 40% of the image holding a vertical ramp of ``cmap``: at least
    ``min_len`` consecutive pixels on the colour map, its position rising upwards."""
    H, W, _ = img.shape
    cols = []
    for x in range(int(0.6 * W), W):
        dist, pos = _cmap_distance(img[:, x], cmap)
        on = dist < 12
        run, best, start = 0, (0, 0), 0
        for y in range(H):
            run = run + 1 if on[y] else 0
            if run == 1:
                start = y
            if run > best[0]:
                best = (run, start)
        if best[0] >= min_len:
            seg = pos[best[1] : best[1] + best[0]]
            if seg[0] > 0.9 and seg[-1] < 0.1 and np.all(np.diff(seg) <= 0.02):
                cols.append(x)
    return cols


def test_colorize_range_and_mask():
    d = np.linspace(0, 1, 20).reshape(4, 5)
    mask = np.ones_like(d, bool)
    mask[0, 0] = False
    img = viz.colorize_disparity(d, vmin=0, vmax=1, mask=mask)
    assert img.shape == (4, 5, 3) and img.dtype == np.uint8
    assert (img[0, 0] == 0).all()
    assert np.allclose(
        img[3, 4], np.asarray(matplotlib.colormaps[viz.DISPARITY_CMAP](1.0)[:3]) * 255, atol=1
    )
    with pytest.raises(ValueError, match="expects"):
        viz.colorize_disparity(np.zeros((2, 2, 2)))


def test_badpix_map_follows_the_toolkit_colours():
    gt = np.zeros((3, 3))
    d = gt.copy()
    d[1, 1] = 0.5
    mask = np.ones((3, 3), bool)
    mask[0, 2] = False
    img = viz.badpix_map(d, gt, threshold=0.07, mask=mask).astype(int)
    cm = matplotlib.colormaps[viz.BADPIX_CMAP]
    assert np.allclose(img[1, 1], np.asarray(cm(1.0)[:3]) * 255, atol=1)  # bad: red
    assert np.allclose(img[0, 0], np.asarray(cm(0.2)[:3]) * 255, atol=1)  # good: green
    assert img[1, 1, 0] > img[1, 1, 1] and img[0, 0, 1] > img[0, 0, 0]
    assert (img[0, 2] == 0).all()  # not evaluated
    with pytest.raises(ValueError, match="GT"):
        viz.badpix_map(d, gt[:2])


def test_error_map_sign_is_gt_minus_estimate():
    gt = np.zeros((1, 2))
    d = np.array([[-0.2, 0.2]])  # too far (smaller disparity), too near
    img = viz.error_map(d, gt).astype(int)
    assert img[0, 0, 0] > img[0, 0, 2]  # red: too far
    assert img[0, 1, 2] > img[0, 1, 0]  # blue: too near


def test_mosaic_layout():
    imgs = np.arange(2 * 3 * 2 * 2).reshape(2, 3, 2, 2).astype(np.float32)
    m = viz.mosaic(imgs, gap=1, fill=np.nan)
    assert m.shape == (2 * 2 + 1, 3 * 2 + 2)
    assert m[3, 3] == imgs[1, 1, 0, 0] and np.isnan(m[2, 0])


def test_epi_lines_are_drawn():
    epi = np.zeros((9, 40, 3), np.float32)
    img = viz.epi_with_lines(epi, np.array([10.0]), np.array([20.0]), row_scale=4)
    assert img.shape == (36, 40, 3)
    assert img[..., 0].sum() > 0 and img[:, :5].sum() == 0


def test_disparity_figure_has_colour_bar_and_range_in_metadata():
    d = np.fromfunction(lambda y, x: x / 63.0 * 2 - 1, (64, 64))
    img, text = _png(viz.disparity_figure(d, title="centre view", vmin=-1.0, vmax=1.0))
    assert float(text["vmin"]) == -1.0 and float(text["vmax"]) == 1.0
    assert text["units"] == viz.DISPARITY_LABEL and "px per view step" in text["units"]
    assert text["colormap"] == viz.DISPARITY_CMAP
    # a viridis ramp (yellow at the top, purple at the bottom) on the right of the image
    cols = _colour_bar_columns(img, viz.DISPARITY_CMAP, min_len=int(0.5 * img.shape[0]))
    assert cols, "no colour bar found"
    x0, y0, x1, y1 = (int(v) for v in text["colorbar_bbox"].split())
    assert all(x0 <= c < x1 for c in cols)
    dist, pos = _cmap_distance(img[y0 + 2 : y1 - 2, (x0 + x1) // 2], viz.DISPARITY_CMAP)
    assert dist.max() < 12 and pos[0] > 0.95 and pos[-1] < 0.05
    # the map itself: left column dark (low disparity), right column bright
    assert img[img.shape[0] // 2, 15].sum() < img[img.shape[0] // 2, x0 - 20].sum()


def test_disparity_figure_default_range_is_the_1st_to_99th_percentile():
    d = np.linspace(0, 10, 101 * 50).reshape(101, 50)
    _, text = _png(viz.disparity_figure(d, title="t"))
    assert float(text["vmin"]) == pytest.approx(np.percentile(d, 1), rel=1e-4)
    assert float(text["vmax"]) == pytest.approx(np.percentile(d, 99), rel=1e-4)


def test_error_figure_is_symmetric_and_diverging():
    gt = np.zeros((40, 40))
    d = np.random.default_rng(0).normal(0, 0.1, gt.shape)
    img, text = _png(viz.error_figure(d, gt, title="error"))
    assert float(text["vmin"]) == -viz.ERROR_LIMIT and float(text["vmax"]) == viz.ERROR_LIMIT
    assert text["colormap"] == viz.ERROR_CMAP and "GT" in text["units"]
    x0, y0, x1, y1 = (int(v) for v in text["colorbar_bbox"].split())
    column = img[y0 + 1 : y1 - 1, (x0 + x1) // 2]
    dist, _ = _cmap_distance(column, viz.ERROR_CMAP)
    assert dist.max() < 12
    assert column[len(column) // 2].min() > 200  # white at zero error


def test_badpix_figure_two_entry_bar():
    gt = np.zeros((40, 40))
    d = gt.copy()
    d[:20] = 0.5
    img, text = _png(viz.badpix_figure(d, gt, title="bad", threshold=0.07))
    assert text["threshold"] == "0.07"
    x0, y0, x1, y1 = (int(v) for v in text["colorbar_bbox"].split())
    xc = (x0 + x1) // 2
    top, bottom = img[y0 + 3, xc], img[y1 - 3, xc]
    assert top[0] > top[1] and bottom[1] > bottom[0]  # red above (bad), green below (good)


def test_epi_figure_draws_coloured_lines_and_says_which_row():
    epi = np.full((9, 60, 3), 0.5, np.float32)
    fig_md = viz.epi_figure(
        epi,
        np.array([10.0, 40.0]),
        np.array([18.0, 40.0]),
        np.array([1.0, 0.0]),
        title="horizontal EPI of pixel row y = 5",
        vmin=0.0,
        vmax=1.0,
    )
    img, text = _png(fig_md)
    assert "row y = 5" in text["Title"]
    x0, y0, _, y1 = (int(v) for v in text["colorbar_bbox"].split())
    rows = img[(y0 + y1) // 2 - 3 : (y0 + y1) // 2 + 3, : x0 - 5]  # across the lines
    dist, pos = _cmap_distance(rows.reshape(-1, 3), viz.DISPARITY_CMAP)
    on = dist < 20
    assert (pos[on] > 0.9).any() and (pos[on] < 0.1).any()  # both line colours present


def test_image_figure_rejects_bad_input():
    with pytest.raises(ValueError, match="expects"):
        viz.image_figure(np.zeros((2, 2, 4)), title="t", cmap="viridis", vmin=0, vmax=1, label="")
    with pytest.raises(ValueError, match="vmax > vmin"):
        viz.image_figure(np.zeros((2, 2)), title="t", cmap="viridis", vmin=1, vmax=1, label="")
