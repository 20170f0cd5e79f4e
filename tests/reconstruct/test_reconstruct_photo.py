"""Photo-consistent snapping of depth boundaries."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from scipy.ndimage import grey_dilation

from mvedge_jax.reconstruct import photo_cost, photo_refine


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
