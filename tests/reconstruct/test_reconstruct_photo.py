"""Photo-consistent snapping of depth boundaries."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.ndimage import grey_dilation

from mvedge_jax.reconstruct import (
    ReconstructConfig,
    photo_cost,
    photo_refine,
    photo_select,
    select_centre,
)


def _cross(lf):
    U, V = lf.grid
    rc, cc = U // 2, V // 2
    pos = [(rc, c) for c in range(V) if c != cc] + [(r, cc) for r in range(U) if r != rc]
    views = jnp.stack([lf.views[r, c] for r, c in pos])
    offsets = jnp.asarray([(r - rc, c - cc) for r, c in pos], jnp.float32)
    return views, offsets


def test_photo_cost_is_lowest_at_the_truth(small_scene):
    lf, _, _ = small_scene
    views, offsets = _cross(lf)
    gt = lf.centre_gt
    costs = [
        float(jnp.mean(photo_cost(gt + delta, lf.centre_view, views, offsets)))
        for delta in (-0.3, 0.0, 0.3)
    ]
    assert costs[1] < 0.5 * min(costs[0], costs[2]), costs


def test_photo_refine_removes_a_foreground_halo(small_scene):
    lf, _, _ = small_scene
    views, offsets = _cross(lf)
    gt = np.asarray(lf.centre_gt)
    halo = grey_dilation(gt, size=(5, 5))  # foreground fattened by 2 px (edge fattening)
    f = jax.jit(
        lambda d: photo_refine(d, lf.centre_view, views, offsets, radius=3, jump=0.2, iterations=4)
    )
    out = np.asarray(f(jnp.asarray(halo)))
    bad_in = np.mean(np.abs(halo - gt) > 0.07)
    bad_out = np.mean(np.abs(out - gt) > 0.07)
    assert bad_in > 0.05
    assert bad_out < 0.5 * bad_in, (bad_in, bad_out)
    # Away from discontinuities nothing changes.
    flat = grey_dilation(halo, size=(31, 31)) + grey_dilation(-halo, size=(31, 31)) < 0.2
    assert flat.sum() > 100
    np.testing.assert_array_equal(out[flat], halo[flat])


def test_photo_select_takes_the_better_map_and_keeps_fine_values(small_scene):
    """A candidate that fixes a fattened boundary but is noisy at the 0.01 level elsewhere:
    the merge takes its boundary fix and keeps the incumbent's fine values."""
    lf, _, _ = small_scene
    views, offsets = _cross(lf)
    gt = np.asarray(lf.centre_gt)
    halo = grey_dilation(gt, size=(5, 5))  # incumbent: exact except a 2 px foreground halo
    rng = np.random.default_rng(0)
    candidate = gt + rng.uniform(-0.015, 0.015, gt.shape).astype(np.float32)
    f = jax.jit(lambda a, b: photo_select(a, b, lf.centre_view, views, offsets, min_change=0.02))
    out, took = (np.asarray(v) for v in f(jnp.asarray(halo), jnp.asarray(candidate)))
    wrong = np.abs(halo - gt) > 0.07
    assert wrong.mean() > 0.05
    # The halo is (mostly) replaced by the candidate ...
    assert np.mean(np.abs(out - gt)[wrong] > 0.07) < 0.15, np.mean(took[wrong])  # 0.07
    # ... and nowhere else does the candidate's noise come in (|difference| <= min_change).
    small = np.abs(candidate - halo) <= 0.02
    assert small.sum() > 0.5 * gt.size
    np.testing.assert_array_equal(out[small], halo[small])
    assert not took[small].any()
    np.testing.assert_array_equal(out[took], candidate[took])


def test_photo_select_keeps_a_correct_incumbent(small_scene):
    lf, _, _ = small_scene
    views, offsets = _cross(lf)
    gt = np.asarray(lf.centre_gt)
    halo = grey_dilation(gt, size=(5, 5))
    out, took = photo_select(jnp.asarray(gt), jnp.asarray(halo), lf.centre_view, views, offsets)
    wrong = np.abs(halo - gt) > 0.07
    assert np.mean(np.asarray(took)[wrong]) < 0.15  # measured 0.07
    assert np.mean(np.abs(np.asarray(out) - gt) > 0.07) < 0.15 * np.mean(wrong)


def test_photo_select_bad_input(small_scene):
    lf, _, _ = small_scene
    views, offsets = _cross(lf)
    gt = lf.centre_gt
    with pytest.raises(ValueError, match="same shape"):
        photo_select(gt, gt[:-1], lf.centre_view, views, offsets)


def test_select_centre_matches_photo_select_with_the_cross_hair(small_scene):
    lf, _, _ = small_scene
    views, offsets = _cross(lf)
    gt = jnp.asarray(lf.centre_gt)
    halo = jnp.asarray(grey_dilation(np.asarray(gt), size=(5, 5)))
    cfg = ReconstructConfig(select_min_change=0.05, select_aggregate=2)
    a, ta = select_centre(lf.views, halo, gt, cfg)
    b, tb = photo_select(halo, gt, lf.centre_view, views, offsets, min_change=0.05, aggregate=2)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-6)
    assert np.mean(np.asarray(ta) == np.asarray(tb)) > 0.999
    with pytest.raises(ValueError, match="centre_disparity must have shape"):
        select_centre(lf.views, halo, gt[:, :-1], cfg)
    with pytest.raises(ValueError, match="select_aggregate"):
        ReconstructConfig(select_aggregate=-1)
    with pytest.raises(ValueError, match="select_min_change"):
        ReconstructConfig(select_min_change=-0.1)
