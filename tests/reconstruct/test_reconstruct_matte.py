"""Boundary matting: the side of a depth discontinuity from the colour mixture."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.ndimage import grey_dilation, grey_erosion

from mvedge_jax.lightfield import linear_to_srgb, srgb_to_linear
from mvedge_jax.reconstruct import SharpenConfig, boundary_matte
from mvedge_jax.reconstruct._centre import colour_guide
from mvedge_jax.synthetic import make_scene

FG, BG = 1.5, -0.5


def _edge_scene(edge: float, size: int = 24):
    """A vertical depth edge at sub-pixel column ``edge`` (foreground on the left): the
    centre-sampled ground truth and box-filtered colours (red foreground, blue background)."""
    x = np.arange(size, dtype=np.float64)
    cover = np.clip(edge - (x - 0.5), 0.0, 1.0)  # foreground fraction of each pixel's box
    gt_row = np.where(x < edge, FG, BG)
    fg_col, bg_col = np.array([0.9, 0.2, 0.1]), np.array([0.1, 0.3, 0.8])
    row = cover[:, None] * fg_col + (1 - cover[:, None]) * bg_col
    img = np.broadcast_to(row, (size, size, 3)).astype(np.float32)
    gt = np.broadcast_to(gt_row, (size, size)).astype(np.float32)
    return gt, img


@pytest.mark.parametrize("edge", [10.1, 10.3, 10.45, 10.55, 10.7, 10.9])
@pytest.mark.parametrize("shift", [-1, 0, 1])
def test_matte_puts_the_edge_on_the_covered_pixel_centres(edge, shift):
    gt, img = _edge_scene(edge)
    # The map's edge is off by up to one pixel (fattened, exact or thinned).
    d = np.roll(gt, shift, axis=1)
    d[:, :2], d[:, -2:] = FG, BG
    out = np.asarray(jax.jit(boundary_matte)(jnp.asarray(d), jnp.asarray(img)))
    np.testing.assert_allclose(out, gt, atol=1e-5)


def _slanted_edge_linear_light(size: int = 32, slope: float = 0.13):
    """A near-horizontal depth edge (foreground above), crossing the pixel centres at every
    offset along its length, between a grey foreground and a dark blue-green background
    (backgammon's colours): the centre-sampled ground truth, each pixel's exact foreground
    coverage, and the colours mixed in linear light by that coverage, encoded as sRGB (as
    a camera or a renderer does)."""
    y = np.arange(size, dtype=np.float64)[:, None]
    x = np.arange(size, dtype=np.float64)[None, :]
    # Edge y = y0 + slope x; a pixel's box [y - 1/2, y + 1/2] is covered above the edge
    # (averaging the coverage over the box's width: the edge is linear across it).
    y_edge = size / 2 + 0.37 + slope * (x - size / 2)
    cover = np.clip(y_edge - (y - 0.5), 0.0, 1.0)
    gt = np.where(y < y_edge, FG, BG).astype(np.float32)
    fg_col, bg_col = np.array([0.5, 0.5, 0.5]), np.array([0.08, 0.25, 0.33])
    lin = cover[..., None] * np.asarray(srgb_to_linear(fg_col))
    lin = lin + (1 - cover[..., None]) * np.asarray(srgb_to_linear(bg_col))
    return gt, cover, np.asarray(linear_to_srgb(lin), np.float32)


def test_matte_in_linear_light_decides_mixtures_made_in_linear_light():
    gt, cover, img = _slanted_edge_linear_light()
    clear = np.abs(cover - 0.5) > 0.02  # away from near-ties
    inner = (slice(3, -3), slice(3, -3))
    for shift in (-1, 1):  # the map's edge one pixel too low (fattened) or too high
        d = np.roll(gt, shift, axis=0)
        lin = np.asarray(boundary_matte(jnp.asarray(d), colour_guide(img, "linear")))
        wrong = (np.abs(lin - gt) > 0.5) & clear
        assert not wrong[inner].any(), np.argwhere(wrong)
        # The same decisions made on CIELAB values: the encoding bends the mixture line,
        # and pixels that are mostly background look like foreground.
        lab = np.asarray(boundary_matte(jnp.asarray(d), colour_guide(img, "lab")))
        assert ((np.abs(lab - gt) > 0.5) & clear)[inner].sum() >= 2


def test_matte_fixes_fattened_boundaries_of_a_synthetic_scene():
    # 4x4 supersampling: with 2x2 a pixel whose centre lies just inside an edge often has
    # exactly half coverage, and the colour cannot tell its side.
    lf = make_scene(
        4, grid=(3, 3), size=(64, 64), disparity_range=(-1.0, 1.0), n_objects=3, supersample=4
    )
    gt = np.asarray(lf.centre_gt)
    guide = colour_guide(lf.centre_view, "lab")
    for fattened in (grey_dilation(gt, size=(2, 2)), grey_erosion(gt, size=(2, 2))):
        before = np.mean((fattened - gt) ** 2)
        after = np.mean((np.asarray(boundary_matte(jnp.asarray(fattened), guide)) - gt) ** 2)
        assert after < 0.3 * before, (before, after)
    # Ground truth is (almost) a fixed point.
    out = np.asarray(boundary_matte(jnp.asarray(gt), guide))
    assert np.mean(np.abs(out - gt) > 0.07) < 0.005


def test_matte_leaves_smooth_maps_and_flat_colours_alone():
    gt, img = _edge_scene(10.3)
    ramp = np.broadcast_to(np.linspace(-0.3, 0.3, 24, dtype=np.float32), (24, 24))
    out = boundary_matte(jnp.asarray(ramp), jnp.asarray(img))  # no jump above 0.2
    np.testing.assert_array_equal(np.asarray(out), ramp)
    flat = np.full_like(img, 0.5)  # no colour evidence: nothing decided
    d = np.roll(gt, 1, axis=1)
    out = boundary_matte(jnp.asarray(d), jnp.asarray(flat))
    np.testing.assert_array_equal(np.asarray(out), d)


def test_matte_leaves_colours_off_the_two_colour_line_alone():
    gt, img = _edge_scene(10.3)
    d = np.roll(gt, 1, axis=1)  # column 11 fattened: foreground over a pure background pixel
    d[:, :2], d[:, -2:] = FG, BG
    third = img.copy()
    # A colour perpendicular to F - B from the background's: alpha stays 0, the residual
    # |c - B - alpha (F - B)|^2 / |F - B|^2 is 0.65 / 1.14.
    third[:, 11] += np.array([0.1, 0.8, 0.0], np.float32)
    decided = np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(third)))
    np.testing.assert_allclose(decided[:, 11], BG)
    kept = np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(third), max_residual=0.5))
    np.testing.assert_allclose(kept[:, 11], FG)
    np.testing.assert_allclose(kept[:, :11], gt[:, :11])
    # Mixtures of the two colours lie on the line: the test leaves those decisions alone.
    tested = np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(img), max_residual=0.01))
    np.testing.assert_allclose(tested, gt, atol=1e-5)


def test_matte_vmaps_over_views():
    gts, imgs = zip(*(_edge_scene(e) for e in (10.2, 10.8)), strict=True)
    d = jnp.asarray(np.stack([np.roll(g, 1, axis=1) for g in gts]))
    out = jax.vmap(boundary_matte)(d, jnp.asarray(np.stack(imgs)))
    for i in range(2):
        np.testing.assert_array_equal(np.asarray(out[i]), np.asarray(boundary_matte(d[i], imgs[i])))


def test_matte_rejects_bad_input():
    gt, img = _edge_scene(10.3)
    with pytest.raises(ValueError, match="disparity must have shape"):
        boundary_matte(jnp.zeros((2, 24, 24)), img)
    with pytest.raises(ValueError, match="guide must have shape"):
        boundary_matte(gt, img[:10])
    with pytest.raises(ValueError, match="radius"):
        boundary_matte(gt, img, radius=0)
    with pytest.raises(ValueError, match="spatial_sigma"):
        boundary_matte(gt, img, spatial_sigma=0.0)
    with pytest.raises(ValueError, match="matte_radius"):
        SharpenConfig(matte_radius=0)
    with pytest.raises(ValueError, match="matte_jump"):
        SharpenConfig(matte_jump=-1.0)


def test_matte_needs_a_neighbour_on_the_chosen_side():
    """Three surfaces: a horizontal edge between a middle surface (top) and a far wall
    (bottom), and a near bar to the right. Pixels on the middle/wall edge whose colour
    matches the bar's (as a mixture of two other colours can) would join the bar by their
    colour alone; two pixels from the bar (inside the 5x5 window, not among the 8
    neighbours) they keep their value, next to the bar they may join it."""
    H, W = 12, 16
    mid_c, wall_c = np.array([0.9, 0.1, 0.1]), np.array([0.1, 0.1, 0.9])
    bar_c = np.array([0.5, 0.4, 0.5])
    d = np.full((H, W), -1.2, np.float32)
    d[:6] = -0.3
    d[:, 10:] = 1.35  # the bar
    img = np.empty((H, W, 3), np.float32)
    img[:6], img[6:] = mid_c, wall_c
    img[6] = bar_c  # the edge row
    img[:, 10:] = bar_c
    out = np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(img)))
    # Column 8: the bar (column 10) is in the window but not a neighbour.
    assert out[6, 8] == d[6, 8]
    # Column 9 touches the bar and has its colour: it joins the bar.
    assert out[6, 9] > 1.0
    # Off the edge row nothing changes left of the bar.
    np.testing.assert_array_equal(out[:6, :9], d[:6, :9])


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("mode", ["jit", "grad"])
def test_matte_leaves_a_pixel_alone_whose_window_has_one_side(dtype, mode, x64):
    """A pixel far below every other pixel of its window (an outlier of the input) is the
    window's only background pixel; the mean background colour is undefined without it, so
    it keeps its value, also when the matte is compiled with a backward pass (where XLA
    rounds the products of the window weights differently)."""
    rng = np.random.default_rng(3)
    H, W = 9, 9
    d = np.tile(np.linspace(-0.3, 0.0, W), (H, 1))
    d[4, 4] = -0.7
    img = rng.uniform(0.0, 1.0, (H, W, 3))
    d, img = jnp.asarray(d, dtype), jnp.asarray(img, dtype)

    def matte(x):
        return boundary_matte(x, img, radius=2, spatial_sigma=1.3, impure_weight=0.05)

    if mode == "jit":
        out = jax.jit(matte)(d)
    else:

        def loss(x):
            m = matte(x)
            return jnp.sum(m**2), m

        (_, out), _ = jax.jit(jax.value_and_grad(loss, has_aux=True))(d)
    assert float(out[4, 4]) == float(d[4, 4])
