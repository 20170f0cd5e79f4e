"""Boundary matting: the side of a depth discontinuity from the colour mixture."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.ndimage import grey_dilation, grey_erosion, minimum_filter

from mvedge_jax.lightfield import linear_to_srgb, srgb_to_linear
from mvedge_jax.reconstruct import (
    SharpenConfig,
    boundary_matte,
    near_surface_colours,
    observed_background,
    split_candidates,
)
from mvedge_jax.reconstruct._centre import colour_guide
from mvedge_jax.reconstruct._matte import LIST_STEPS, largest_jumps, pixel_subset
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


@pytest.mark.parametrize("edge", [10.3, 10.7])
def test_matte_snaps_values_between_the_two_surfaces(edge):
    gt, img = _edge_scene(edge)
    # A map averaged across the edge (as a merge of two views' values or a blur leaves
    # it): the pixels next to the edge hold values between the two surfaces.
    d = gt.copy()
    d[:, 1:-1] = (gt[:, :-2] + gt[:, 1:-1] + gt[:, 2:]) / 3
    between = (d > BG + 0.1) & (d < FG - 0.1)
    assert between[:, 10:12].all()
    kept = np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(img)))
    # Without snapping a pixel already on its side keeps its value: some stay between.
    assert ((kept > BG + 0.1) & (kept < FG - 0.1)).any()
    assert np.abs(kept - gt)[:, 2:-2].max() > 0.6
    snapped = np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(img), snap=0.1))
    # Each pixel is on its ground truth's side, at its side's mean: that mean includes the
    # averaged pixels above and below it (at their impure weight), hence the tolerance.
    np.testing.assert_allclose(snapped[:, 2:-2], gt[:, 2:-2], atol=0.15)
    # snap = 0: every decided pixel takes its side's mean; pixels off the edge stay.
    every = np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(img), snap=0.0))
    np.testing.assert_allclose(every[:, 2:-2], gt[:, 2:-2], atol=0.15)
    np.testing.assert_array_equal(every[:, :7], d[:, :7])
    np.testing.assert_array_equal(every[:, 15:], d[:, 15:])


@pytest.mark.parametrize("edge", [10.03, 9.97])
def test_matte_soft_blends_the_two_sides_where_the_mixture_is_uncertain(edge):
    # Pixel 10 is 53 % foreground (on the foreground) or 47 % (on the background): within
    # a band of 0.2 around 1/2 it takes the blend of the two sides' values,
    # p = 1/2 + (α − 1/2) / 0.2; every other pixel, and pixel 10 with a band narrower than
    # its |α − 1/2|, is decided as without the band.
    gt, img = _edge_scene(edge)
    d, img = jnp.asarray(gt), jnp.asarray(img)
    kw = dict(impure_weight=0.0)  # pure side colours: α is the coverage
    hard = np.asarray(boundary_matte(d, img, **kw))
    np.testing.assert_array_equal(np.asarray(boundary_matte(d, img, soft=0.0, **kw)), hard)
    np.testing.assert_allclose(hard, gt, atol=1e-5)
    out = np.asarray(jax.jit(lambda x, g: boundary_matte(x, g, soft=0.2, **kw))(d, img))
    alpha = edge - 9.5
    p = 0.5 + (alpha - 0.5) / 0.2
    np.testing.assert_allclose(out[:, 10], p * FG + (1 - p) * BG, atol=1e-4)
    np.testing.assert_array_equal(np.delete(out, 10, axis=1), np.delete(hard, 10, axis=1))
    np.testing.assert_array_equal(np.asarray(boundary_matte(d, img, soft=0.05, **kw)), hard)
    with pytest.raises(ValueError, match="soft"):
        boundary_matte(d, img, soft=-0.1)


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


def _textured_edge(observed):
    """A vertical depth edge (foreground left, grey 0.5) whose mixed column 8 is 20 %
    foreground over a dark (0.05) background stripe, next to bright (0.9) background
    columns: the map is fattened (column 8 foreground). Returns ``(d, guide, out)`` with
    ``out`` the matte given the true background colour at column 8 (``observed``) or not."""
    H, W = 12, 16
    d = np.full((H, W), BG, np.float32)
    d[:, :9] = FG
    grey = np.full((W,), 0.9, np.float32)
    grey[:8] = 0.5
    grey[8] = 0.2 * 0.5 + 0.8 * 0.05
    img = np.repeat(np.broadcast_to(grey, (H, W))[..., None], 3, axis=-1).copy()
    kw = {}
    if observed:
        back = np.zeros_like(img)
        back[:, 8] = 0.05
        valid = np.zeros((H, W), bool)
        valid[:, 8] = True
        kw = {"background": jnp.asarray(back), "background_valid": jnp.asarray(valid)}
    out = np.asarray(jax.jit(boundary_matte)(jnp.asarray(d), jnp.asarray(img), **kw))
    return d, img, out


def test_matte_decides_with_the_observed_background():
    # The window's background (the bright columns) makes the mostly-background pixel look
    # like foreground; its own background colour, seen by another view, does not.
    d, img, plain = _textured_edge(observed=False)
    np.testing.assert_array_equal(plain, d)
    _, _, out = _textured_edge(observed=True)
    np.testing.assert_allclose(out[:, 8], BG, atol=1e-6)
    np.testing.assert_array_equal(np.delete(out, 8, axis=1), np.delete(d, 8, axis=1))
    # Nowhere valid: the window mean, as without it.
    none = boundary_matte(d, img, background=np.ones_like(img), background_valid=np.zeros(d.shape))
    np.testing.assert_array_equal(np.asarray(none), plain)
    with pytest.raises(ValueError, match="together"):
        boundary_matte(d, img, background=img)
    with pytest.raises(ValueError, match="background must have shape"):
        boundary_matte(d, img, background=img[:4], background_valid=np.ones(d.shape, bool))


def _square_light_field(U=5, V=5, size=32, fg=2.0):
    """A textured far plane (disparity 0) and a textured square (disparity ``fg``, rows and
    columns 12–19 in the centre view), integer shifts, no mixed pixels: ``(guides (U, V, H,
    W, 3), maps (U, V, H, W), background texture (H, W, 3))``."""
    rng = np.random.default_rng(3)
    back = rng.uniform(0.0, 1.0, (size, size, 3)).astype(np.float32)
    front = rng.uniform(0.0, 1.0, (8, 8, 3)).astype(np.float32)
    guides = np.broadcast_to(back, (U, V, size, size, 3)).copy()
    maps = np.zeros((U, V, size, size), np.float32)
    for r in range(U):
        for c in range(V):
            # A point at x in the centre view is at x - offset * disparity in this view.
            y0, x0 = 12 - int((r - U // 2) * fg), 12 - int((c - V // 2) * fg)
            guides[r, c, y0 : y0 + 8, x0 : x0 + 8] = front
            maps[r, c, y0 : y0 + 8, x0 : x0 + 8] = fg
    return guides, maps, back


def _observed(guides, maps, view, present, steps=3, **kw):
    b = minimum_filter(maps[view], size=5, mode="nearest")
    colour, valid = jax.jit(observed_background, static_argnames=("steps", "capacity"))(
        *view, b, guides, maps, present, steps=steps, tolerance=0.3, **kw
    )
    return np.asarray(colour), np.asarray(valid), b


def test_observed_background_is_the_background_behind_the_foreground_edge():
    guides, maps, back = _square_light_field()
    U, V = maps.shape[:2]
    colour, valid, b = _observed(guides, maps, (2, 2), np.ones((U, V), bool))
    far = b == 0
    # Every sample that counts is the far plane's texture at the pixel itself.
    np.testing.assert_allclose(colour[valid & far], back[valid & far], atol=1e-6)
    # Every square pixel within 2 px of its outline (window minimum 0) has a sample.
    outline = (maps[2, 2] > 0) & far
    assert outline.sum() == 48 and valid[outline].all()
    # Views without an image never count, nor views outside the grid.
    _, none, _ = _observed(guides, maps, (2, 2), _only(U, V))
    assert not none.any()
    g1, m1 = guides[2:3, 2:4], maps[2:3, 2:4]
    _, edge_of_grid, _ = _observed(g1, m1, (0, 0), np.array([[True, False]]))
    assert not edge_of_grid.any()


def test_observed_background_of_a_subset_of_pixels():
    guides, maps, _ = _square_light_field()
    present = np.ones(maps.shape[:2], bool)
    colour, valid, _ = _observed(guides, maps, (1, 3), present)
    where = np.zeros(maps.shape[2:], bool)
    where[8:24, 6:26] = True
    sub, sub_valid, _ = _observed(guides, maps, (1, 3), present, where=where, capacity=1000)
    np.testing.assert_array_equal(sub_valid, valid & where)
    np.testing.assert_array_equal(sub[where], colour[where])
    # With room for 3 rows of the subset, the rows below it are not computed.
    part, part_valid, _ = _observed(guides, maps, (1, 3), present, where=where, capacity=60)
    np.testing.assert_array_equal(part_valid[:11], sub_valid[:11])
    assert sub_valid[11:].any() and not part_valid[11:].any()
    np.testing.assert_array_equal(part[:11], sub[:11])


def _only(U, V):
    present = np.zeros((U, V), bool)
    present[U // 2, V // 2] = True
    return present


def test_observed_background_rejects_bad_input():
    guides, maps, _ = _square_light_field(U=3, V=3)
    b = np.zeros(maps.shape[2:], np.float32)
    with pytest.raises(ValueError, match="steps"):
        observed_background(1, 1, b, guides, maps, np.ones((3, 3), bool), steps=0)
    with pytest.raises(ValueError, match="background_disparity must have shape"):
        observed_background(1, 1, b[:4], guides, maps, np.ones((3, 3), bool))
    with pytest.raises(ValueError, match="present must have shape"):
        observed_background(1, 1, b, guides, maps, np.ones((2, 3), bool))
    with pytest.raises(ValueError, match="guides must have shape"):
        observed_background(1, 1, b, guides[0], maps, np.ones((3, 3), bool))
    with pytest.raises(ValueError, match="capacity"):
        observed_background(1, 1, b, guides, maps, np.ones((3, 3), bool), capacity=0)
    with pytest.raises(ValueError, match="where must have shape"):
        observed_background(1, 1, b, guides, maps, np.ones((3, 3), bool), where=b[:3] > 0)


@pytest.mark.parametrize(
    "n, capacity, fraction",
    [(100, 10, 0.3), (5000, 6000, 0.5), (160 * 160, 4096, 0.9), (128 * 128, 4096, 0.1)],
)
def test_pixel_subset_is_the_first_pixels_of_the_mask(n, capacity, fraction):
    where = jnp.asarray(np.random.default_rng(n).random(n) < fraction)
    expected = jnp.nonzero(where, size=capacity, fill_value=n)[0]
    np.testing.assert_array_equal(
        np.asarray(jax.jit(pixel_subset, static_argnums=1)(where, capacity)), expected
    )


def test_pixel_subset_of_a_batch_is_each_frames_subset():
    """Frames of a batch (one almost empty, one over capacity) get each frame's own list."""
    rng = np.random.default_rng(3)
    where = jnp.asarray(rng.random((2, 3, 500)) < np.array([0.02, 0.5, 0.95])[:, None])
    out = np.asarray(jax.jit(pixel_subset, static_argnums=1)(where, 200))
    assert out.shape == (2, 3, 200)
    for b in range(2):
        for f in range(3):
            expected = jnp.nonzero(where[b, f], size=200, fill_value=500)[0]
            np.testing.assert_array_equal(out[b, f], expected)


