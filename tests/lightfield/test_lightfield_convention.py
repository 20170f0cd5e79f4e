"""The SPEC §0 disparity sign, checked on real HCI 4D scenes with ground truth.

``centre(x, y) ≈ view[row, col](x - dc d, y - dr d)``: warping every cross-hair view to the
centre with the GT disparity must beat warping with zero disparity and with the negated GT by a
clear factor, and beat 0.75× and 1.33× the GT (the scale is right too).

Why the comparison is made on pixels visible in both views. On backgammon the foreground is
a comb of thin horizontal wedges: vertical parallax moves points ACROSS their horizontal edges,
so at |dr| = 4 about 11% of the centre pixels are occluded in the other view (under 1% for
horizontal parallax, which slides along the edges). At those pixels the GT warp samples the
occluder, so the mean error over all pixels is dominated by occlusions (view (0, 4): 0.027 with
GT vs 0.040 zero vs 0.051 negated; view (4, 8): 0.0065 vs 0.031 vs 0.033) while the median is
not (0.0063 vs 0.029 vs 0.035). Excluding the pixels that the GT z-buffer says are occluded in
the other view, and the 1-px band of mixed (anti-aliased) pixels along depth steps, restores
the contrast ((0, 4): 0.0076 vs 0.030 vs 0.038). For adjacent views (|offset| = 1) the zero
warp is itself only 0.5-1.5 px off on backgammon, so the ratio there is bounded by the noise
and interpolation floor (~0.007) and the threshold is lower.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

from mvedge_jax.io import read_hci4d
from mvedge_jax.lightfield import backward_warp, forward_project

BORDER = 16
SCALES = (1.0, 0.0, -1.0, 0.75, 1.33)
# Minimum ratio err(wrong)/err(GT): (for |offset| = 1, for |offset| >= 2). Measured minima
# over the 16 cross-hair views: backgammon 1.75 / 3.17, antinous 4.42 / 5.48 (zero disparity;
# the negated GT is always worse), scale 0.75/1.33: backgammon 1.06 / 1.49, antinous 1.79 / 2.37.
THRESHOLDS = {
    "stratified/backgammon": {"sign": (1.5, 2.8), "scale": (1.03, 1.3), "median": 2.5},
    "additional/antinous": {"sign": (3.5, 4.5), "scale": (1.4, 1.9), "median": 2.5},
}


def _cross_hair(U, V):
    rc, cc = U // 2, V // 2
    return [(rc, c) for c in range(V) if c != cc] + [(r, cc) for r in range(U) if r != rc]


@jax.jit
def _errors(view, centre, gt, off):
    """Mean-over-channels |warped view - centre| for each disparity scale: (5, H, W)."""
    return jnp.stack([jnp.abs(backward_warp(view, s * gt, off) - centre).mean(-1) for s in SCALES])


@jax.jit
def _visible(gt, off):
    """Centre pixels whose point is not occluded in the view at ``off`` (GT z-buffer)."""
    H, W = gt.shape
    z, valid = forward_project(gt, off)
    ys, xs = jnp.meshgrid(jnp.arange(H), jnp.arange(W), indexing="ij")
    tx = jnp.floor(xs - off[1] * gt + 0.5).astype(jnp.int32)
    ty = jnp.floor(ys - off[0] * gt + 0.5).astype(jnp.int32)
    inside = (tx >= 0) & (tx < W) & (ty >= 0) & (ty < H)
    tx, ty = jnp.clip(tx, 0, W - 1), jnp.clip(ty, 0, H - 1)
    return inside & valid[ty, tx] & (z[ty, tx] <= gt + 0.1)


def _depth_step_band(g, thresh=0.1):
    jump = np.zeros(g.shape, bool)
    dx = np.abs(np.diff(g, axis=1)) > thresh
    dy = np.abs(np.diff(g, axis=0)) > thresh
    jump[:, 1:] |= dx
    jump[:, :-1] |= dx
    jump[1:] |= dy
    jump[:-1] |= dy
    return ndimage.binary_dilation(jump, iterations=1)


@pytest.mark.parametrize("scene", list(THRESHOLDS))
def test_gt_warp_sign_and_scale_on_hci(data_dir, scene):
    lf = read_hci4d(data_dir / "hci4d" / scene)
    assert lf.gt_disparity is not None and bool(lf.centre_gt_mask.all())
    gt, centre = lf.centre_gt, lf.centre_view
    U, V = lf.grid
    rc, cc = lf.centre_index
    band = _depth_step_band(np.asarray(gt))
    inner = np.zeros(band.shape, bool)
    inner[BORDER:-BORDER, BORDER:-BORDER] = True
    th = THRESHOLDS[scene]
    failures = []
    print(f"\n{scene}: view |o| mask  err: GT  zero  neg  0.75x 1.33x | all px mean, median")
    for r, c in _cross_hair(U, V):
        off = jnp.array([r - rc, c - cc], jnp.float32)
        E = np.asarray(_errors(lf.views[r, c], centre, gt, off))
        m = np.asarray(_visible(gt, off)) & ~band & inner
        e = E[:, m].mean(axis=1)
        allm = E[:, inner].mean(axis=1)
        med = np.median(E[:, inner], axis=1)
        o = int(max(abs(r - rc), abs(c - cc)))
        print(
            f"  ({r},{c})  {o}  {m.sum() / inner.sum():.3f}  "
            + " ".join(f"{x:.4f}" for x in e)
            + " | "
            + "/".join(f"{x:.4f}" for x in allm[:3])
            + ", "
            + "/".join(f"{x:.4f}" for x in med[:3])
        )
        k = 0 if o == 1 else 1
        if min(e[1], e[2]) < th["sign"][k] * e[0]:
            failures.append((r, c, "sign", e[1] / e[0], e[2] / e[0]))
        if min(e[3], e[4]) < th["scale"][k] * e[0]:
            failures.append((r, c, "scale", e[3] / e[0], e[4] / e[0]))
        # The median over ALL pixels (occlusions included) is robust for |offset| >= 2.
        if o >= 2 and min(med[1], med[2]) < th["median"] * med[0]:
            failures.append((r, c, "median", med[1] / med[0], med[2] / med[0]))
        assert m.sum() > 0.6 * inner.sum()  # the comparison covers most of the image
    assert not failures, failures
