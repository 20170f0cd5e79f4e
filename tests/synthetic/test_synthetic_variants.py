"""Synthetic variant scenes: each has the difficulty it names, exact GT, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from mvedge_jax.synthetic import VARIANTS, variant_scene, variant_scenes

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
