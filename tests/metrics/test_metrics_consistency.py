"""View consistency (eqs 6.9–6.10): hand-computed case, synthetic GT vs perturbed, jit, errors."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

from mvedge_jax.metrics import view_consistency
from mvedge_jax.synthetic import default_light_field, make_scene


def test_hand_computed_variance():
    # 3x3 views, all zero except view (0, 0) = 0.3 (projects with a rounded shift of 0, so
    # every target pixel gets nine values: eight 0 and one 0.3).
    d = np.zeros((3, 3, 8, 10), np.float32)
    d[0, 0] = 0.3
    expect = 0.09 / 9 - (0.3 / 9) ** 2
    assert float(view_consistency(d)) == pytest.approx(expect, rel=1e-5)
    assert float(view_consistency(d, target=(0, 0))) == pytest.approx(expect, rel=1e-5)
    C, n = view_consistency(d, per_pixel=True)
    assert C.shape == (8, 10) and int(n.min()) == 9
    mask = np.ones((3, 3), bool)
    mask[0, 0] = False
    assert float(view_consistency(d, view_mask=mask)) == pytest.approx(0.0, abs=1e-12)


def test_only_views_that_land_count():
    # View (1, 2) with disparity 2 lands 2 px to the right in the target (1, 1) (offset of the
    # target from it: dc = -1, x' = x - dc d = x + 2), so the first two target columns only
    # receive the eight zero maps.
    d = np.zeros((3, 3, 6, 12), np.float32)
    d[1, 2] = 2.0
    C, n = view_consistency(d, per_pixel=True, fill_cracks=False)
    assert (np.asarray(n)[:, :2] == 8).all() and (np.asarray(n)[:, 2:] == 9).all()
    np.testing.assert_allclose(np.asarray(C)[:, :2], 0.0)
    np.testing.assert_allclose(np.asarray(C)[:, 2:], 4.0 / 9 - (2.0 / 9) ** 2, rtol=1e-5)


@pytest.fixture(scope="module")
def gts():
    return [
        default_light_field().gt_disparity,
        make_scene(1, grid=(7, 9), size=(96, 128)).gt_disparity,
    ]


def test_synthetic_gt_is_consistent_and_perturbations_are_not(gts):
    for gt in gts:
        # (per-pixel maps only: one compilation per shape; eq 6.10 = mean over covered pixels)
        def vc_map(d):
            C, n = view_consistency(d, per_pixel=True)
            C = np.asarray(C)
            return C, float(C[np.asarray(n) > 0].mean())

        C, vc = vc_map(gt)
        _, vn = vc_map(gt + 0.1 * jax.random.normal(jax.random.key(0), gt.shape))
        _, vb = vc_map(
            gt + 0.1 * jax.random.normal(jax.random.key(1), gt.shape[:2])[..., None, None]
        )
        Cn, _ = vc_map(gt + 0.02 * jax.random.normal(jax.random.key(2), gt.shape))
        print(
            f"GT {vc:.4f} (pixels > 1e-4: {(C > 1e-4).mean():.3f}), noise 0.1: {vn:.4f}, "
            f"per-view bias 0.1: {vb:.4f}, "
            f"noise 0.02 pixels > 1e-4: {(np.asarray(Cn) > 1e-4).mean():.3f}"
        )
        # exact GT: zero variance except along depth edges, where nearest-pixel projection of
        # a sampled edge is off by up to one pixel in some views
        assert np.median(C) < 1e-5 and (C > 1e-4).mean() < 0.05
        # ... and nowhere else: outside a 2-px band around the target's depth steps C ~ 0
        g = np.asarray(gt[gt.shape[0] // 2, gt.shape[1] // 2])
        jump = np.zeros(g.shape, bool)
        jump[:, 1:] |= np.abs(np.diff(g, axis=1)) > 0.05
        jump[:, :-1] |= np.abs(np.diff(g, axis=1)) > 0.05
        jump[1:] |= np.abs(np.diff(g, axis=0)) > 0.05
        jump[:-1] |= np.abs(np.diff(g, axis=0)) > 0.05
        band = ndimage.binary_dilation(jump, iterations=2)
        assert C[~band].max() < 1e-4, C[~band].max()
        assert vc < 0.035
        assert vn > 2.0 * vc + 0.005 and vb > vc + 0.004
        assert (np.asarray(Cn) > 1e-4).mean() > 0.6


def test_jit_traced_target_and_bad_inputs(gts):
    gt = gts[1]
    f = jax.jit(lambda d, t: view_consistency(d, target=t, per_pixel=True)[0])
    C, _ = view_consistency(gt, per_pixel=True)
    np.testing.assert_allclose(f(gt, jnp.array([3, 4])), C, rtol=1e-6)
    assert not np.allclose(f(gt, jnp.array([0, 0])), C)
    with pytest.raises(ValueError, match=r"\(U, V, H, W\)"):
        view_consistency(np.zeros((3, 8, 8)))
    with pytest.raises(ValueError, match="outside"):
        view_consistency(np.zeros((3, 3, 8, 8)), target=(3, 0))
    with pytest.raises(ValueError, match="view_mask"):
        view_consistency(np.zeros((3, 3, 8, 8)), view_mask=np.ones((3, 4), bool))
