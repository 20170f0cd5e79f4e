"""Photo-consistent snapping of depth boundaries."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reconstruct_helpers import cross_hair, interior
from scipy.ndimage import grey_dilation, grey_erosion

from mvedge_jax.io import load_light_field
from mvedge_jax.lightfield import ssim_map
from mvedge_jax.reconstruct import (
    ReconstructConfig,
    SelectConfig,
    SharpenConfig,
    photo_cost,
    photo_refine,
    photo_select,
    photo_sweep,
    select_centre,
)
from mvedge_jax.reconstruct._photo import _window_extrema


def test_photo_cost_is_lowest_at_the_truth(small_scene):
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = lf.centre_gt
    costs = [
        float(jnp.mean(photo_cost(gt + delta, lf.centre_view, views, offsets)))
        for delta in (-0.3, 0.0, 0.3)
    ]
    assert costs[1] < 0.5 * min(costs[0], costs[2]), costs


def test_photo_cost_view_weights_in_the_half_plane_means():
    rng = np.random.default_rng(0)
    ref = jnp.asarray(rng.uniform(0.2, 0.6, (8, 10, 3)), jnp.float32)
    views = jnp.stack([ref, ref + 0.1])  # per-view L1 costs 0 and 0.3 (three channels)
    offsets = jnp.asarray([[0.0, -1.0], [0.0, -2.0]])  # both in the left half-plane
    flat = jnp.zeros((8, 10))  # identity warps
    equal = photo_cost(flat, ref, views, offsets)
    np.testing.assert_allclose(np.asarray(equal), 0.15, atol=1e-6)
    weighted = photo_cost(flat, ref, views, offsets, weights=jnp.asarray([3.0, 1.0]))
    np.testing.assert_allclose(np.asarray(weighted), 0.3 / 4, atol=1e-6)
    ones = photo_cost(flat, ref, views, offsets, weights=jnp.ones(2))
    np.testing.assert_array_equal(np.asarray(ones), np.asarray(equal))


def _halo_refine(small_scene):
    """The scene, its centre ground truth fattened by 2 px (edge fattening) and `photo_refine`
    of a map against the scene's cross-hair (radius 3, jump 0.2; further keywords passed)."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    halo = jnp.asarray(grey_dilation(np.asarray(lf.centre_gt), size=(5, 5)))

    def refine(d, **kw):
        return photo_refine(d, lf.centre_view, views, offsets, radius=3, jump=0.2, **kw)

    return lf, halo, refine


def test_photo_refine_near_weight(small_scene):
    _, halo, refine = _halo_refine(small_scene)
    f = jax.jit(lambda d, w: refine(d, iterations=4, near_weight=w))
    plain = refine(halo, iterations=4)
    np.testing.assert_array_equal(np.asarray(f(halo, 1.0)), np.asarray(plain))
    # weight 0 leaves the views one step away out of the cost: a different decision somewhere
    assert not np.array_equal(np.asarray(f(halo, 0.0)), np.asarray(plain))


def test_photo_refine_removes_a_foreground_halo(small_scene):
    lf, halo, refine = _halo_refine(small_scene)
    gt = np.asarray(lf.centre_gt)
    out = np.asarray(jax.jit(lambda d: refine(d, iterations=4))(halo))
    halo = np.asarray(halo)
    bad_in = np.mean(np.abs(halo - gt) > 0.07)
    bad_out = np.mean(np.abs(out - gt) > 0.07)
    assert bad_in > 0.05
    assert bad_out < 0.5 * bad_in, (bad_in, bad_out)
    # Away from discontinuities nothing changes.
    flat = grey_dilation(halo, size=(31, 31)) + grey_dilation(-halo, size=(31, 31)) < 0.2
    assert flat.sum() > 100
    np.testing.assert_array_equal(out[flat], halo[flat])


def test_photo_refine_passes_equal_single_passes(small_scene):
    # The passes carry the costs of the pixels' values over from the previous pass instead of
    # recomputing them: the same decisions as passes that start afresh each time.
    _, halo, refine = _halo_refine(small_scene)
    f = jax.jit(lambda d, n: refine(d, iterations=n), static_argnums=1)
    one = halo
    for k in range(1, 5):
        one = f(one, 1)
        together = np.asarray(f(halo, k))
        np.testing.assert_array_equal(together, np.asarray(one))
    assert not np.array_equal(np.asarray(f(halo, 1)), together)  # later passes change pixels