def test_largest_jumps_keeps_the_list_for_the_largest_jumps():
    """Three maps of 20×20 pixels in 2×2 blocks (so that counting every other row and column
    is exact), jump 0.5, a list of 40: the first has 24 pixels above 0.5 (all kept); the
    second 120 above 0.5 of which 32 above 0.75 (the 1.5× step: kept, the 1.25× step's 80 do
    not fit); the third 200 above even 8 × 0.5 (that step's mask)."""
    rng = np.random.default_rng(0)
    blocks = np.zeros((3, 100), np.float32)
    blocks[0, rng.choice(100, 6, replace=False)] = 0.6
    idx = rng.permutation(100)
    blocks[1, idx[:30]] = 0.55
    blocks[1, idx[:20]] = 0.7
    blocks[1, idx[:8]] = 0.9
    blocks[2, :50] = 5.0
    blocks[2, 50:60] = 0.6
    span = np.repeat(np.repeat(blocks.reshape(3, 10, 10), 2, axis=1), 2, axis=2)
    got = np.asarray(largest_jumps(jnp.asarray(span), 0.5, 40))
    np.testing.assert_array_equal(got[0], span[0] > 0.5)
    np.testing.assert_array_equal(got[1], span[1] > 0.75)
    assert got[1].sum() == 32
    np.testing.assert_array_equal(got[2], span[2] > 0.5 * LIST_STEPS[-1])
    # A list that holds every pixel above the jump changes nothing.
    np.testing.assert_array_equal(
        np.asarray(largest_jumps(jnp.asarray(span), 0.5, 400)), span > 0.5
    )


