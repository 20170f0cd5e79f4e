"""Detection on synthetic EPIs: exact label recovery, sub-pixel search, soft-detection grads."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.edges import (
    bank_width,
    detect_centre_row,
    filter_disparities,
    prewitt_bank,
    soft_detect,
)
from mvedge_jax.edges._detect import (
    centre_bank,
    centre_response_magnitude,
    local_std,
    non_max_suppress,
)
from mvedge_jax.edges._refine import variance_search


def _bank(n=41, d_max=2.0, h=9):
    d = filter_disparities(n, d_max)
    return d, prewitt_bank(d, 2 * h - 1, bank_width(2 * h - 1, d_max, 1.5))


def test_centre_response_magnitude_matches_direct_sum():
    # The norm over the channels of each filter's correlation with the centre rows, written
    # out in NumPy: out[n, x, i] = |sum_{a,k} sub[i, a, k] epi_pad[n, a, x + k, :]|.
    rng = np.random.default_rng(3)
    disps, bank = _bank(n=7, d_max=1.5, h=5)
    epis = rng.random((2, 5, 23, 3)).astype(np.float32)
    got = np.asarray(centre_response_magnitude(jnp.asarray(epis), bank))
    sub = np.asarray(centre_bank(bank, 5), np.float64)
    n, h, fw = sub.shape
    pad = np.pad(epis.astype(np.float64), ((0, 0), (0, 0), (fw // 2, fw // 2), (0, 0)), "edge")
    want = np.zeros((2, 23, n))
    for x in range(23):
        win = pad[:, :, x : x + fw, :]  # (N, h, fw, C)
        r = np.einsum("iak,nakc->nci", sub, win)
        want[:, x] = np.sqrt(np.sum(r * r, axis=1))
    assert got.shape == (2, 23, 7) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="at least 3 views"):
        centre_response_magnitude(jnp.asarray(epis[:, :2]), bank)
    with pytest.raises(ValueError, match="no channel"):
        centre_response_magnitude(jnp.zeros((2, 5, 23, 0)), bank)


def test_local_std_matches_numpy():
    # The norm over the channels of the standard deviations of each centre-row pixel's 3x3
    # window (edge-replicated columns).
    rng = np.random.default_rng(4)
    epis = rng.random((3, 7, 19, 3)).astype(np.float32)
    rows = np.pad(epis[:, 2:5].astype(np.float64), ((0, 0), (0, 0), (1, 1), (0, 0)), "edge")
    win = np.stack([rows[:, :, i : i + 19] for i in range(3)], axis=2)  # (N, 3, 3, W, C)
    want = np.sqrt(np.sum(np.var(win, axis=(1, 2)), axis=-1))
    got = np.asarray(local_std(jnp.asarray(epis)))
    assert got.shape == (3, 19)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("i", [0, 3, 10, 12, 20, 30, 31, 38, 40])
def test_label_on_known_slope(make_step_epi, i):
    # Two blurred step edges with the slope of filter i: the two NMS peaks sit on the edges and
    # carry label i exactly where the line meets pixel centres on every row (integer d; the
    # tent-interpolated filters of other slopes are slightly attenuated), within one label else.
    disps, bank = _bank()
    d = float(disps[i])
    epi = jnp.asarray(make_step_epi([40.3, 80.0], [1, -1], d, 9, 128))[None]
    det = detect_centre_row(epi, bank)
    conf = np.asarray(non_max_suppress(det["conf"] * local_std(epi)))[0]
    peaks = np.argsort(conf)[::-1][:2]
    assert sorted(peaks.tolist()) == [40, 80]
    labels = np.asarray(det["label"])[0, peaks]
    if abs(d - round(d)) < 1e-6:
        assert labels.tolist() == [i, i]
    else:
        assert np.abs(labels - i).max() <= 1


def test_variance_search_subpixel(make_texture):
    disps, _ = _bank()
    spacing = float(disps[1] - disps[0])
    t = make_texture(3, fmax=0.12)  # content the pre-blur leaves (sigma 0.85 px)
    h, W = 9, 160
    a = (np.arange(h) - h // 2)[:, None]
    x = np.arange(W)[None, :]
    search = jax.jit(
        lambda e, x, d: variance_search(e, x, d, radius=1.5 * spacing, offset=1.0, steps=17)
    )
    for d_true in (-1.234, 0.05, 0.777):
        epi = jnp.asarray(t(x + a * d_true), jnp.float32)  # E[u, x] = T(x + a d): x(u) = x_c - a d
        xc = jnp.array([50.0, 80.0, 110.0])
        d0 = jnp.full((3,), d_true + 0.7 * spacing)
        d, std, _, ratio = search(epi, xc, d0)
        np.testing.assert_allclose(np.asarray(d), d_true, atol=4e-3)
        assert float(jnp.max(std)) < 0.01
        assert float(jnp.min(ratio)) > 5.0  # a distinct minimum on a textured line
    # A flat EPI has no distinct minimum.
    flat = jnp.full((h, W, 3), 0.5)
    _, _, _, ratio = search(flat, xc, d0)
    assert float(jnp.max(ratio)) < 1.5


def test_soft_detect_matches_hard_at_low_temperature(make_step_epi):
    disps, bank = _bank(n=21)
    epi = jnp.asarray(make_step_epi([30.0], [1], float(disps[14]), 9, 64))[None]
    dsoft, csoft = soft_detect(epi, bank, disps, 1e-4)
    det = detect_centre_row(epi, bank)
    assert float(dsoft[0, 30]) == pytest.approx(float(disps[14]), abs=1e-3)
    assert float(csoft[0, 30]) == pytest.approx(float(det["conf"][0, 30]), rel=1e-3)


def test_soft_detect_gradients(x64, make_step_epi):
    from mvedge_jax.edges import blur_images

    disps = jnp.linspace(-1.0, 1.0, 7)
    epi = jnp.asarray(make_step_epi([12.3], [1], 0.4, 5, 24), jnp.float64)[None]

    @jax.jit
    def f(epi, sigma, temperature, shift):
        bank = prewitt_bank(disps, 9, 15, shift=shift, aa_sigma=0.4)  # smooth in shift
        e = blur_images(epi, sigma, 2)
        d, c = soft_detect(e, bank, disps, temperature)
        return jnp.sum(d[:, 8:18] * c[:, 8:18])

    args = (epi, jnp.float64(0.8), jnp.float64(0.05), jnp.float64(1.1))
    check_grads(f, args, order=1, modes=("rev",), eps=1e-6)
    g = jax.grad(f, argnums=(0, 1, 2, 3))(*args)
    assert all(bool(jnp.all(jnp.isfinite(x))) and float(jnp.abs(x).max()) > 0 for x in g)


def test_detect_shapes_and_bad_input(make_step_epi):
    disps, bank = _bank()
    epis = jnp.zeros((5, 9, 64, 3))
    det = jax.jit(lambda e: detect_centre_row(e, bank, chunk=2))(epis)
    assert det["conf"].shape == (5, 64) and det["label"].dtype == jnp.int32
    with pytest.raises(ValueError, match="at least 3 views"):
        detect_centre_row(jnp.zeros((2, 1, 64, 3)), bank)
    with pytest.raises(ValueError, match="shape"):
        detect_centre_row(jnp.zeros((9, 64, 3)), bank)


def test_soft_edge_maps_gradients_reach_views_and_parameters(x64, make_texture):
    from mvedge_jax.edges import soft_edge_maps

    t = make_texture(7, fmax=0.15)
    a = np.arange(5) - 2
    xs = np.arange(20)
    views = np.stack([np.repeat(t(xs + ai * 0.4)[None], 6, axis=0) for ai in a])  # (5, 6, 20, 3)
    views = jnp.asarray(np.clip(views, 0.05, 0.95), jnp.float64)

    @jax.jit
    def loss(views, sigma, temperature):
        d, c = soft_edge_maps(
            views,
            d_max=1.0,
            n_filters=9,
            presmooth_sigma=sigma,
            temperature=temperature,
            aa_sigma=0.4,
            blur_radius=2,
        )
        return jnp.sum((d[:, 6:14] - 0.4) ** 2 * c[:, 6:14])

    args = (views, jnp.float64(0.85), jnp.float64(0.05))
    check_grads(loss, args, order=1, modes=("rev",), eps=1e-6)
    d, c = soft_edge_maps(views, d_max=1.0, n_filters=9, aa_sigma=0.4)
    assert d.shape == (6, 20) and c.shape == (6, 20)
    with pytest.raises(ValueError, match="n >= 3"):
        soft_edge_maps(views[:2], d_max=1.0)
