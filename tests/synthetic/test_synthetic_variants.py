"""Synthetic variant scenes: each has the difficulty it names, exact GT, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from mvedge_jax.lightfield import srgb_to_linear
from mvedge_jax.synthetic import (
    GLOSS_NOISE,
    N_SHADE,
    RECT,
    VARIANTS,
    WHOLE,
    Surface,
    render_coverage,
    render_surfaces,
    variant_scene,
    variant_scenes,
    variant_surfaces,
)

SMALL = {"grid": (3, 3), "size": (64, 64), "supersample": 1}


@pytest.fixture(scope="module")
def scenes():
    return variant_scenes(**SMALL)


def test_shapes_names_and_determinism(scenes):
    assert tuple(scenes) == VARIANTS
    for kind, lf in scenes.items():
        assert lf.name == f"synthetic-{kind}"
        assert lf.views.shape == (3, 3, 64, 64, 3)
        assert lf.gt_disparity.shape == (3, 3, 64, 64)
        assert bool(np.asarray(lf.gt_mask).all())
        assert np.isfinite(np.asarray(lf.gt_disparity)).all()
    again = variant_scene("slanted", **SMALL)
    np.testing.assert_array_equal(np.asarray(again.views), np.asarray(scenes["slanted"].views))
    other = variant_scene("slanted", seed=1, **SMALL)
    assert not np.array_equal(np.asarray(other.views), np.asarray(again.views))


def _flat_colour(img: np.ndarray) -> np.ndarray:
    """Pixels whose 3×3 neighbourhood has one colour."""
    rng = ndimage.maximum_filter(img, size=(3, 3, 1)) - ndimage.minimum_filter(img, size=(3, 3, 1))
    return rng.max(axis=-1) < 1e-5


def test_textureless_has_uniform_regions_over_varying_depth(scenes):
    lf = scenes["textureless"]
    img = np.asarray(lf.views[1, 1])
    gt = np.asarray(lf.gt_disparity[1, 1])
    flat = _flat_colour(img)
    assert flat.mean() > 0.25
    # the uniform floor is slanted: depth varies where colour does not
    assert np.ptp(gt[flat]) > 0.3
    # the other variants are textured almost everywhere
    assert _flat_colour(np.asarray(scenes["slanted"].views[1, 1])).mean() < 0.05


def test_slanted_has_depth_gradient_almost_everywhere(scenes):
    gt = np.asarray(scenes["slanted"].gt_disparity[1, 1])
    gy, gx = np.gradient(gt)
    assert (np.hypot(gx, gy) > 0.003).mean() > 0.95
    assert np.hypot(gx, gy)[np.hypot(gx, gy) < 0.1].max() > 0.03  # steep planes too


def test_thin_structures_are_a_few_pixels_wide(scenes):
    gt = np.asarray(scenes["thin"].gt_disparity[1, 1])
    bars = gt > 0.0  # the bars are nearer than the board (-0.5) and the wall (-1.2)
    assert bars.sum() > 100
    # a 6-pixel opening removes them but where two bars cross: they are at most 5 px wide
    assert ndimage.binary_opening(bars, np.ones((6, 6), bool)).sum() < 0.1 * bars.sum()
    assert ndimage.binary_opening(gt > -1.0, np.ones((6, 6), bool)).sum() > 300  # the board


def test_wide_range(scenes):
    lf = scenes["wide"]
    gt = np.asarray(lf.gt_disparity)
    assert lf.disparity_range == (-4.0, 4.0)
    assert gt.min() >= -4.0 and gt.max() <= 4.0
    assert np.abs(gt).max() > 2.5 and np.ptp(gt) > 4.0


def test_unknown_variant():
    with pytest.raises(ValueError, match="unknown synthetic variant 'foggy'"):
        variant_scene("foggy")


def _two_flat_surfaces():
    """A flat dark background and a flat bright band (a rotated rectangle much longer than
    the views): two straight edges, no corner in view, crossing the pixels of every view at
    varying sub-pixel positions (disparity 0.37 against −0.5)."""
    back = Surface(plane=(-0.5, 0.0, 0.0), kind=WHOLE, base=(0.1, 0.2, 0.3))
    front = Surface(
        plane=(0.37, 0.0, 0.0),
        kind=RECT,
        centre=(0.3, -0.2),
        half_size=(7.3, 1000.0),
        angle=0.3,
        base=(0.9, 0.7, 0.5),
    )
    return [back, front]


@pytest.mark.parametrize("supersample", [2, 3, 5])
def test_coverage_is_the_colour_mixture_of_the_ground_truth_surface(supersample):
    """Two flat surfaces: each pixel's linear colour is ``c A + (1 − c) B`` with ``c`` the
    coverage of its ground-truth surface; an odd supersampling gives the ground-truth surface
    most of every pixel's colour at these straight boundaries, an even one leaves pixels mixed
    exactly half and half."""
    surfaces = _two_flat_surfaces()
    kw = {"grid": (3, 3), "size": (24, 32), "supersample": supersample}
    lf = render_surfaces(surfaces, **kw)
    cov = np.asarray(render_coverage(surfaces, **kw))
    assert cov.shape == (3, 3, 24, 32) and cov.dtype == np.float32
    front = np.asarray(lf.gt_disparity) > 0
    lin = np.asarray(srgb_to_linear(lf.views))
    a = np.asarray(srgb_to_linear(np.array([0.9, 0.7, 0.5])))
    b = np.asarray(srgb_to_linear(np.array([0.1, 0.2, 0.3])))
    own, other = np.where(front[..., None], a, b), np.where(front[..., None], b, a)
    expected = cov[..., None] * own + (1 - cov[..., None]) * other
    np.testing.assert_allclose(lin, expected, atol=2e-3)
    mixed = cov < 1
    assert mixed.sum() > 100 and front.sum() > 100
    if supersample % 2:
        assert cov.min() > 0.5
    else:
        assert np.sum(cov == 0.5) > 0.2 * mixed.sum()


def test_variant_surfaces_render_the_variant_scene():
    for kind in ("thin", "wide"):
        kw = {"grid": (3, 3), "size": (48, 48)}
        lf = variant_scene(kind, seed=2, **kw)
        again = render_surfaces(variant_surfaces(kind, seed=2, **kw), supersample=3, **kw)
        np.testing.assert_array_equal(np.asarray(lf.views), np.asarray(again.views))
        np.testing.assert_array_equal(np.asarray(lf.gt_disparity), np.asarray(again.gt_disparity))
    with pytest.raises(ValueError, match="unknown synthetic variant"):
        variant_surfaces("foggy")


def test_render_coverage_rejects_bad_input():
    with pytest.raises(ValueError, match="supersample must be >= 1"):
        render_coverage(_two_flat_surfaces(), supersample=0)
    with pytest.raises(ValueError, match="at least one surface"):
        render_coverage([])
    with pytest.raises(ValueError, match="grid must be at least"):
        render_coverage(_two_flat_surfaces(), grid=(2, 9))


def test_surface_shading_changes_colour_with_the_view():
    """A flat grey surface whose shading sinusoid is constant (k = 0, phase π/2): the view at
    ``(dr, dc)`` is brighter by ``amp_dc dc + amp_dr dr`` in every channel; the centre view
    and the ground truth are unaffected."""
    shading = np.zeros((N_SHADE, 5))
    shading[0] = (0.0, 0.0, np.pi / 2, 0.01, -0.02)
    lit = Surface(plane=(0.5, 0.0, 0.0), kind=WHOLE, base=(0.5, 0.5, 0.5), shading=shading)
    plain = Surface(plane=(0.5, 0.0, 0.0), kind=WHOLE, base=(0.5, 0.5, 0.5))
    a = render_surfaces([lit], grid=(3, 5), size=(8, 8), supersample=1)
    b = render_surfaces([plain], grid=(3, 5), size=(8, 8), supersample=1)
    np.testing.assert_array_equal(np.asarray(a.gt_disparity), np.asarray(b.gt_disparity))
    views = np.asarray(a.views)
    for r in range(3):
        for c in range(5):
            expected = 0.5 + 0.01 * (c - 2) - 0.02 * (r - 1)
            np.testing.assert_allclose(views[r, c], expected, atol=2e-5)


def test_glossy_has_faint_texture_view_dependent_shading_and_noise():
    """The glossy variant's photometry as measured on HCI antinous: on pixels away from depth
    edges, the difference of a view to the centre view (warped with the ground truth) has a
    smooth part that grows with the view distance and a noise-like rest of about
    ``GLOSS_NOISE · √2 · 0.8``; the texture is faint."""
    lf = variant_scene("glossy", grid=(9, 9), size=(64, 64), supersample=1)
    views = np.asarray(lf.views, np.float64)
    gt = np.asarray(lf.gt_disparity[4, 4], np.float64)
    centre = views[4, 4]
    grad = np.hypot(*np.gradient(centre.mean(-1)))
    assert np.median(grad) < 0.006
    keep = ndimage.maximum_filter(np.hypot(*np.gradient(gt)), 7) < 0.05
    keep[:8], keep[-8:], keep[:, :8], keep[:, -8:] = False, False, False, False
    y, x = np.mgrid[:64, :64].astype(np.float64)
    smooth, rest = {}, {}
    for u in (1, 4):
        warped = ndimage.map_coordinates(views[4, 4 + u].mean(-1), [y, x - u * gt], order=1)
        diff = np.where(keep, warped - centre.mean(-1), 0.0)
        w = ndimage.gaussian_filter(keep.astype(float), 4)
        low = ndimage.gaussian_filter(diff, 4) / np.maximum(w, 1e-6)
        smooth[u] = np.abs(low[keep]).mean()
        rest[u] = np.abs((diff - low)[keep]).mean()
    assert smooth[4] > 2.5 * smooth[1], smooth
    assert 0.3 * GLOSS_NOISE < rest[1] < 2.0 * GLOSS_NOISE, rest