# A slanted depth edge between a flat red foreground (left) and a background whose texture
# (periods of 2.7–4.1 px) changes the window means next to the edge from pixel to pixel.
_MV_FG, _MV_BG, _MV_SIZE = 1.0, -1.3, 40


def _mv_edge(y):
    return 17.3 + 0.29 * y


def _mv_view(k: int, seed: int, ss: int = 5) -> np.ndarray:
    """View ``(0, k)`` of the scene, each pixel the mean of ``ss²`` samples: the foreground
    edge moves by ``-_MV_FG k`` pixels, the background texture by ``-_MV_BG k``."""
    rng = np.random.default_rng(seed)
    s = (np.arange(ss) + 0.5) / ss - 0.5
    y = np.arange(_MV_SIZE)[:, None, None, None] + s[None, None, :, None]
    x = np.arange(_MV_SIZE)[None, :, None, None] + s[None, None, None, :]
    fg = x < _mv_edge(y) - _MV_FG * k
    xb = x + _MV_BG * k  # the background point's position in the centre view
    phase = rng.uniform(0, 2 * np.pi, 3)
    tex = np.stack(
        [
            0.45 + 0.3 * np.sin(2 * np.pi * xb / p + f + 0.8 * y)
            for p, f in zip((2.7, 3.4, 4.1), phase, strict=True)
        ],
        axis=-1,
    )
    colour = np.where(fg[..., None], np.array([0.9, 0.15, 0.1]), tex)
    return colour.mean(axis=(2, 3)).astype(np.float32)


def test_matte_with_other_views_averages_out_the_background_texture():
    y, x = np.mgrid[:_MV_SIZE, :_MV_SIZE]
    gt = jnp.asarray(np.where(x < _mv_edge(y), _MV_FG, _MV_BG).astype(np.float32))
    ks = [k for k in range(-4, 5) if k]
    offsets = jnp.asarray([(0, k) for k in ks], jnp.float32)
    alone = with_others = 0
    for seed in range(5):
        guide = jnp.asarray(_mv_view(0, seed))
        colours, weights = near_surface_colours(
            gt, jnp.asarray(np.stack([_mv_view(k, seed) for k in ks])), offsets
        )
        alone += int((np.asarray(boundary_matte(gt, guide)) != gt).sum())
        out = jax.jit(boundary_matte)(gt, guide, others=colours, other_weights=weights)
        with_others += int((np.asarray(out) != gt).sum())
    # The centre view alone moves 35 pixels of the ground truth (5–10 per seed) to the
    # wrong side; with the eight other views of the row, 2.
    assert alone >= 20, alone
    assert with_others <= 4, with_others


