"""Synthetic scenes: determinism, ranges, exact per-view GT, photometric consistency."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

from mvedge_jax.lightfield import (
    LightField,
    backward_warp,
    forward_project,
    linear_to_srgb,
    srgb_to_linear,
)
from mvedge_jax.synthetic import (
    DISC,
    RECT,
    WHOLE,
    Surface,
    default_light_field,
    make_scene,
    render_surfaces,
)


@pytest.fixture(scope="module")
def scenes() -> list[LightField]:
    return [
        default_light_field(),
        make_scene(0),
        make_scene(2, grid=(7, 9), size=(96, 128), disparity_range=(-1.0, 2.5)),
    ]


def _edge_band(g: np.ndarray, thresh=0.05, width=1) -> np.ndarray:
    """Pixels within ``width`` px of a depth discontinuity of ``g``."""
    jump = np.zeros(g.shape, bool)
    dx = np.abs(np.diff(g, axis=1)) > thresh
    dy = np.abs(np.diff(g, axis=0)) > thresh
    jump[:, 1:] |= dx
    jump[:, :-1] |= dx
    jump[1:] |= dy
    jump[:-1] |= dy
    return ndimage.binary_dilation(jump, iterations=width) if width > 0 else jump


def _visible_in_centre(g_view, centre_gt, off, tol=0.05):
    """View pixels whose GT surface point is inside the centre view and not occluded there."""
    H, W = g_view.shape
    ys, xs = np.mgrid[0:H, 0:W]
    xc = xs + off[1] * g_view  # view(x') sees centre(x' + dc d, y' + dr d)
    yc = ys + off[0] * g_view
    inside = (xc >= 0) & (xc <= W - 1) & (yc >= 0) & (yc <= H - 1)
    xi = np.clip(np.floor(xc + 0.5), 0, W - 1).astype(int)
    yi = np.clip(np.floor(yc + 0.5), 0, H - 1).astype(int)
    return inside & (centre_gt[yi, xi] <= g_view + tol)


def test_shapes_metadata_and_range(scenes):
    for lf, grid, size, rng in zip(
        scenes,
        [(9, 9), (9, 9), (7, 9)],
        [(160, 160), (128, 128), (96, 128)],
        [(-1.5, 1.5), (-2.0, 2.0), (-1.0, 2.5)],
        strict=True,
    ):
        assert lf.views.shape == (*grid, *size, 3) and lf.views.dtype == jnp.float32
        assert lf.gt_disparity.shape == (*grid, *size) and bool(lf.gt_mask.all())
        assert bool(lf.view_mask.all()) and lf.source is None
        assert lf.disparity_range == rng
        g = np.asarray(lf.gt_disparity)
        assert rng[0] <= g.min() and g.max() <= rng[1], (lf.name, g.min(), g.max())
        assert g.max() - g.min() > 0.5 * (rng[1] - rng[0])  # uses a good part of the range
        v = np.asarray(lf.views)
        assert 0.0 <= v.min() and v.max() <= 1.0 and v.std() > 0.1


def test_default_light_field_is_a_good_demo(scenes):
    lf = scenes[0]
    assert lf.name == "synthetic-default" and default_light_field() is lf  # cached
    g = np.asarray(lf.centre_gt)
    levels = np.unique(np.round(g, 1))
    assert len(levels) >= 6  # several depths incl. slanted surfaces
    assert -1.5 <= g.min() < -1.0 and 1.0 < g.max() <= 1.5
    assert 0.02 < _edge_band(g, 0.1, 0).mean() < 0.2  # occlusion edges, not everywhere
    # colour edges exist inside surfaces (stripes/checkers) → EPI edges
    grad = np.abs(np.diff(np.asarray(lf.centre_view), axis=1)).max(-1)
    assert (grad[~_edge_band(g)[:, 1:]] > 0.2).mean() > 0.01


def test_deterministic_per_seed():
    a = make_scene(5, size=(32, 48), grid=(3, 5))
    b = make_scene(5, size=(32, 48), grid=(3, 5))
    c = make_scene(6, size=(32, 48), grid=(3, 5))
    np.testing.assert_array_equal(a.views, b.views)
    np.testing.assert_array_equal(a.gt_disparity, b.gt_disparity)
    assert not np.array_equal(np.asarray(a.views), np.asarray(c.views))


def test_gt_is_exact_under_forward_projection(scenes):
    """Forward-projecting the centre GT into each view reproduces that view's GT wherever the
    view's surface point is visible in the centre view (away from 1-px depth-edge bands, where
    nearest-pixel rounding decides fg/bg), and leaves holes where it is not."""
    for lf in scenes:
        gt = np.asarray(lf.gt_disparity)
        U, V, H, W = gt.shape
        rc, cc = U // 2, V // 2
        dr, dc = lf.view_offsets()
        offs = jnp.stack([dr.ravel(), dc.ravel()], -1)
        P, Vd = jax.jit(jax.vmap(forward_project, in_axes=(None, 0)))(gt[rc, cc], offs)
        P = np.asarray(P).reshape(U, V, H, W)
        Vd = np.asarray(Vd).reshape(U, V, H, W)
        worst = {"hole_visible": 0.0, "valid_disoccluded": 0.0, "value": 0.0}
        for r in range(U):
            for c in range(V):
                g, p, v = gt[r, c], P[r, c], Vd[r, c]
                off = (r - rc, c - cc)
                interior = ~_edge_band(g)
                vis = _visible_in_centre(g, gt[rc, cc], off) & interior
                # allowed error: nearest-pixel rounding on a slanted plane (half a pixel of slope)
                # (|∂x d| + |∂y d|: half a pixel in x and in y of source position error)
                sx = np.zeros_like(g)
                sy = np.zeros_like(g)
                sx[:, :-1] = np.abs(np.diff(g, axis=1))
                sy[:-1] = np.abs(np.diff(g, axis=0))
                slope = ndimage.maximum_filter(
                    np.where(interior, sx, 0), 3
                ) + ndimage.maximum_filter(np.where(interior, sy, 0), 3)
                bad = vis & v & (np.abs(p - g) > 0.6 * slope + 1e-4)
                assert not bad.any(), (lf.name, r, c, np.abs(p - g)[bad].max())
                worst["value"] = max(worst["value"], float(np.abs(p - g)[vis & v].max()))
                worst["hole_visible"] = max(worst["hole_visible"], float((vis & ~v).mean()))
                # disoccluded (inside the centre's field of view but hidden there) → holes
                xc = np.mgrid[0:H, 0:W][1] + off[1] * g
                yc = np.mgrid[0:H, 0:W][0] + off[0] * g
                inside = (xc >= 0) & (xc <= W - 1) & (yc >= 0) & (yc <= H - 1)
                disocc = inside & interior & ~_visible_in_centre(g, gt[rc, cc], off)
                worst["valid_disoccluded"] = max(
                    worst["valid_disoccluded"], float((disocc & v).mean())
                )
        print(lf.name, {k: round(x, 5) for k, x in worst.items()})
        assert worst["hole_visible"] < 1e-3  # visible points are (almost) never holes
        assert worst["valid_disoccluded"] < 5e-3
        assert worst["value"] < 0.01


def test_every_view_is_photometrically_consistent_with_its_own_gt(scenes):
    """Warping the centre view into each view with that view's GT reproduces the view (on
    pixels visible in the centre, away from depth edges); zero or negated disparity do not."""
    warp = jax.jit(jax.vmap(backward_warp, in_axes=(None, 0, 0)))
    for lf in scenes:
        U, V, H, W = lf.gt_disparity.shape
        dr, dc = lf.view_offsets()
        offs = jnp.stack([dr.ravel(), dc.ravel()], -1)
        g = lf.gt_disparity.reshape(-1, H, W)
        views = np.asarray(lf.views.reshape(-1, H, W, 3))
        cg = np.asarray(lf.centre_gt)
        # view(x') = centre(x' + dc d): the centre sits at offset -(dr, dc) from the view
        errs = {
            k: np.asarray(jnp.abs(warp(lf.centre_view, s * g, -offs) - views).mean(-1))
            for k, s in (("gt", 1.0), ("zero", 0.0), ("neg", -1.0))
        }
        rows = []
        for i in range(U * V):
            off = np.asarray(offs[i])
            if not off.any():
                continue
            gi = np.asarray(g[i])
            m = _visible_in_centre(gi, cg, off) & ~_edge_band(gi, width=2)
            e = {k: float(v[i][m].mean()) for k, v in errs.items()}
            rows.append((e["gt"], e["zero"] / e["gt"], e["neg"] / e["gt"]))
        rows = np.array(rows)
        print(
            lf.name,
            f"max gt err {rows[:, 0].max():.4f}, min ratio zero {rows[:, 1].min():.2f}, "
            f"neg {rows[:, 2].min():.2f}",
        )
        assert rows[:, 0].max() < 0.015  # bilinear-interpolation floor on crisp stripes
        # (zero disparity is closer to right when most of the scene is near d = 0, as in the
        # third scene, whose range is (-1, 2.5))
        assert rows[:, 1].min() > 2.5
        assert rows[:, 2].min() > 4.0


def test_render_surfaces_by_hand():
    """A fronto-parallel disc over a background: exact disc edges and positions in a side view."""
    surfaces = [
        Surface(plane=(0.0, 0.0, 0.0), kind=WHOLE, base=(0.2, 0.2, 0.2)),
        Surface(
            plane=(2.0, 0.0, 0.0),
            kind=DISC,
            centre=(0.0, 0.0),
            half_size=(5.0, 5.0),
            base=(0.9, 0.9, 0.9),
        ),
        Surface(
            plane=(1.0, 0.0, 0.05),
            kind=RECT,
            centre=(-10.0, 0.0),
            half_size=(2.0, 8.0),
            base=(0.5, 0.1, 0.1),
        ),
    ]
    lf = render_surfaces(surfaces, grid=(3, 3), size=(31, 41), supersample=1)
    g = np.asarray(lf.gt_disparity)
    # centre view: disc of radius 5 around pixel (15, 20)
    assert g[1, 1, 15, 20] == 2.0 and g[1, 1, 15, 25] == 2.0 and g[1, 1, 15, 26] == 0.0
    # right view (dc = +1): the disc moves by -2 px: centre at x = 18
    assert g[1, 2, 15, 23] == 2.0 and g[1, 2, 15, 24] == 0.0 and g[1, 2, 15, 13] == 2.0
    # slanted bar: d = 1 + 0.05 Y in the centre view; view (0, 1) (dr = -1):
    # d = (1 + 0.05 Y') / (1 + 0.05)
    np.testing.assert_allclose(g[1, 1, 10, 10], 1 + 0.05 * (10 - 15), rtol=1e-6)
    np.testing.assert_allclose(g[0, 1, 10, 10], (1 + 0.05 * (10 - 15)) / 1.05, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(lf.views[1, 1, 15, 20]), 0.9, atol=1e-6)


def test_occlusion_edges_mix_in_linear_light():
    """A pixel half covered by a near rectangle is the mean of the two colours in linear
    light (as a camera integrates light), encoded as sRGB, not the mean of the encoded
    values."""
    fg, bg = 0.9, 0.1
    surfaces = [
        Surface(plane=(0.0, 0.0, 0.0), kind=WHOLE, base=(bg, bg, bg)),
        # Left edge at X = 0: through the centres of column 10 (W = 21).
        Surface(
            plane=(1.0, 0.0, 0.0),
            kind=RECT,
            centre=(5.0, 0.0),
            half_size=(5.0, 20.0),
            base=(fg, fg, fg),
        ),
    ]
    lf = render_surfaces(surfaces, grid=(3, 3), size=(9, 21), supersample=2)
    centre = np.asarray(lf.views[1, 1])
    lin = 0.5 * (np.asarray(srgb_to_linear(fg)) + np.asarray(srgb_to_linear(bg)))
    np.testing.assert_allclose(centre[4, 10], float(linear_to_srgb(lin)), atol=1e-5)
    assert abs(float(centre[4, 10, 0]) - 0.5 * (fg + bg)) > 0.1
    np.testing.assert_allclose(centre[4, 9], bg, atol=1e-5)
    np.testing.assert_allclose(centre[4, 11], fg, atol=1e-5)


def test_bad_inputs():
    with pytest.raises(ValueError, match="d_min < d_max"):
        make_scene(0, disparity_range=(1.0, -1.0))
    with pytest.raises(ValueError, match="n_objects"):
        make_scene(0, n_objects=-1)
    with pytest.raises(ValueError, match="at least one"):
        render_surfaces([])
    with pytest.raises(ValueError, match="grid"):
        render_surfaces([Surface(plane=(0, 0, 0))], grid=(2, 9))
    with pytest.raises(ValueError, match="supersample"):
        render_surfaces([Surface(plane=(0, 0, 0))], supersample=0)
    with pytest.raises(ValueError, match="too steep"):
        render_surfaces([Surface(plane=(0.0, 0.3, 0.0))], grid=(9, 9), size=(8, 8))
    with pytest.raises(ValueError, match="covered by no surface"):
        render_surfaces([Surface(plane=(0, 0, 0), kind=DISC, half_size=(2.0, 2.0))], size=(16, 16))
