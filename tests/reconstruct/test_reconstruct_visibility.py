"""Visibility test of the cross-hair hole fill (`contradicted_by_centre`,
``EpiConfig.visibility_fill``, ``EpiConfig.frame_margin``)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.reconstruct import (
    EpiConfig,
    ReconstructConfig,
    contradicted_by_centre,
    project_cross_hair,
)
from mvedge_jax.reconstruct._reconstruct import _cross_hair_fill


def test_contradicted_by_centre_hand_computed():
    """Centre: background 0, a foreground column block of disparity 1 at x >= 4. View two
    steps to the right (dc = 2): a value traced to ``x + 2 d``."""
    centre = jnp.zeros((3, 8)).at[:, 4:].set(1.0)
    off = jnp.array([0.0, 2.0])

    def at(x, d):
        cand = jnp.zeros((3, 8)).at[1, x].set(d)
        return bool(contradicted_by_centre(cand, centre, off, 0.2)[1, x])

    assert at(1, 0.0)  # traced to x = 1: the centre sees background there
    assert not at(1, -1.0)  # traced to x = -1: outside the centre's frame
    assert not at(2, 0.75)  # x = 3.5: pixel 4 (disparity 1 > 0.95) may hide it
    assert at(2, 0.25)  # x = 2.5: pixels 2 and 3 both show disparity 0 <= 0.45
    assert not at(3, 0.0)  # x = 3 exactly: pixel 4 is nearer
    assert at(1, 1.0)  # x = 3: pixel 4 shows this surface (1 <= 1.2): it would have landed
    assert at(2, 1.0)  # x = 4: likewise
    # The vertical offset traces rows the same way.
    c_t = centre.T
    cand = jnp.zeros((8, 3)).at[1, 1].set(-1.0)
    assert not bool(contradicted_by_centre(cand, c_t, jnp.array([2.0, 0.0]), 0.2)[1, 1])
    jitted = jax.jit(contradicted_by_centre)(cand, c_t, jnp.array([2.0, 0.0]), 0.2)
    assert jitted.shape == (8, 3) and jitted.dtype == jnp.bool_


@pytest.mark.parametrize("visibility", [False, True])
def test_frame_strip_takes_the_surface_from_outside(visibility):
    """Centre column of 5 views, centre map: background (disparity -2) in rows 0-3, a
    foreground (+1) from row 4. In view 4 (two steps down) the foreground moves up by 2 and
    the background down by 4, behind the foreground: rows 0-1 show background from above the
    centre's frame, and nothing is projected there. An inpainting that spreads the
    foreground into them is kept without the visibility test (the view's own background
    fill only sees the foreground below) and replaced by the background of the centre view's
    top rows with it. The bottom strip, foreground entering from below, keeps the
    foreground either way."""
    H, W, U = 12, 6, 5
    centre = jnp.full((H, W), -2.0).at[4:].set(1.0)
    _, _, pv, vv = project_cross_hair(centre, (U, 1))
    vv_np = np.asarray(vv)
    assert not vv_np[4, :2].any() and vv_np[4, 2:10].all() and not vv_np[4, 10:].any()
    maps = jnp.where(vv, pv, 1.0).at[U // 2].set(centre)
    offsets = jnp.stack([jnp.arange(U) - U // 2, jnp.zeros(U)], axis=1).astype(jnp.float32)
    config = dataclasses.replace(ReconstructConfig(), epi=EpiConfig(visibility_fill=visibility))
    # Flat colours: the fill's colour choice ties and takes the farthest value.
    guides = jnp.full(maps.shape + (3,), 0.5)
    out = np.asarray(
        _cross_hair_fill(maps, vv, jnp.ones_like(maps), U // 2, offsets, centre, guides, config)
    )
    np.testing.assert_array_equal(out[U // 2], np.asarray(centre))
    np.testing.assert_array_equal(out[4, 2:10], np.asarray(pv)[4, 2:10])
    np.testing.assert_array_equal(out[4, 10:], 1.0)
    np.testing.assert_array_equal(out[4, :2], -2.0 if visibility else 1.0)


@pytest.mark.parametrize("hole_value", ["farther", "fill"])
def test_hole_value_chooses_between_the_blend_and_the_fill(hole_value):
    """One row of 3 views (the centre is view 1). View 0: far background (disparity -3,
    black) in columns 0-2, a mid-depth surface (0, white) in columns 6-8, and a hole in
    columns 3-5 that shows the white surface, where the inpainting left a blend (-1.5). The
    colour fill finds the white surface (0); ``"farther"`` keeps the blend, ``"fill"`` takes
    the fill. Landed pixels and the centre view keep their values either way."""
    K, H, W = 3, 4, 9
    row = jnp.array([-3.0, -3.0, -3.0, -1.5, -1.5, -1.5, 0.0, 0.0, 0.0])
    maps = jnp.broadcast_to(row, (K, H, W))
    valid = jnp.ones((K, H, W), bool).at[0, :, 3:6].set(False)
    white = (jnp.arange(W) >= 3).astype(jnp.float32)
    guides = jnp.broadcast_to(white[None, None, :, None], (K, H, W, 3))
    offsets = jnp.stack([jnp.zeros(K), jnp.arange(K) - 1.0], axis=1)
    centre = jnp.full((H, W), 5.0)  # nearer than every candidate: nothing is contradicted
    config = dataclasses.replace(
        ReconstructConfig(), epi=EpiConfig(hole_value=hole_value, visibility_fill=False)
    )
    out = np.asarray(
        _cross_hair_fill(maps, valid, jnp.ones_like(maps), 1, offsets, centre, guides, config)
    )
    expected = np.asarray(maps).copy()
    expected[0, :, 3:6] = -1.5 if hole_value == "farther" else 0.0
    np.testing.assert_array_equal(out, expected)
    # With the visibility test the same values stand (the centre contradicts none of them).
    vis = dataclasses.replace(config, epi=EpiConfig(hole_value=hole_value))
    out_vis = _cross_hair_fill(maps, valid, jnp.ones_like(maps), 1, offsets, centre, guides, vis)
    np.testing.assert_array_equal(np.asarray(out_vis), expected)


def test_hole_value_is_checked():
    with pytest.raises(ValueError, match="hole_value"):
        EpiConfig(hole_value="nearest")


@pytest.mark.parametrize("fill_choice", ["colour", "farthest"])
@pytest.mark.parametrize("passes", [1, 2])
def test_second_pass_reaches_the_background_through_resolved_holes(passes, fill_choice):
    """One row of 3 views (the centre is view 1; view 0 is one step left, ``dc = -1``).
    Centre map: background (-2) in columns 0-2, foreground (+2) from column 3. View 0: a
    black disocclusion in columns 3-4 of every row, flanked by white foreground (+2) except
    in row 0, where the black background (-2) lies to its left. Row 0's holes take the
    background in the first pass. In rows 1-5 the first pass's candidates are all
    foreground (left, right, and the same pixel in the centre view), and the centre view
    contradicts each (traced to columns 1-2, where it sees the background): they keep the
    foreground with one pass; the second pass finds the resolved row 0 above them, which
    the centre view does not contradict (traced to columns 5-6, behind its foreground). The
    colour choice and the farthest value agree here. Views 1 and 2 have no holes."""
    K, H, W = 3, 6, 9
    centre = jnp.full((H, W), 2.0).at[:, :3].set(-2.0)
    view0 = jnp.full((H, W), 2.0).at[0, :3].set(-2.0)
    maps = jnp.stack([view0, centre, centre])
    valid = jnp.ones((K, H, W), bool).at[0, :, 3:5].set(False)
    black = jnp.zeros((H, W), bool).at[0, :3].set(True).at[:, 3:5].set(True)
    grey = jnp.where(black, 0.0, 1.0)
    guides = jnp.stack([grey, jnp.full((H, W), 0.5), jnp.full((H, W), 0.5)])[..., None]
    guides = jnp.broadcast_to(guides, (K, H, W, 3))
    offsets = jnp.stack([jnp.zeros(K), jnp.arange(K) - 1.0], axis=1)
    epi = EpiConfig(visibility_passes=passes, fill_choice=fill_choice)
    config = dataclasses.replace(ReconstructConfig(), epi=epi)
    out = np.asarray(
        _cross_hair_fill(maps, valid, jnp.ones_like(maps), 1, offsets, centre, guides, config)
    )
    expected = np.asarray(maps).copy()
    expected[0, 0, 3:5] = -2.0
    expected[0, 1:, 3:5] = -2.0 if passes == 2 else 2.0
    np.testing.assert_array_equal(out, expected)


@pytest.mark.parametrize("margin", [0.1, 1e9])
def test_frame_margin_gives_the_border_strip_the_far_surface(margin):
    """One row of 3 views (the centre is view 1; view 2 is one step right, ``dc = 1``). View
    2: row 0 holds the black far wall (-3) in columns 0-4 and the white object (+1) from
    column 5; in rows 1-3 columns 0-4 are holes that reach the left border, white-ish in
    columns 2-4 (a colour the 2-D fill matches to the object) and black in columns 0-1.
    The fill gives columns 0-1 the wall and columns 2-4 the object. ``epi.frame_margin``
    then gives column 2 the wall, the run's farthest value: its point lies at 2 - 3 = -1,
    beyond the centre frame. Columns 3-4 (points at 0 and 1, inside the frame) keep the
    object; 1e9 turns the rule off."""
    K, H, W = 3, 4, 10
    view2 = jnp.full((H, W), 1.0).at[0, :5].set(-3.0)
    centre = jnp.full((H, W), 5.0)  # nearer than every candidate: nothing is contradicted
    maps = jnp.stack([centre, centre, view2])
    valid = jnp.ones((K, H, W), bool).at[2, 1:, :5].set(False)
    grey = jnp.ones((H, W)).at[0, :5].set(0.0).at[1:, :2].set(0.0).at[1:, 2:5].set(0.9)
    guides = jnp.stack([jnp.full((H, W), 0.5), jnp.full((H, W), 0.5), grey])[..., None]
    guides = jnp.broadcast_to(guides, (K, H, W, 3))
    offsets = jnp.stack([jnp.zeros(K), jnp.arange(K) - 1.0], axis=1)
    config = dataclasses.replace(ReconstructConfig(), epi=EpiConfig(frame_margin=margin))
    out = np.asarray(
        _cross_hair_fill(maps, valid, jnp.ones_like(maps), 1, offsets, centre, guides, config)
    )
    expected = np.asarray(maps).copy()
    expected[2, 1:, :2] = -3.0
    expected[2, 1:, 2:5] = 1.0
    if margin < 1:
        expected[2, 1:, 2] = -3.0
    np.testing.assert_array_equal(out, expected)


def test_visibility_passes_is_checked():
    with pytest.raises(ValueError, match="visibility_passes"):
        EpiConfig(visibility_passes=0)