def test_matte_with_other_views_weighted_zero_is_the_matte_alone():
    gt, img = _edge_scene(10.45)
    d = jnp.asarray(np.roll(gt, 1, axis=1))
    rng = np.random.default_rng(0)
    others = jnp.asarray(rng.uniform(0, 1, (3, *img.shape)).astype(np.float32))
    zero = jnp.zeros((3, *gt.shape), jnp.float32)
    np.testing.assert_array_equal(
        np.asarray(boundary_matte(d, img, others=others, other_weights=zero)),
        np.asarray(boundary_matte(d, img)),
    )


def test_matte_follows_the_other_views_only_where_the_window_holds_two_surfaces():
    gt, img = _edge_scene(10.3)  # column 10: foreground; 11: background
    d = jnp.asarray(gt)
    # Other views that see column 11 in the pure foreground colour outvote the pixel's own
    # colour and pull it to the foreground.
    fg = img.copy()
    fg[:, 11] = img[:, 0]
    others = jnp.asarray(np.stack([fg] * 4))
    weights = jnp.ones((4, *gt.shape), jnp.float32)
    out = np.asarray(boundary_matte(d, img, others=others, other_weights=weights))
    assert np.all(out[:, 11] == FG) and np.all(out[:, 12] == BG)
    # The same where a nearer surface lies in the window (its largest disparity is not the
    # foreground side's): the other views do not count, as with a negative tolerance.
    for kw in ({"align_tolerance": -1.0}, {}):
        near = np.asarray(gt).copy()
        if not kw:
            near[:, 13] = 3.0  # a third, nearer surface two columns from column 11
        out = np.asarray(
            boundary_matte(jnp.asarray(near), img, others=others, other_weights=weights, **kw)
        )
        np.testing.assert_array_equal(out[:, 11], near[:, 11])
    # ... and without the tolerance they would have pulled it there too.
    out = boundary_matte(
        jnp.asarray(near), img, others=others, other_weights=weights, align_tolerance=1e9
    )
    assert np.all(np.asarray(out)[:, 11] > 1.0)


def test_near_surface_colours_sample_the_nearest_surface_in_each_view():
    rng = np.random.default_rng(1)
    H, W = 12, 16
    guides = jnp.asarray(rng.uniform(0, 1, (3, H, W, 3)).astype(np.float32))
    d = np.full((H, W), -1.0, np.float32)
    d[:, 8:] = 2.0  # a near surface from column 8; its window maximum reaches column 6
    offsets = jnp.asarray([(0, 1), (-1, 0), (0, -2)], jnp.float32)
    colours, weights = jax.jit(near_surface_colours)(jnp.asarray(d), guides, offsets)
    h = np.where(np.arange(W) >= 6, 2.0, -1.0)  # the window maximum (radius 2) per column
    ys, xs = np.mgrid[:H, :W]
    for k, (dr, dc) in enumerate(np.asarray(offsets)):
        sy, sx = (ys - dr * h).astype(int), (xs - dc * h).astype(int)
        inside = (sy >= 0) & (sy < H) & (sx >= 0) & (sx < W)
        np.testing.assert_array_equal(np.asarray(weights[k]), inside.astype(np.float32))
        g = np.asarray(guides[k])
        np.testing.assert_array_equal(np.asarray(colours[k])[inside], g[sy[inside], sx[inside]])


@pytest.mark.parametrize(("value", "weight"), [(0.25, 0.5), (0.1, 0.8), (0.5, 0.0), (0.4, 0.2)])
def test_near_surface_colours_weigh_the_distance_to_the_pixel(value, weight):
    d = jnp.full((8, 8), value, jnp.float32)  # lands value px from a pixel centre (< 1/2)
    guides = jnp.ones((1, 8, 8, 3), jnp.float32)
    _, w = near_surface_colours(d, guides, jnp.asarray([[0.0, 1.0]]), phase=0.5)
    np.testing.assert_allclose(np.asarray(w)[0, :, 1:], weight, atol=1e-6)
    _, w = near_surface_colours(d, guides, jnp.asarray([[0.0, 1.0]]), phase=1.0)
    np.testing.assert_allclose(np.asarray(w)[0, :, 1:], 1 - 0.5 * (1 - weight), atol=1e-6)


def test_near_surface_colours_and_others_reject_bad_input():
    gt, img = _edge_scene(10.3)
    others = jnp.zeros((2, *img.shape), jnp.float32)
    weights = jnp.ones((2, *gt.shape), jnp.float32)
    with pytest.raises(ValueError, match="given together"):
        boundary_matte(gt, img, others=others)
    with pytest.raises(ValueError, match="others must have shape"):
        boundary_matte(gt, img, others=others[:, :5], other_weights=weights)
    with pytest.raises(ValueError, match="others must have shape"):
        boundary_matte(gt, img, others=others, other_weights=weights[:1])
    off = jnp.zeros((2, 2), jnp.float32)
    with pytest.raises(ValueError, match="disparity must have shape"):
        near_surface_colours(gt[0], others, off)
    with pytest.raises(ValueError, match="guides must have shape"):
        near_surface_colours(gt, others[0], off)
    with pytest.raises(ValueError, match="offsets must have shape"):
        near_surface_colours(gt, others, off[:1])
    with pytest.raises(ValueError, match="radius"):
        near_surface_colours(gt, others, off, radius=0)
    with pytest.raises(ValueError, match="phase"):
        near_surface_colours(gt, others, off, phase=0.0)
    with pytest.raises(ValueError, match="matte_phase"):
        SharpenConfig(matte_phase=0.0)


