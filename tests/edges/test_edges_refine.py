"""Refinement stages on small inputs: entropy search (eq 4.5), alignment / visibility
(eqs 4.3–4.4), outlier rejection (eqs 4.1–4.2) and the trilateral filter (eq 4.6)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.edges import EdgeConfig, EdgeRefineConfig, EdgeSet, OutlierConfig, detect_edges
from mvedge_jax.edges._global import reject_outliers, trilateral_filter
from mvedge_jax.edges._refine import (
    alignment_cosines,
    entropy_search,
    gauss_newton_refine,
    line_entropy,
    line_variance,
    sample_epi,
    shift_stack,
    sobel_tensor,
)


def test_entropy_search_moves_towards_the_true_line(make_step_epi, key):
    # Two-tone EPI of one edge with d = 0.5; the entropy of a line lying on one side is 0.
    h, W = 9, 48
    epi = make_step_epi([20.0], [1], 0.5, h, W, sigma=0.0)[..., 0] / 0.6 * 0.9 + 0.05
    epi = jnp.asarray(epi)
    # True line on the left side, 1.5 px from the edge: x(u) = 18.5 - (u - 4) 0.5.
    xt, xb = jnp.array([18.5 + 2.0 + 0.3]), jnp.array([18.5 - 2.0 - 0.3])  # slope a bit off
    e0 = float(line_entropy(epi, xt, xb, 16)[0])
    nt, nb = entropy_search(
        epi, xt, xb, jnp.array([True]), key, iters=30, t=0.95, alpha=0.6, bins=16
    )
    e1 = float(line_entropy(epi, nt, nb, 16)[0])
    assert e1 <= e0
    # inactive lines do not move
    st, sb = entropy_search(
        epi, xt, xb, jnp.array([False]), key, iters=5, t=0.9, alpha=0.5, bins=16
    )
    assert float(st[0]) == float(xt[0]) and float(sb[0]) == float(xb[0])


def test_alignment_cosines(make_step_epi):
    epi = jnp.asarray(make_step_epi([20.0], [1], 0.5, 9, 48))
    T = sobel_tensor(epi)
    cos = np.asarray(alignment_cosines(T, jnp.array([20.0, 20.0]), jnp.array([0.5, -1.5])))
    assert cos.shape == (2, 9)
    assert cos[0].min() > np.cos(np.pi / 13)  # the edge's own slope: aligned on every row
    assert np.median(cos[1]) < cos[0].min()  # a wrong slope is not


def _edges(x, y, d, conf, lab=None, direction=None):
    n = len(x)
    e = EdgeSet.empty(n)
    return EdgeSet(
        x=jnp.asarray(x, jnp.float32),
        y=jnp.asarray(y, jnp.float32),
        disparity=jnp.asarray(d, jnp.float32),
        confidence=jnp.asarray(conf, jnp.float32),
        visible=jnp.ones(n, bool),
        lab=jnp.zeros((n, 3)) if lab is None else jnp.asarray(lab, jnp.float32),
        direction=jnp.zeros(n, jnp.int32) if direction is None else jnp.asarray(direction),
        intercepts=e.intercepts,
        valid=jnp.ones(n, bool),
        n_dropped=e.n_dropped,
    )


def test_outlier_rejection_counts_same_label_neighbours():
    # 15x15 image, p = q = 1/3 of it = 5: a cluster of 6 points with label 10 and one isolated
    # weak point with label 30 (a strong isolated point survives on its confidence alone).
    xs = [5, 6, 7, 5, 6, 7, 12, 2]
    ys = [5, 5, 5, 6, 6, 6, 12, 12]
    labels = jnp.array([10, 10, 11, 10, 10, 10, 30, 40])
    conf = [0.1] * 6 + [0.1, 10.0]
    e = _edges(xs, ys, np.zeros(8), conf)
    cfg = EdgeConfig(outliers=OutlierConfig(test="count", window_frac=1 / 3, label_tol=1, tau=0.2))
    keep = np.asarray(jax.jit(lambda e, lb: reject_outliers(e, lb, (15, 15), cfg))(e, labels))
    # cluster: 0.1 * 6 / 25 = 0.024 < 0.2; isolated weak 0.1 / 25; strong 10 / 25 = 0.4 >= 0.2.
    assert keep.tolist() == [False] * 6 + [False, True]
    cfg2 = EdgeConfig(
        outliers=OutlierConfig(test="count", window_frac=1 / 3, label_tol=1, tau=0.02)
    )
    keep2 = np.asarray(reject_outliers(e, labels, (15, 15), cfg2))
    assert keep2.tolist() == [True] * 6 + [False, True]


def test_outlier_agreement_test_keeps_isolated_points_and_drops_disagreeing_ones():
    # A cluster of 6 points with label 10, one point inside it with label 30 (disagrees with
    # its neighbours), and an isolated point with label 40 far away (no neighbours at all).
    xs = [5, 6, 7, 5, 6, 7, 6, 13]
    ys = [5, 5, 5, 6, 6, 6, 7, 13]
    labels = jnp.array([10, 10, 11, 10, 10, 10, 30, 40])
    e = _edges(xs, ys, np.zeros(8), [0.1] * 8)
    cfg = EdgeConfig(outliers=OutlierConfig(test="agreement", window_frac=1 / 3, min_agreement=0.3))
    keep = np.asarray(jax.jit(lambda e, lb: reject_outliers(e, lb, (15, 15), cfg))(e, labels))
    # cluster: 6 of 7 neighbours agree; label 30: 1 of 7; isolated: 1 of 1.
    assert keep.tolist() == [True] * 6 + [False, True]


@pytest.mark.parametrize("order", [(0, 1, 2), (2, 1, 0)])
def test_trilateral_filter_keeps_the_highest_index_point_of_a_pixel(order):
    """Three points of one EPI direction on one pixel (alone in its window): the grid holds
    the one of the highest index, whatever order the scatter would apply them in, and every
    point on the pixel reads its value; a point of the other direction keeps its own."""
    d = np.array([0.2, 0.9, 1.6])[list(order)]
    xs = [5.2, 4.9, 5.0, 5.1]
    ys = [5.0, 5.3, 4.8, 5.0]
    e = _edges(xs, ys, [*d, -0.7], np.ones(4), direction=[0, 0, 0, 1])
    cfg = EdgeConfig(refine=EdgeRefineConfig(trilateral_radius=2))
    f = np.asarray(jax.jit(lambda e: trilateral_filter(e, (12, 12), cfg))(e))
    np.testing.assert_allclose(f[:3], d[2], atol=1e-6)
    np.testing.assert_allclose(f[3], -0.7, atol=1e-6)


def test_trilateral_filter_smooths_within_surfaces_only():
    rng = np.random.default_rng(0)
    ys, xs = np.mgrid[0:12, 0:12]
    xs, ys = xs.ravel(), ys.ravel()
    d = np.where(xs < 6, 0.5, 1.5) + rng.normal(0, 0.02, xs.size)  # two surfaces, noisy
    lab = np.where((xs < 6)[:, None], [[40.0, 0, 0]], [[70.0, 10, 0]])
    e = _edges(xs, ys, d, np.ones(xs.size), lab=lab)
    cfg = EdgeConfig(refine=EdgeRefineConfig(trilateral_radius=3))
    f = np.asarray(jax.jit(lambda e: trilateral_filter(e, (12, 12), cfg))(e))
    truth = np.where(xs < 6, 0.5, 1.5)
    assert np.abs(f - truth).mean() < 0.5 * np.abs(d - truth).mean()
    assert np.abs(f - truth).max() < 0.1  # no bleeding across the depth edge


def test_outlier_rejection_is_automatic_for_few_views():
    # outliers.enabled=None rejects outliers only when the EPIs have <= outliers.auto_views
    # views.
    from edges_helpers import plane_light_field

    for U, expect_on in ((3, True), (9, False)):
        plane = plane_light_field(0.637, U=U, H=16, W=24, seed=2)
        cfg = EdgeConfig(outliers=OutlierConfig(min_agreement=1.01))  # would reject every point
        n = int(np.asarray(detect_edges(plane, cfg).valid).sum())
        assert (n == 0) == expect_on, (U, n)


def test_trilateral_filter_is_eq_4_6_summed_directly():
    """Random points of both directions (one per pixel and direction) on a 10x12 grid: the
    filter equals eq 4.6 summed point by point over the window, both directions pooled."""
    rng = np.random.default_rng(3)
    H, W, r = 10, 12, 2
    cells = rng.choice(2 * H * W, 120, replace=False)
    direction, rest = np.divmod(cells, H * W)
    ys, xs = np.divmod(rest, W)
    n = cells.size
    d = rng.uniform(-1.0, 1.0, n)
    lab = rng.uniform(0.0, 60.0, (n, 3))
    e = _edges(xs, ys, d, np.ones(n), lab=lab, direction=direction)
    cfg = EdgeConfig(refine=EdgeRefineConfig(trilateral_radius=r))
    f = np.asarray(jax.jit(lambda e: trilateral_filter(e, (H, W), cfg))(e))
    rc = cfg.refine
    expect = np.empty(n)
    for i in range(n):
        near = (np.abs(ys - ys[i]) <= r) & (np.abs(xs - xs[i]) <= r)
        w = np.exp(
            -((ys[near] - ys[i]) ** 2 + (xs[near] - xs[i]) ** 2) / (2 * rc.sigma_s**2)
            - (d[near] - d[i]) ** 2 / (2 * rc.sigma_d**2)
            - np.sum((lab[near] - lab[i]) ** 2, axis=1) * 1e-4 / (2 * rc.sigma_c**2)
        )
        expect[i] = np.sum(w * d[near]) / np.sum(w)
    np.testing.assert_allclose(f, expect, atol=1e-5)


def test_shift_stack_is_cubic_interpolation_of_each_row():
    """Every row resampled at its own static shifts equals `sample_epi`'s cubic
    interpolation at the shifted positions of the edge-replicated row (inside and beyond the
    borders)."""
    rng = np.random.default_rng(4)
    h, W, C, S, pad = 5, 30, 3, 4, 6
    epi = jnp.asarray(rng.uniform(0.0, 1.0, (h, W, C)), jnp.float32)
    shifts = rng.uniform(-3.0, 3.0, (h, S))
    shifts[0] = [-1.0, 0.0, 2.0, 2.5]  # integer and half-pixel shifts
    got = np.asarray(shift_stack(epi, shifts, cubic=True))
    assert got.shape == (h, W, S, C)
    padded = jnp.pad(epi, ((0, 0), (pad, pad), (0, 0)), mode="edge")
    x = pad + np.arange(W)[None, :, None] + shifts[:, None, :]  # (h, W, S)
    for j in range(S):
        want = sample_epi(padded, jnp.asarray(x[:, :, j].T, jnp.float32), cubic=True)
        np.testing.assert_allclose(got[:, :, j], np.transpose(want, (1, 0, 2)), atol=1e-5)


def test_gauss_newton_refine_reaches_the_variance_minimum():
    """Lines on a smooth random texture moving with disparity 0.63: started 0.05 off, the
    polish lands where the cubic line variance is smallest (a fine grid search), and returns
    that variance."""
    rng = np.random.default_rng(5)
    h, W, C, d_true = 9, 64, 3, 0.63
    coarse = rng.uniform(0.0, 1.0, (W // 4 + 4, C))
    xs_tex = np.arange(W + 40) / 4.0
    tex = np.stack([np.interp(xs_tex, np.arange(len(coarse)), coarse[:, c]) for c in range(C)], 1)
    a = np.arange(h) - h // 2
    u = np.arange(W)
    epi = np.stack(
        [
            np.stack(
                [np.interp(u + ai * d_true + 20, np.arange(W + 40), tex[:, c]) for c in range(C)], 1
            )
            for ai in a
        ]
    )  # (h, W, C): row u shows the texture moved by -a d
    epi = jnp.asarray(epi, jnp.float32)
    xs = jnp.asarray([20.3, 31.0, 40.7], jnp.float32)
    d0 = jnp.asarray([d_true - 0.05, d_true + 0.05, d_true - 0.03], jnp.float32)
    d, var = gauss_newton_refine(epi, xs, d0, iters=4, max_step=0.1)
    grid = d_true + np.linspace(-0.1, 0.1, 401)
    v = np.asarray(
        line_variance(
            epi, xs[:, None], jnp.asarray(np.broadcast_to(grid, (3, 401)), jnp.float32), cubic=True
        )
    )
    best = grid[np.argmin(v, axis=1)]
    np.testing.assert_allclose(np.asarray(d), best, atol=1e-3)
    np.testing.assert_allclose(
        np.asarray(var),
        np.asarray(line_variance(epi, xs, d, cubic=True)),
        rtol=1e-4,
        atol=1e-9,
    )