def test_photo_select_takes_the_better_map_and_keeps_fine_values(small_scene):
    """A candidate that fixes a fattened boundary but is noisy at the 0.01 level elsewhere:
    the merge takes its boundary fix and keeps the incumbent's fine values."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
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
    views, offsets = cross_hair(lf)
    gt = np.asarray(lf.centre_gt)
    halo = grey_dilation(gt, size=(5, 5))
    out, took = photo_select(jnp.asarray(gt), jnp.asarray(halo), lf.centre_view, views, offsets)
    wrong = np.abs(halo - gt) > 0.07
    assert np.mean(np.asarray(took)[wrong]) < 0.15  # measured 0.07
    assert np.mean(np.abs(np.asarray(out) - gt) > 0.07) < 0.15 * np.mean(wrong)


def test_photo_select_bad_input(small_scene):
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = lf.centre_gt
    with pytest.raises(ValueError, match="same shape"):
        photo_select(gt, gt[:-1], lf.centre_view, views, offsets)


def test_select_centre_matches_photo_select_with_the_cross_hair(small_scene):
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = jnp.asarray(lf.centre_gt)
    halo = jnp.asarray(grey_dilation(np.asarray(gt), size=(5, 5)))
    cfg = ReconstructConfig(select=SelectConfig(min_change=0.05, aggregate=2))
    a, ta = select_centre(lf.views, halo, gt, cfg)
    b, tb = photo_select(
        halo, gt, lf.centre_view, views, offsets, min_change=0.05, aggregate=2, ssim=1.0
    )
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-6)
    assert np.mean(np.asarray(ta) == np.asarray(tb)) > 0.999
    with pytest.raises(ValueError, match="centre_disparity must have shape"):
        select_centre(lf.views, halo, gt[:, :-1], cfg)
    with pytest.raises(ValueError, match=r"SelectConfig\.aggregate"):
        SelectConfig(aggregate=-1)
    with pytest.raises(ValueError, match=r"SelectConfig\.min_change"):
        SelectConfig(min_change=-0.1)
    with pytest.raises(ValueError, match=r"SelectConfig\.ssim"):
        SelectConfig(ssim=-1.0)


def test_photo_cost_ssim_term(small_scene):
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    ref = lf.centre_view
    d = lf.centre_gt + 0.2
    plain = np.asarray(photo_cost(d, ref, views, offsets))
    np.testing.assert_array_equal(np.asarray(photo_cost(d, ref, views, offsets, ssim=0.0)), plain)
    with_ssim = np.asarray(photo_cost(d, ref, views, offsets, ssim=1.0))
    assert np.all(with_ssim >= plain - 1e-6) and np.mean(with_ssim > plain + 1e-3) > 0.3
    # a copy of the reference at disparity 0: the warp is the identity, SSIM is 1
    zero = jnp.zeros_like(d)
    same = photo_cost(zero, ref, ref[None], jnp.asarray([[0.0, 1.0]]), ssim=1.0)
    np.testing.assert_allclose(np.asarray(same), 0.0, atol=1e-6)


def test_ssim_channels_first_matches_channels_last():
    rng = np.random.default_rng(3)
    a, b = rng.uniform(0, 1, (2, 9, 11, 3)).astype(np.float32)
    last = np.asarray(ssim_map(a, b))
    first = np.asarray(ssim_map(a.transpose(2, 0, 1), b.transpose(2, 0, 1), channels_last=False))
    np.testing.assert_allclose(first, last.transpose(2, 0, 1), rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="3-D images of one shape"):
        ssim_map(a, b[:, :-1])


def test_ssim_tells_disparities_apart_on_faint_real_texture(data_dir):
    """Antinous, bottom 128 rows (the steep, faintly textured floor and the statue's base):
    the share of pixels where the ground truth costs less than GT − 0.05 / GT + 0.05.
    Measured (session 8): L1 alone 0.60 / 0.80, with the SSIM term 0.72 / 0.86 (on the whole
    512² view 0.69 / 0.79 and 0.82 / 0.87; on the floor's bottom 64 rows 0.48 / 0.83 and
    0.58 / 0.84)."""
    lf = load_light_field(data_dir / "hci4d" / "additional" / "antinous")
    crop = (slice(384, 512), slice(None))
    others = [lf.views[4, c] for c in range(9) if c != 4] + [
        lf.views[r, 4] for r in range(9) if r != 4
    ]
    views = jnp.stack([v[crop] for v in others])
    offsets = jnp.asarray(
        [(0, c - 4) for c in range(9) if c != 4] + [(r - 4, 0) for r in range(9) if r != 4],
        jnp.float32,
    )
    ref, gt = lf.centre_view[crop], jnp.asarray(lf.centre_gt)[crop]
    cost = jax.jit(lambda d, r, v, o, w: photo_cost(d, r, v, o, aggregate=3, ssim=w))
    wins = {}
    for w in (0.0, 1.0):
        c0 = np.asarray(cost(gt, ref, views, offsets, w))
        wins[w] = [
            float(np.mean(c0 < np.asarray(cost(gt + dd, ref, views, offsets, w))))
            for dd in (-0.05, 0.05)
        ]
    assert wins[1.0][0] > wins[0.0][0] + 0.05, wins
    assert wins[1.0][1] > wins[0.0][1], wins
    assert min(wins[1.0]) > 0.6, wins


def test_photo_sweep_corrects_a_small_offset(small_scene):
    """A map off by 0.06 px per view step everywhere: inside the surfaces the sweep brings it
    closer to the truth (parabola vertex between hypotheses 0.1 apart). Measured: median
    error 0.016, 18 % of the pixels above 0.04, none above the input's 0.06 but 1 %."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = np.asarray(lf.centre_gt)
    f = jax.jit(lambda d: photo_sweep(d, lf.centre_view, views, offsets, steps=5, search=0.2))
    out = np.asarray(f(jnp.asarray(gt + 0.06)))
    inside = interior(gt)
    assert inside.mean() > 0.4
    err = np.abs(out - gt)[inside]
    assert np.median(err) < 0.02 and np.mean(err > 0.065) < 0.05, (np.median(err), err.mean())
    assert np.all(np.abs(out - (gt + 0.06)) <= 0.2 + 1e-5)


def test_photo_sweep_margin_keeps_values_without_a_significant_gain(small_scene):
    """With a margin, the sweep moves a pixel only where a hypothesis beats the pixel's own
    value by that fraction: the ground truth stays exact where it is the best hypothesis, a
    0.06 offset is still corrected where the colours say so clearly."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = np.asarray(lf.centre_gt)
    f = jax.jit(
        lambda d, m: photo_sweep(d, lf.centre_view, views, offsets, steps=5, search=0.2, margin=m)
    )
    inside = interior(gt)
    plain = np.asarray(f(jnp.asarray(gt), 0.0))
    kept = np.asarray(f(jnp.asarray(gt), 0.1))
    # without a margin the parabola vertex moves the exact values by a few thousandths;
    # with it 93 % of the interior keeps them (measured)
    assert np.mean(plain[inside] != gt[inside]) > 0.5
    assert np.mean(kept[inside] == gt[inside]) > 0.9
    # margin 0 is the default (eager against jit: rounding only)
    eager = photo_sweep(jnp.asarray(gt), lf.centre_view, views, offsets, steps=5, search=0.2)
    np.testing.assert_allclose(np.asarray(eager), plain, rtol=0, atol=1e-6)
    # a 0.06 offset: corrected where the gain is significant (measured: 55 % of the interior
    # closer, against 82 % without a margin; fewer pixels worse than the input, 2 % vs 4 %)
    off = np.asarray(f(jnp.asarray(gt + 0.06), 0.1))
    err = np.abs(off - gt)[inside]
    assert np.mean(err < 0.0599) > 0.5 and np.mean(err > 0.065) < 0.03, (
        np.mean(err < 0.0599),
        np.mean(err > 0.065),
    )
    # a margin of 1 asks for a zero cost: nothing moves
    np.testing.assert_array_equal(np.asarray(f(jnp.asarray(gt + 0.06), 1.0)), gt + 0.06)


def test_photo_sweep_depth_aware_support(small_scene):
    """With ``support_jump``, window pixels across a depth discontinuity of the input do not
    enter a pixel's aggregated cost: near the depth edges of a map off by 0.06 (7×7 windows
    spanning more than 0.1 px/view step, not interior) fewer pixels end more than 0.07 off
    (measured, aggregation radius 4: 9.5 % against 11.3 %); inside the surfaces nothing
    changes; a jump above the disparity range is the plain aggregation."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = np.asarray(lf.centre_gt)
    f = jax.jit(
        lambda d, sj: photo_sweep(
            d, lf.centre_view, views, offsets, steps=5, search=0.2, aggregate=4, support_jump=sj
        )
    )
    plain = np.asarray(
        photo_sweep(
            jnp.asarray(gt + 0.06), lf.centre_view, views, offsets, steps=5, search=0.2, aggregate=4
        )
    )
    inside = interior(gt)
    span = grey_dilation(gt, size=(7, 7)) + grey_dilation(-gt, size=(7, 7))
    band = (span > 0.1) & ~inside
    assert band.mean() > 0.1
    bad = {sj: np.abs(np.asarray(f(jnp.asarray(gt + 0.06), sj)) - gt) > 0.07 for sj in (0.1, 1e9)}
    bad_plain = np.abs(plain - gt) > 0.07
    np.testing.assert_allclose(np.asarray(f(jnp.asarray(gt + 0.06), 1e9)), plain, atol=1e-6)
    assert bad[0.1][band].mean() < bad_plain[band].mean() - 0.01, (
        bad[0.1][band].mean(),
        bad_plain[band].mean(),
    )
    assert abs(bad[0.1][inside].mean() - bad_plain[inside].mean()) < 0.005