def test_near_surface_colours_weigh_the_larger_of_the_row_and_column_distances():
    d = jnp.full((8, 8), 0.2, jnp.float32)  # lands 0.2 px from a pixel along both axes
    guides = jnp.ones((1, 8, 8, 3), jnp.float32)
    _, w = near_surface_colours(d, guides, jnp.asarray([[1.0, 1.0]]), phase=0.5)
    np.testing.assert_allclose(np.asarray(w)[0, 1:, 1:], 1 - 0.2 / 0.5, atol=1e-6)


def _matte_with_others_scene():
    """The edge scene of `_edge_scene`, the map one column fattened, and four other views
    whose column 11 shows the pure foreground colour (they pull it to the foreground)."""
    gt, img = _edge_scene(10.3)
    fg = img.copy()
    fg[:, 11] = img[:, 0]
    return gt, img, jnp.asarray(np.stack([fg] * 4)), jnp.ones((4, *gt.shape), jnp.float32)


def test_matte_tests_the_two_colour_model_on_the_pixels_own_colour():
    # Column 11's own colour lies on the line through B and F (α 0.2) and passes the
    # two-colour test; the other views then move it to the foreground (α 0.84 together).
    # Tested with that combined α, the colour would lie off the line and stay.
    gt, img, others, weights = _matte_with_others_scene()
    fg, bg = img[0, 0], img[0, -1]
    img = img.copy()
    img[:, 11] = bg + 0.2 * (fg - bg)
    args = (jnp.asarray(gt), jnp.asarray(img))
    out = boundary_matte(*args, others=others, other_weights=weights, max_residual=0.05)
    assert np.all(np.asarray(out)[:, 11] == FG)
    alone = boundary_matte(*args, max_residual=0.05)
    np.testing.assert_array_equal(np.asarray(alone)[:, 11], gt[:, 11])


def test_matte_ignores_other_views_whose_two_sides_look_alike():
    gt, img, others, weights = _matte_with_others_scene()
    # One grey: each other view's α would be 0 and pull column 10 (α 0.8) to the background.
    flat = jnp.full_like(others, 0.5)
    out = boundary_matte(jnp.asarray(gt), img, others=flat, other_weights=weights)
    np.testing.assert_array_equal(np.asarray(out), np.asarray(boundary_matte(jnp.asarray(gt), img)))


def test_matte_takes_the_observed_background_for_its_own_colour_only():
    # Column 11 is background; its colour is 30 % foreground. An observed background far
    # beyond the background colour, away from the foreground, makes its own α 0.825 (it
    # joins the foreground alone); four other views that see it as pure background (α ≈ 0
    # with their window means) hold it back. Were the observed background taken for their
    # B too, their α would be 0.75 and it would join the foreground.
    gt, img = _edge_scene(10.3)
    fg, bg = img[0, 0], img[0, -1]
    own = img.copy()
    own[:, 11] = bg + 0.3 * (fg - bg)
    observed = jnp.asarray(np.broadcast_to(bg - 3.0 * (fg - bg), img.shape).copy())
    valid = jnp.zeros(gt.shape, bool).at[:, 11].set(True)
    d = jnp.asarray(gt)
    kw = {"background": observed, "background_valid": valid}
    alone = boundary_matte(d, jnp.asarray(own), **kw)
    assert np.all(np.asarray(alone)[:, 11] == FG)
    others = jnp.asarray(np.stack([img] * 4))
    weights = jnp.ones((4, *gt.shape), jnp.float32)
    out = boundary_matte(d, jnp.asarray(own), others=others, other_weights=weights, **kw)
    np.testing.assert_array_equal(np.asarray(out)[:, 11], gt[:, 11])


def _ramp_edge_scene(edge: float, slope: float, size: int = 24):
    """`_edge_scene` with a background whose colour changes linearly across the columns,
    ``slope`` of the foreground–background difference per pixel (zero at the edge): the
    mean of the window's background pixels, a pixel or more from the edge, is not the
    colour behind the edge pixel."""
    x = np.arange(size, dtype=np.float64)
    cover = np.clip(edge - (x - 0.5), 0.0, 1.0)
    fg_col, bg_col = np.array([0.9, 0.2, 0.1]), np.array([0.1, 0.3, 0.8])
    bg = bg_col + slope * (x - edge)[:, None] * (fg_col - bg_col)
    row = cover[:, None] * fg_col + (1 - cover[:, None]) * bg
    img = np.broadcast_to(row, (size, size, 3)).astype(np.float32)
    gt = np.broadcast_to(np.where(x < edge, FG, BG), (size, size)).astype(np.float32)
    return jnp.asarray(gt), jnp.asarray(img)


