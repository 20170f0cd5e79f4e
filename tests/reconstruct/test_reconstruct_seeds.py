"""Photo-consistent samples of the centre diffusion where no edge label is near."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reconstruct_helpers import cross_hair, interior
from scipy.ndimage import grey_dilation

from mvedge_jax.reconstruct import (
    CentreConfig,
    ReconstructConfig,
    SeedConfig,
    centre_disparity,
    photo_seeds,
)
from mvedge_jax.solve import SolverConfig


def test_photo_seeds_recover_textured_surfaces(small_scene):
    """No labels anywhere: inside the textured surfaces of the synthetic scene most pixels get
    a sample, close to the truth (hypotheses 0.05 apart, parabola vertex, 2× reduced
    sweep). Measured: 99.9 % of the interior sampled, median error 0.015, 1.5 % above 0.1
    (largest 0.19)."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = np.asarray(lf.centre_gt)
    none = jnp.zeros(gt.shape, bool)
    value, valid = photo_seeds(lf.centre_view, views, offsets, none, -1.2, 1.2, steps=49)
    value, valid = np.asarray(value), np.asarray(valid)
    inside = interior(gt)
    assert inside.mean() > 0.4
    assert valid[inside].mean() > 0.8, valid[inside].mean()
    err = np.abs(value - gt)[inside & valid]
    assert np.median(err) < 0.03 and np.mean(err > 0.1) < 0.04, (np.median(err), err.max())
    assert err.max() < 0.3