def test_photo_sweep_keeps_the_value_when_the_optimum_is_out_of_range(small_scene):
    """0.5 off with ``search = 0.1``: the cost falls towards the end of the range, so the
    pixels keep their value."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    d = np.asarray(lf.centre_gt) - 0.5
    out = np.asarray(photo_sweep(jnp.asarray(d), lf.centre_view, views, offsets, search=0.1))
    inside = interior(lf.centre_gt)
    assert np.mean(out[inside] == d[inside]) > 0.9
    assert np.all(np.abs(out - d) <= 0.1 + 1e-5)


def test_photo_sweep_gradient_matches_finite_differences(small_scene, x64):
    """Where the chosen hypothesis does not change, the swept map is differentiable in the
    input map (identity plus the parabola vertex's dependence on the warped colours):
    forward-mode derivative against central differences along a random direction (float64;
    pixels whose choice flips within ±eps are the few that disagree)."""
    lf, _, _ = small_scene
    ref = jnp.asarray(lf.centre_view, jnp.float64)
    views, offsets = (jnp.asarray(a, jnp.float64) for a in cross_hair(lf))
    gt = jnp.asarray(lf.centre_gt, jnp.float64)
    d0 = gt + 0.03
    v = jnp.asarray(np.random.default_rng(0).normal(size=gt.shape))

    def f(d):
        return photo_sweep(d, ref, views, offsets, steps=5, search=0.2)

    _, tangent = jax.jvp(f, (d0,), (v,))
    eps = 1e-6
    fd = (np.asarray(f(d0 + eps * v)) - np.asarray(f(d0 - eps * v))) / (2 * eps)
    tangent = np.asarray(tangent)
    inside = interior(gt)
    close = np.abs(fd - tangent) <= 1e-3 * np.abs(tangent) + 1e-3
    assert np.mean(close[inside]) > 0.98, np.mean(close[inside])
    # the vertex term is present: the derivative is not the identity everywhere
    assert np.mean(np.abs(tangent - np.asarray(v))[inside] > 1e-3) > 0.2


def test_photo_sweep_bad_steps(small_scene):
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    for steps in (1, 4):
        with pytest.raises(ValueError, match="odd integer"):
            photo_sweep(lf.centre_gt, lf.centre_view, views, offsets, steps=steps)
    with pytest.raises(ValueError, match="sweep_steps"):
        SharpenConfig(sweep_steps=4)


@pytest.mark.parametrize("radius", [1, 2, 3])
def test_window_extrema_match_grey_morphology(radius):
    """The separable window minimum and maximum equal SciPy's grey erosion and dilation
    over the ``(2 radius + 1)²`` window with an edge-replicated border, on a non-square map
    with ties."""
    rng = np.random.default_rng(radius)
    d = np.round(rng.normal(size=(23, 37)), 1).astype(np.float32)
    lo, hi = _window_extrema(jnp.asarray(d), radius)
    k = 2 * radius + 1
    np.testing.assert_array_equal(np.asarray(lo), grey_erosion(d, size=(k, k), mode="nearest"))
    np.testing.assert_array_equal(np.asarray(hi), grey_dilation(d, size=(k, k), mode="nearest"))