@pytest.mark.parametrize("transpose", [False, True])
@pytest.mark.parametrize("slope", [0.1, 0.15, -0.1, -0.15])
@pytest.mark.parametrize("edge", [10.1, 10.3, 10.45, 10.55, 10.7, 10.9])
def test_matte_background_fit_follows_a_colour_gradient(edge, slope, transpose):
    # The linear fit of the background side's colours, read at the pixel, is the colour
    # behind it: every pixel stays on its side of the ground truth (a vertical edge and,
    # transposed, a horizontal one).
    gt, img = _ramp_edge_scene(edge, slope)
    if transpose:
        gt, img = gt.T, jnp.swapaxes(img, 0, 1)
    out = jax.jit(boundary_matte, static_argnames="background_fit")(gt, img, background_fit=1e3)
    np.testing.assert_array_equal(np.asarray(out), np.asarray(gt))


def test_matte_background_mean_misses_a_colour_gradient():
    # The mean of the background side, 1.3 pixels from the edge pixel on average, is
    # brighter towards the foreground colour than the colour behind it: the pixel whose
    # centre the foreground covers (column 10, 60 % foreground) looks like background.
    gt, img = _ramp_edge_scene(10.1, 0.15)
    out = np.asarray(boundary_matte(gt, img))
    np.testing.assert_array_equal(out[:, 10], np.full(24, BG, np.float32))
    np.testing.assert_array_equal(np.delete(out, 10, axis=1), np.delete(np.asarray(gt), 10, 1))


def test_matte_fits_without_strength_are_the_mean():
    # A fit held back by a ridge of 1e9 is the mean up to rounding; 0 is the mean itself.
    rng = np.random.default_rng(4)
    gt, img = _ramp_edge_scene(10.45, 0.1)
    img = jnp.asarray(np.clip(np.asarray(img) + rng.normal(0, 0.05, img.shape), 0, 1))
    d = jnp.asarray(np.roll(np.asarray(gt), 1, axis=1))
    mean = np.asarray(boundary_matte(d, img))
    for kw in ({"foreground_fit": 1e-9}, {"background_fit": 1e-9}):
        np.testing.assert_array_equal(np.asarray(boundary_matte(d, img, **kw)), mean)
    # ... and a strong fit of either side changes decisions on this noisy ramp.
    for kw in ({"foreground_fit": 1e3}, {"background_fit": 1e3}):
        assert not np.array_equal(np.asarray(boundary_matte(d, img, **kw)), mean), kw


def test_matte_fits_reject_bad_strengths():
    gt, img = _ramp_edge_scene(10.3, 0.1)
    for kw in ({"foreground_fit": -1.0}, {"background_fit": float("inf")}):
        with pytest.raises(ValueError, match="_fit must be finite and >= 0"):
            boundary_matte(gt, img, **kw)
    with pytest.raises(ValueError, match="matte_view_foreground_fit"):
        SharpenConfig(matte_view_foreground_fit=-1.0)


def test_matte_near_tie_is_tested_on_the_combined_alpha():
    # Column 10 is half covered: with the pixels on the discontinuity weighted 0, the window
    # means are the two pure colours and its own α is 1/2, a near-tie that keeps its value
    # (were the tie broken, α ≤ 1/2 would keep it on the background side too: a map on the
    # foreground side shows it). Four other views that see it in the pure foreground colour
    # make the mean α 0.9, and it is decided.
    gt, img = _edge_scene(10.0)
    fg = img.copy()
    fg[:, 10] = img[:, 0]
    others = jnp.asarray(np.stack([fg] * 4))
    weights = jnp.ones((4, *gt.shape), jnp.float32)
    d = gt.copy()
    d[:, 10] = FG  # the map has column 10 on the foreground side
    bg_side = np.asarray(boundary_matte(jnp.asarray(gt), img, impure_weight=0.0))
    np.testing.assert_array_equal(bg_side[:, 10], gt[:, 10])
    alone = np.asarray(boundary_matte(jnp.asarray(d), img, impure_weight=0.0, snap=0.0))
    np.testing.assert_array_equal(alone[:, 10], d[:, 10])
    out = np.asarray(
        boundary_matte(
            jnp.asarray(gt), img, others=others, other_weights=weights, impure_weight=0.0
        )
    )
    np.testing.assert_allclose(out[:, 10], FG, atol=1e-5)


@pytest.mark.parametrize("edge", [0.7, 1.3, 1.6, 2.45, 21.55, 22.4, 23.3])
def test_matte_with_copies_of_its_own_view_is_the_matte_alone_at_the_frame_border(edge):
    # Other views identical to this one give every pixel its own α, including windows that
    # reach beyond the frame (whose border is replicated, for this view and the others).
    gt, img = _edge_scene(edge)
    d = jnp.asarray(np.roll(gt, 1, axis=1) if edge < 12 else np.roll(gt, -1, axis=1))
    others = jnp.asarray(np.stack([img] * 3))
    weights = jnp.ones((3, *gt.shape), jnp.float32)
    np.testing.assert_array_equal(
        np.asarray(boundary_matte(d, img, others=others, other_weights=weights)),
        np.asarray(boundary_matte(d, img)),
    )