def test_photo_seeds_keep_away_from_labels(small_scene):
    """No sample within ``min_distance`` (chessboard) of a labelled pixel."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    support = np.zeros((64, 64), bool)
    support[::16, ::16] = True
    _, valid = photo_seeds(
        lf.centre_view, views, offsets, jnp.asarray(support), -1.2, 1.2, min_distance=4
    )
    near = grey_dilation(support, size=(9, 9))
    valid = np.asarray(valid)
    assert not valid[near].any()
    assert valid[~near].mean() > 0.5


def test_photo_seeds_near_labels_take_surfaces_behind_them(small_scene):
    """Within ``min_distance`` of the support, ``support_values`` admit the samples that are
    farther than every label value within that distance by more than ``behind_jump``, and
    only those."""
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    gt = np.asarray(lf.centre_gt)
    support = np.zeros((64, 64), bool)
    support[::16, ::16] = True
    args = (lf.centre_view, views, offsets, jnp.asarray(support), -1.2, 1.2)
    # Every pixel's best hypothesis and whether it is distinct: no support at all.
    none = jnp.zeros((64, 64), bool)
    free, free_ok = (np.asarray(a) for a in photo_seeds(*args[:3], none, *args[4:]))
    _, away = photo_seeds(*args, min_distance=4)
    near = grey_dilation(support, size=(9, 9))
    # Label values far nearer than the scene (3.0 against at most 1): near every label
    # the samples farther by more than 1 come back; none of those within 1 of the labels.
    nearer = jnp.full((64, 64), 3.0)
    for jump, expect in ((1.0, free < 2.0), (3.5, free < -0.5), (10.0, np.zeros_like(near))):
        _, valid = photo_seeds(*args, min_distance=4, support_values=nearer, behind_jump=jump)
        valid = np.asarray(valid)
        np.testing.assert_array_equal(valid[~near], np.asarray(away)[~near])
        np.testing.assert_array_equal(valid[near], (free_ok & expect)[near])
    assert (free_ok & (free < -0.5))[near].any() and not (free_ok & (free < -0.5))[near].all()
    # The labels' own values (the scene's truth): a label's value bounds the window, so
    # with a jump of 0 a sample near it must be farther than the nearest-valued label.
    truth = jnp.asarray(gt)
    _, valid = photo_seeds(*args, min_distance=4, support_values=truth, behind_jump=0.0)
    lowest = -grey_dilation(np.where(support, -gt, -np.inf), size=(9, 9))
    np.testing.assert_array_equal(np.asarray(valid)[near], (free_ok & (free < lowest))[near])


def test_photo_seeds_refuse_uniform_colour_and_repeated_texture(small_scene):
    """Uniform colour: every hypothesis costs the same, no sample. A texture that repeats
    every 8 px horizontally: hypotheses 2 px per view step apart fit equally, no sample."""
    lf, _, _ = small_scene
    _, offsets = cross_hair(lf)
    K = offsets.shape[0]
    grey = jnp.full((64, 64, 3), 0.4)
    none = jnp.zeros((64, 64), bool)
    _, valid = photo_seeds(grey, jnp.stack([grey] * K), offsets, none, -3.0, 3.0)
    assert not np.asarray(valid).any()
    # a horizontal period of 8 px and disparity 1: the horizontal views match at
    # d = 1 and d = 1 ± 4 (shifts by a whole period for offsets ±2) — with the vertical
    # views constant along y, only the horizontal views decide.
    x = np.arange(64, dtype=np.float32)
    u = np.array([int(o[1]) for o in np.asarray(offsets)])

    def stripes(shift):
        row = 0.5 + 0.3 * np.sin(2 * np.pi * (x - shift) / 8.0)
        return np.repeat(np.repeat(row[None, :, None], 64, 0), 3, 2)

    ref = jnp.asarray(stripes(0.0))
    others = jnp.asarray(np.stack([stripes(1.0 * uu) for uu in u]))
    _, valid = photo_seeds(ref, others, offsets, none, -5.0, 5.0, steps=81, exclusion=0.8)
    assert np.asarray(valid).mean() < 0.05


def test_photo_seeds_bad_arguments(small_scene):
    lf, _, _ = small_scene
    views, offsets = cross_hair(lf)
    none = jnp.zeros((64, 64), bool)
    with pytest.raises(ValueError, match="steps"):
        photo_seeds(lf.centre_view, views, offsets, none, -1.0, 1.0, steps=2)
    with pytest.raises(ValueError, match="scale"):
        photo_seeds(lf.centre_view, views, offsets, none, -1.0, 1.0, scale=0)
    with pytest.raises(ValueError, match="steps"):
        SeedConfig(steps=2)
    with pytest.raises(ValueError, match="ratio"):
        SeedConfig(ratio=1.5)


def test_seeds_enter_the_centre_diffusion(small_scene):
    """Labels only in the left half: the right half takes the diffused labels, unless
    samples are given there. Weight 0 leaves the map unchanged; a shape mismatch is an
    error naming ``seeds``."""
    lf, edges, surface = small_scene
    gt = np.asarray(lf.centre_gt)
    keep = jnp.asarray(np.asarray(edges.x) < 24) & edges.valid
    left = eqx.tree_at(lambda e: e.valid, edges, keep)
    cfg = ReconstructConfig()
    plain = np.asarray(centre_disparity(left, surface, lf.centre_view, cfg))
    right = np.zeros_like(gt)
    right[:, 40:] = 1.0
    zero = (jnp.zeros_like(jnp.asarray(gt)), jnp.asarray(gt))
    same = np.asarray(centre_disparity(left, surface, lf.centre_view, cfg, zero))
    np.testing.assert_allclose(same, plain, atol=1e-5)
    seeded = np.asarray(
        centre_disparity(left, surface, lf.centre_view, cfg, (10.0 * right, jnp.asarray(gt)))
    )
    region = interior(gt) & (right > 0)
    err_plain = np.abs(plain - gt)[region].mean()
    err_seeded = np.abs(seeded - gt)[region].mean()
    assert err_seeded < 0.5 * err_plain, (err_seeded, err_plain)
    with pytest.raises(ValueError, match="seeds"):
        centre_disparity(left, surface, lf.centre_view, cfg, (jnp.zeros((3, 3)), gt))


def test_seed_weight_gradient_matches_finite_differences(small_scene, x64):
    """The centre map is a linear solve in the seed weight: reverse-mode derivative (through
    the solver's custom VJP) of a weighted sum against central differences (float64, solver
    to a 1e-12 residual)."""
    lf, edges, surface = small_scene
    edges = jax.tree.map(lambda a: a.astype(jnp.float64) if a.dtype == jnp.float32 else a, edges)
    surface = jax.tree.map(
        lambda a: a.astype(jnp.float64) if a.dtype == jnp.float32 else a, surface
    )
    img = jnp.asarray(lf.centre_view, jnp.float64)
    gt = jnp.asarray(lf.centre_gt, jnp.float64)
    mask = jnp.zeros(gt.shape).at[:, 40:].set(1.0)
    w = jnp.asarray(np.random.default_rng(1).normal(size=gt.shape))
    tight = SolverConfig(rtol=1e-12, max_iters=5000)
    cfg = ReconstructConfig(centre=CentreConfig(solver=tight))

    def f(weight):
        d = centre_disparity(edges, surface, img, cfg, (weight * mask, gt + 0.2))
        return jnp.sum(w * d)

    x0 = jnp.asarray(3.0, jnp.float64)
    ad = float(jax.grad(f)(x0))
    h = 1e-5
    fd = (float(f(x0 + h)) - float(f(x0 - h))) / (2 * h)
    assert ad != 0.0
    assert abs(ad - fd) <= 1e-4 * max(abs(ad), abs(fd)), (ad, fd)
