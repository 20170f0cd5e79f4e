"""Losses of eqs 7.15–7.16 and Sec. 7.2.3: occlusion masks, warping error, SSIM, supervision."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.diff import (
    LossConfig,
    edge_aware_smoothness,
    occlusion_mask,
    photometric_terms,
    self_supervised_loss,
    ssim_map,
    supervised_loss,
)
from mvedge_jax.diff._loss import _occlusion_masks
from mvedge_jax.synthetic import make_scene


@pytest.fixture(scope="module")
def scene():
    lf = make_scene(3, grid=(3, 3), size=(40, 40))
    U, V = lf.grid
    offs, views = [], []
    for r in range(U):
        for c in range(V):
            if (r, c) != (U // 2, V // 2):
                offs.append((r - U // 2, c - V // 2))
                views.append(lf.views[r, c])
    return lf.centre_view, jnp.stack(views), jnp.asarray(offs, jnp.float32), lf.centre_gt


def test_occlusion_mask_of_a_near_square():
    d = jnp.zeros((20, 20)).at[8:12, 8:12].set(3.0)
    m = np.asarray(occlusion_mask(d, jnp.array([0.0, 1.0])))
    # view to the right: the square lands 3 px to the left → background pixels 5..7 of rows
    # 8..11 are hidden behind it; the square itself is visible
    assert not m[8:12, 5:8].any()
    assert m[8:12, 8:12].all()
    assert m[0:6, 5:8].all() and m[14:, :].all()
    # constant disparity: only the strip that leaves the image is invalid
    m2 = np.asarray(occlusion_mask(jnp.full((10, 10), 2.0), jnp.array([1.0, 0.0])))
    assert not m2[:2].any() and m2[2:].all()


def test_occlusion_masks_of_all_views_are_each_views_mask(scene):
    """`photometric_terms` takes the masks of all views from one stacked z-buffer; they are
    `occlusion_mask` of each view, bit for bit."""
    _, _, offsets, gt = scene
    masks = _occlusion_masks(gt, offsets, 0.25)
    for k in range(offsets.shape[0]):
        np.testing.assert_array_equal(masks[k], occlusion_mask(gt, offsets[k], tolerance=0.25))
    assert 0 < int(jnp.sum(~masks)) < masks.size


def test_ground_truth_has_lower_warping_error_than_wrong_disparity(scene):
    centre, others, offsets, gt = scene
    good = photometric_terms(gt, centre, others, offsets)
    bad = photometric_terms(gt + 0.5, centre, others, offsets)
    flat = photometric_terms(jnp.zeros_like(gt), centre, others, offsets)
    assert float(good["photometric"]) < 0.5 * float(bad["photometric"])
    assert float(good["photometric"]) < 0.5 * float(flat["photometric"])
    assert float(good["ssim"]) < float(bad["ssim"])
    assert good["error"].shape == gt.shape and float(good["mask_count"].max()) == 8.0
    lg = self_supervised_loss(gt, centre, others, offsets)
    lb = self_supervised_loss(gt + 0.5, centre, others, offsets)
    assert float(lg) < float(lb)


def test_ssim_and_smoothness():
    a = jax.random.uniform(jax.random.key(0), (12, 12, 3))
    np.testing.assert_allclose(np.asarray(ssim_map(a, a)), 1.0, atol=1e-5)
    assert float(ssim_map(a, 1.0 - a).mean()) < 0.0
    img = jnp.zeros((8, 8, 3)).at[:, 4:].set(1.0)
    step = jnp.zeros((8, 8)).at[:, 4:].set(1.0)
    # a depth step on the image edge is cheap, the same step elsewhere is not
    assert float(edge_aware_smoothness(step, img)) < 1e-3
    assert float(edge_aware_smoothness(step.T, img)) > 0.05


def test_ssim_matches_reference_and_gradients(x64):
    # Reference: 3x3 means with edge replication (scipy's uniform_filter, mode "nearest").
    from scipy.ndimage import uniform_filter

    rng = np.random.default_rng(7)
    a, b = rng.uniform(0, 1, (2, 9, 11, 3))

    def mean3(x):
        return uniform_filter(x, size=(3, 3, 1), mode="nearest")

    mu_a, mu_b = mean3(a), mean3(b)
    va, vb = mean3(a * a) - mu_a**2, mean3(b * b) - mu_b**2
    cov = mean3(a * b) - mu_a * mu_b
    c1, c2 = 0.01**2, 0.03**2
    ref = (2 * mu_a * mu_b + c1) * (2 * cov + c2) / ((mu_a**2 + mu_b**2 + c1) * (va + vb + c2))
    np.testing.assert_allclose(np.asarray(ssim_map(a, b)), ref, rtol=1e-9, atol=1e-12)
    check_grads(lambda x, y: ssim_map(x, y), (a, b), order=1, modes=("rev",), eps=1e-6)


def test_supervised_loss_and_bad_input():
    d = jnp.zeros((4, 5))
    t = jnp.ones((4, 5))
    assert float(supervised_loss(d, t)) == 1.0
    m = jnp.zeros((4, 5), bool).at[0, 0].set(True)
    assert float(supervised_loss(d, t.at[0, 0].set(3.0), m)) == 3.0
    with pytest.raises(ValueError, match="shape"):
        supervised_loss(d, jnp.ones((5, 4)))
    with pytest.raises(ValueError, match="offsets"):
        photometric_terms(d, jnp.zeros((4, 5, 3)), jnp.zeros((2, 4, 5, 3)), jnp.zeros((3, 2)))
    with pytest.raises(ValueError, match="occlusion_tolerance"):
        LossConfig(occlusion_tolerance=0.0)


def test_self_supervised_loss_grad(scene, x64):
    centre, others, offsets, gt = scene
    c = jnp.asarray(centre[:16, :16], jnp.float64)
    o = jnp.asarray(others[:, :16, :16], jnp.float64)
    # generic point: no exact ties in |∂D| (GT is piecewise constant) or in |I - W[I]|
    noise = jax.random.uniform(jax.random.key(2), (16, 16), jnp.float64, -0.05, 0.05)
    d = jnp.asarray(gt[:16, :16], jnp.float64) + 0.013 + noise
    f = jax.jit(lambda d: self_supervised_loss(d, c, o, offsets))
    check_grads(f, (d,), order=1, modes=("rev",), eps=1e-6)