def test_matte_ignores_other_views_weighted_zero_even_if_not_finite():
    # A view that weighs 0 (e.g. one without an image) adds nothing, NaN colours included.
    gt, img, others, weights = _matte_with_others_scene()
    bad = others.at[0].set(jnp.nan)
    zero_first = weights.at[0].set(0.0)
    d = jnp.asarray(gt)
    out = np.asarray(boundary_matte(d, img, others=bad, other_weights=zero_first))
    ref = np.asarray(boundary_matte(d, img, others=others[1:], other_weights=weights[1:]))
    assert np.all(np.isfinite(out))
    np.testing.assert_array_equal(out, ref)


@pytest.mark.parametrize("steps", [0, 4])
def test_views_matte_keeps_the_map_of_a_view_without_an_image(steps):
    # `_matte_views` runs each view's matte where the view holds an image (`map_where`); a
    # view missing from a partial grid keeps its map, the views with an image are matted
    # as one `boundary_matte` call each.
    from mvedge_jax.reconstruct import ReconstructConfig
    from mvedge_jax.reconstruct._reconstruct import _matte_views

    gt, img = _edge_scene(10.3)
    fattened = np.where(np.arange(24) < 12, FG, BG).astype(np.float32)  # column 11 is BG
    d = np.broadcast_to(fattened, (3, 3, 24, 24)).copy()
    views = np.broadcast_to(linear_to_srgb(img), (3, 3, 24, 24, 3)).copy()
    views[0, 2] = 0.0
    present = jnp.asarray(np.max(views, axis=(2, 3, 4)) > 0)
    config = ReconstructConfig(sharpen=SharpenConfig(matte_view_steps=steps))
    guides = colour_guide(jnp.asarray(views), config.colour_space)
    out = np.asarray(_matte_views(jnp.asarray(d), jnp.asarray(views), guides, present, config))
    np.testing.assert_array_equal(out[0, 2], d[0, 2])
    np.testing.assert_array_equal(out[1, 1], d[1, 1])  # the centre view is not matted here
    guide = colour_guide(jnp.asarray(views[0, 0]), config.sharpen.matte_colour)
    alone = boundary_matte(
        d[0, 0],
        guide,
        jump=config.sharpen.matte_view_jump,
        snap=config.sharpen.matte_view_snap,
        min_separation=config.sharpen.matte_min_separation,
        impure_weight=config.sharpen.matte_impure_weight,
        foreground_fit=config.sharpen.matte_view_foreground_fit,
    )
    assert not np.array_equal(out[0, 0], d[0, 0])
    if steps == 0:
        np.testing.assert_array_equal(out[0, 0], np.asarray(alone))


NEAR, WALL, FLOOR = 2.8, -3.4, -1.5
NEAR_RGB, WALL_RGB, FLOOR_RGB = (0.05, 0.35, 0.1), (0.05, 0.05, 0.6), (0.2, 0.9, 0.2)


def _strip_scene(strip_rgb, strip_value=WALL, size: int = 20):
    """A near object (rows 0–9) above a one-pixel strip (row 10) above a floor (rows 11–):
    the strip is the far wall seen between them (three surfaces in every window that holds
    it). Returns the map (the strip at ``strip_value``) and the colours in linear light."""
    rows = np.arange(size)
    d = np.where(rows < 10, NEAR, np.where(rows == 10, strip_value, FLOOR)).astype(np.float32)
    d = np.broadcast_to(d[:, None], (size, size)).copy()
    rgb = np.where(
        (rows < 10)[:, None], NEAR_RGB, np.where((rows == 10)[:, None], strip_rgb, FLOOR_RGB)
    )
    img = np.broadcast_to(rgb[:, None, :], (size, size, 3)).astype(np.float32)
    return d, img


def _views_matte(d, img, split):
    # The views' matte settings: every decided pixel takes its side's mean (snap 0).
    return np.asarray(
        boundary_matte(jnp.asarray(d), jnp.asarray(img), jump=0.5, snap=0.0, split_background=split)
    )


def test_matte_split_keeps_a_strip_of_far_wall_between_two_nearer_surfaces():
    # The wall's own colour (not a mixture of the object's and the floor's): the whole
    # background side (wall and floor) has a mean colour and disparity of neither.
    d, img = _strip_scene(WALL_RGB)
    whole = _views_matte(d, img, split=False)
    split = _views_matte(d, img, split=True)
    np.testing.assert_allclose(split, d, atol=1e-5)
    assert np.abs(whole - d).max() > 0.5  # the strip or the floor next to it is moved


def test_matte_split_ignores_a_strip_whose_colour_mixes_its_neighbours():
    # A run of wrong far values along the object's lower edge, with the colour of a pixel
    # mixing the object and the floor: not a third surface, so the whole side is used.
    mixed = tuple(0.5 * (a + b) for a, b in zip(NEAR_RGB, FLOOR_RGB, strict=True))
    d, img = _strip_scene(mixed)
    # Equal up to rounding: the whole side's sums are the two parts' sums added.
    np.testing.assert_allclose(_views_matte(d, img, True), _views_matte(d, img, False), atol=1e-5)


@pytest.mark.parametrize("edge", [10.3, 10.7])
def test_matte_split_of_two_surfaces_is_the_matte(edge):
    gt, img = _edge_scene(edge)
    d = np.roll(gt, 1, axis=1)
    d[:, :2], d[:, -2:] = FG, BG
    np.testing.assert_array_equal(_views_matte(d, img, True), _views_matte(d, img, False))


def test_matte_split_needs_the_mean_colours():
    gt, img = _edge_scene(10.3)
    with pytest.raises(ValueError, match="background_fit"):
        boundary_matte(jnp.asarray(gt), jnp.asarray(img), split_background=True, background_fit=1.0)
    with pytest.raises(ValueError, match="matte_view_background_fit"):
        SharpenConfig(matte_view_background_fit=1.0)  # matte_view_split is the default
    SharpenConfig(matte_view_background_fit=1.0, matte_view_split=False)


def test_views_matte_splits_the_background_when_configured():
    # `SharpenConfig.matte_view_split` reaches the views' matte (and only it: the centre
    # view is not matted there).
    from mvedge_jax.reconstruct import ReconstructConfig
    from mvedge_jax.reconstruct._reconstruct import _matte_views

    d, img = _strip_scene(WALL_RGB)
    maps = np.broadcast_to(d, (3, 3, *d.shape)).copy()
    views = np.broadcast_to(linear_to_srgb(img), (3, 3, *img.shape)).copy()
    present = jnp.ones((3, 3), bool)

    def run(split):
        config = ReconstructConfig(
            sharpen=SharpenConfig(matte_view_steps=0, matte_view_split=split)
        )
        guides = colour_guide(jnp.asarray(views), config.colour_space)
        return np.asarray(
            _matte_views(jnp.asarray(maps), jnp.asarray(views), guides, present, config)
        )

    split, whole = run(True), run(False)
    np.testing.assert_allclose(split[0, 0], d, atol=1e-5)
    assert np.abs(whole[0, 0] - d).max() > 0.5
    np.testing.assert_array_equal(split[1, 1], d)


def test_matte_split_gradient_matches_finite_differences():
    # Piecewise a weighted mean of the input map: away from a change of decision, the
    # gradient with respect to the map is the weights' (the chosen part's mean included).
    from jax.test_util import check_grads

    d, img = _strip_scene(WALL_RGB, size=12)
    d = d + np.random.default_rng(0).uniform(-0.05, 0.05, d.shape).astype(np.float32)
    guide = jnp.asarray(img)

    def matte(x):
        return boundary_matte(x, guide, jump=0.5, snap=0.0, split_background=True)

    assert np.abs(np.asarray(matte(jnp.asarray(d))) - d).max() > 0.01  # the means are taken
    check_grads(matte, (jnp.asarray(d),), order=1, modes=["rev"], eps=1e-3, atol=2e-2, rtol=2e-2)


def test_split_candidates_list_the_background_pixels_of_three_surface_windows():
    d, _ = _strip_scene(WALL_RGB)
    H, W = d.shape
    idx = np.asarray(split_candidates(jnp.asarray(d), jump=0.5, capacity=H * W))
    listed = np.zeros(H * W, bool)
    listed[idx[idx < H * W]] = True
    listed = listed.reshape(H, W)
    # The strip and the floor row whose 5×5 windows reach the object above and a pure floor
    # pixel (rows 10–11); not the object, nor the floor below (row 12's window holds the
    # strip and the floor only, and the floor is its foreground side).
    np.testing.assert_array_equal(np.nonzero(listed.any(axis=1))[0], [10, 11])
    assert listed[10:12].all()
    # Two surfaces only: none. A short list keeps the first pixels in row-major order.
    gt, _ = _edge_scene(10.3)
    assert (np.asarray(split_candidates(jnp.asarray(gt), jump=0.5)) == gt.size).all()
    short = np.asarray(split_candidates(jnp.asarray(d), jump=0.5, capacity=5))
    np.testing.assert_array_equal(short, idx[:5])
    # Under vmap (a select instead of the cond) the lists are the same.
    flipped = d[::-1].copy()  # the same scene upside down: the floor above the object
    both = jax.vmap(lambda m: split_candidates(m, jump=0.5, capacity=H * W))(
        jnp.stack([d, flipped])
    )
    np.testing.assert_array_equal(np.asarray(both[0]), idx)
    np.testing.assert_array_equal(
        np.asarray(both[1]),
        np.asarray(split_candidates(jnp.asarray(flipped), jump=0.5, capacity=H * W)),
    )
    with pytest.raises(ValueError, match="shape"):
        split_candidates(jnp.zeros((2, 3, 4)))
    with pytest.raises(ValueError, match="capacity"):
        split_candidates(jnp.asarray(d), capacity=0)


def test_matte_split_at_listed_pixels_only():
    # Given an empty list, the split changes nothing; given the candidates, it is the
    # default's.
    d, img = _strip_scene(WALL_RGB)
    kw = dict(jump=0.5, snap=0.0, split_background=True)
    none = jnp.full((8,), d.size, jnp.int32)
    np.testing.assert_allclose(
        np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(img), split_pixels=none, **kw)),
        _views_matte(d, img, False),
        atol=1e-5,
    )
    listed = split_candidates(jnp.asarray(d), jump=0.5)
    np.testing.assert_array_equal(
        np.asarray(boundary_matte(jnp.asarray(d), jnp.asarray(img), split_pixels=listed, **kw)),
        _views_matte(d, img, True),
    )
