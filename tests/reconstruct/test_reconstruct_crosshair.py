"""Cross-hair projection (z-buffer, holes), EPI line rasterisation, angular inpainting and
the hole fills."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.reconstruct import (
    EpiConfig,
    FillConfig,
    ReconstructConfig,
    background_fill,
    colour_fill,
    fill_beyond_frame,
    inpaint_epis,
    photometric_confidence,
    project_cross_hair,
    rasterise_lines,
)
from mvedge_jax.reconstruct._reconstruct import _fill_views


def _square_scene(H=32, W=40, d_bg=-0.5, d_fg=2.0):
    d = np.full((H, W), d_bg, np.float32)
    d[10:21, 15:26] = d_fg
    return d


def test_project_cross_hair_zbuffer_and_holes():
    centre = jnp.asarray(_square_scene())
    ph, vh, pv, vv = jax.jit(project_cross_hair, static_argnums=1)(centre, (5, 5))
    assert ph.shape == (5, 32, 40) and pv.shape == (5, 32, 40)
    # The centre view is reproduced exactly.
    np.testing.assert_array_equal(ph[2], centre)
    np.testing.assert_array_equal(pv[2], centre)
    # View (2, 4): dc = 2; the square moves by -4 px, the background by +1 px.
    p, v = np.asarray(ph[4]), np.asarray(vh[4])
    np.testing.assert_array_equal(p[15, 11:22], 2.0)  # square, incl. where it covers background
    assert not v[15, 22:27].any()  # disocclusion to the right of the square
    assert v[15, 27] and p[15, 27] == -0.5
    # View (4, 2): dr = 2; the square moves up by 4 px: its bottom rows leave a hole.
    p, v = np.asarray(pv[4]), np.asarray(vv[4])
    np.testing.assert_array_equal(p[6:17, 20], 2.0)
    assert not v[17:22, 20].any()


def _epi_scene(L=64, A=9, d_fg=1.3, lo=20, hi=35, seed=0):
    """One EPI: a textured background (d=0) and a uniformly coloured foreground strip."""
    rng = np.random.default_rng(seed)
    tex = rng.uniform(0.2, 0.8, (L + 40, 3)).astype(np.float32)
    a = np.arange(A)[:, None] - A // 2
    x = np.arange(L)[None, :]
    xc = x + a * d_fg  # centre-view position of a foreground point seen at x
    fg = (xc >= lo) & (xc <= hi)
    colour = np.where(fg[..., None], np.array([0.9, 0.1, 0.1], np.float32), tex[x + 20])
    disp = np.where(fg, d_fg, 0.0).astype(np.float32)
    return colour.astype(np.float32), disp


def test_inpainting_fills_disocclusion_with_background():
    A, L = 9, 64
    colour, truth = _epi_scene(L, A)
    centre_row = np.tile(truth[A // 2][None], (3, 1))  # (3, L) map: the row, repeated
    ph, vh, _, _ = project_cross_hair(jnp.asarray(centre_row), (3, A))
    proj, valid = ph[:, 1][None], vh[:, 1][None]  # (1, A, L) EPI stack
    holes = ~np.asarray(valid[0])
    assert holes.sum() > 20  # disocclusions exist
    guide = jnp.asarray(colour)[None]
    zeros = jnp.zeros((1, A, L))
    # Photometric confidence of the reprojection: the colour each pixel should have, from the
    # centre row. Sub-pixel rounding puts some foreground values on background pixels.
    off = jnp.stack([jnp.zeros(A), jnp.arange(A) - A // 2], axis=1)
    conf = photometric_confidence(
        proj[0][:, None], off, jnp.asarray(colour[A // 2])[None], jnp.asarray(colour)[:, None], 0.1
    )[:, 0][None]
    cfg = ReconstructConfig()
    plain = np.asarray(inpaint_epis(proj, valid, guide, zeros, zeros, cfg)[0])
    out = np.asarray(inpaint_epis(proj, valid, guide, zeros, zeros, cfg, conf)[0])
    err, err_plain = np.abs(out - truth), np.abs(plain - truth)
    # Measured: hole error max 0.28 / mean 0.12 (foreground label 1.3, background 0); without
    # the photometric confidence 0.99 / 0.41 (rounded foreground values leak into the holes
    # along the angular axis, where the background texture is constant).
    assert err[holes].max() < 0.35, err[holes].max()
    assert err[holes].mean() < 0.15, err[holes].mean()
    assert err_plain[holes].mean() > 2 * err[holes].mean()
    assert np.mean(err > 0.07) < 0.06, np.mean(err > 0.07)


def test_epi_lines_carry_labels_the_centre_never_saw():
    # A region with no reprojected data at all: only an EPI line labels it.
    A, L = 9, 48
    proj = jnp.zeros((1, A, L))
    valid = jnp.zeros((1, A, L), bool).at[0, :, :10].set(True)
    # Two colour regions: the reprojected one (x < 12) and the unseen one.
    guide = jnp.where(jnp.arange(L)[None, None, :, None] < 12, 0.2, 0.8) * jnp.ones((1, A, L, 3))
    lw, ll = rasterise_lines(
        jnp.asarray([0.0]), jnp.asarray([30.0]), jnp.asarray([0.8]), jnp.asarray([1.0]), (1, A, L)
    )
    # The line passes x = 30 - (a - 4) * 0.8 in every angular row.
    for a in range(A):
        xs = 30 - (a - 4) * 0.8
        assert float(lw[0, a, int(np.floor(xs))]) > 0
        assert float(ll[0, a, int(np.floor(xs))]) == pytest.approx(0.8)
    cfg = ReconstructConfig(epi=EpiConfig(hole_weight=0.0))
    out = np.asarray(inpaint_epis(proj, valid, guide, lw, ll, cfg)[0])
    assert abs(out[4, 30] - 0.8) < 0.1, out[4, 30]  # measured 0.73
    assert abs(out[4, 0]) < 0.05


def test_rasterise_lines_drops_outside_points():
    lw, ll = rasterise_lines(
        jnp.asarray([5.0, 0.0]),
        jnp.asarray([10.0, 3.0]),
        jnp.asarray([0.0, 0.0]),
        jnp.asarray([1.0, 2.0]),
        (2, 3, 16),
    )
    assert float(lw.sum()) == 3 * 2.0  # the first point's EPI index is out of range
    np.testing.assert_allclose(np.asarray(lw[0, :, 3]), 2.0)


def test_background_fill_prefers_the_farther_side():
    v = jnp.asarray([[2.0, 2.0, 0.0, 0.0, -1.0, -1.0]])
    ok = jnp.asarray([[True, True, False, False, True, True]])
    np.testing.assert_allclose(background_fill(v, ok), [[2.0, 2.0, -1.0, -1.0, -1.0, -1.0]])


def _hidden_square_view():
    """Far background (d = -1, blue) on row 0; below it a mid-depth square (d = 1, yellow) on
    the left and a near surface (d = 3, red) on the right, with a yellow hole between them:
    the part of the square that the near surface hid in the centre view."""
    blue, yellow, red = (0.1, 0.2, 0.9), (0.9, 0.8, 0.1), (0.8, 0.1, 0.1)
    v = np.full((5, 6), -1.0, np.float32)
    g = np.empty((5, 6, 3), np.float32)
    g[:] = blue
    v[1:, :2], g[1:, :2] = 1.0, yellow
    v[1:, 2:4], g[1:, 2:4] = 0.0, yellow
    v[1:, 4:], g[1:, 4:] = 3.0, red
    ok = np.ones((5, 6), bool)
    ok[1:, 2:4] = False
    return v, ok, g


def test_colour_fill_takes_the_surface_the_hole_shows():
    v, ok, g = _hidden_square_view()
    out = np.asarray(jax.jit(colour_fill)(v, ok, g))
    np.testing.assert_array_equal(out[ok], v[ok])
    np.testing.assert_allclose(out[1:, 2:4], 1.0)  # the square, by colour
    # The farthest neighbour is the background above the square.
    np.testing.assert_allclose(np.asarray(background_fill(jnp.asarray(v), ok))[1:, 2:4], -1.0)


def test_colour_fill_breaks_colour_ties_towards_the_farthest():
    rng = np.random.default_rng(0)
    v = rng.uniform(-2, 2, (12, 9)).astype(np.float32)
    ok = rng.random((12, 9)) > 0.6
    flat = np.full((12, 9, 3), 0.5, np.float32)
    np.testing.assert_allclose(
        colour_fill(v, ok, flat), background_fill(jnp.asarray(v), jnp.asarray(ok))
    )
    stack = jax.vmap(colour_fill)(jnp.stack([v, v]), jnp.stack([ok, ok]), jnp.stack([flat, flat]))
    np.testing.assert_allclose(stack[1], background_fill(jnp.asarray(v), jnp.asarray(ok)))


def test_colour_fill_margin_falls_back_to_the_farthest():
    # The hole (yellow) matches the square to its left exactly (L1 distance 0); the farthest
    # candidate, the blue background above it, is 2.2 away in colour.
    v, ok, g = _hidden_square_view()
    fill = jax.jit(colour_fill)
    np.testing.assert_allclose(fill(v, ok, g, 2.1)[1:, 2:4], 1.0)
    np.testing.assert_allclose(fill(v, ok, g, 2.3)[1:, 2:4], -1.0)
    np.testing.assert_array_equal(fill(v, ok, g, np.inf), background_fill(jnp.asarray(v), ok))
    # The margin is traced: one compilation for every value, also under vmap.
    stack = jax.vmap(colour_fill, (None, None, None, 0))(v, ok, g, jnp.asarray([0.0, 3.0]))
    np.testing.assert_allclose(stack[:, 2, 2], [1.0, -1.0])
    with pytest.raises(ValueError, match="margin"):
        colour_fill(v, ok, g, -0.1)


def test_colour_fill_margin_is_stable_where_the_farthest_values_tie():
    # A hole between four valid pixels: two farthest values (0.0) of colour distance 0.3 and
    # 1.0, and a nearer one (2.0) at distance 0.1. The margin counts from the tie's nearer
    # colour (0.3) whichever of the two is a hair farther.
    v = np.array([[9, 0.0, 9], [2.0, 0, 0.0], [9, 5.0, 9]], np.float32)
    ok = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], bool)
    g = np.zeros((3, 3, 3), np.float32)
    g[0, 1, 0], g[1, 2, 0], g[1, 0, 0], g[2, 1, 0] = 0.3, 1.0, 0.1, 2.0
    for eps in (0.0, 1e-6, -1e-6):
        w = v.copy()
        w[1, 2] += eps
        assert float(colour_fill(w, ok, g, 0.15)[1, 1]) == 2.0  # 0.1 < 0.3 - 0.15
        assert float(colour_fill(w, ok, g, 0.25)[1, 1]) == pytest.approx(min(0.0, eps))


def test_colour_fill_rejects_bad_shapes():
    v, ok, g = _hidden_square_view()
    with pytest.raises(ValueError, match="values must have shape"):
        colour_fill(v[None], ok, g)
    with pytest.raises(ValueError, match="guide"):
        colour_fill(v, ok, g[:3])
    with pytest.raises(ValueError, match="valid"):
        colour_fill(v, ok[:3], g)


def _wall_above_object(H=16, W=10, wall=-3.0):
    """A view two steps below the centre (offset (2, 0)): a far wall above a near object (1)
    from row 6 down. Rows 0-5 are holes (the wall there lies beyond the centre frame: its
    point is 6 rows higher in the centre view), filled as a 2-D fill along the rows and
    columns leaves them when the wall's own pixels are out of reach: rows 0-4 the wall, row 5
    the object below it."""
    filled = np.full((H, W), 1.0, np.float32)
    filled[:5] = wall
    valid = np.ones((H, W), bool)
    valid[:6] = False
    return filled, valid


def test_fill_beyond_frame_gives_border_holes_the_far_surface():
    filled, valid = _wall_above_object()
    below = jnp.array([2.0, 0.0])
    out = np.asarray(jax.jit(fill_beyond_frame)(filled, valid, below))
    expected = filled.copy()
    expected[5] = -3.0  # the hole row next to the object: the wall, 5 + 2 * -3 < -0.5
    np.testing.assert_array_equal(out, expected)
    # Seen from a view two steps above the centre, the wall would lie at row 5 - 2 * -3 =
    # 11 of the centre view, inside its frame (and inside it along the columns, which a
    # swapped offset would test): the centre could have seen it, no change.
    up = np.asarray(fill_beyond_frame(filled, valid, jnp.array([-2.0, 0.0])))
    np.testing.assert_array_equal(up, filled)
    # The margin: -3 is 4 farther than the hole's 1; the test is strict.
    np.testing.assert_array_equal(fill_beyond_frame(filled, valid, below, 4.0), filled)
    np.testing.assert_array_equal(fill_beyond_frame(filled, valid, below, 3.99), expected)
    np.testing.assert_array_equal(fill_beyond_frame(filled, valid, below, 1e9), filled)


def test_fill_beyond_frame_runs_from_every_border():
    # The same scene turned so that the holes reach the bottom, left and right borders.
    filled, valid = _wall_above_object()
    expected = filled.copy()
    expected[5] = -3.0
    cases = [
        (lambda a: a[::-1], (-2.0, 0.0)),  # wall below the object, view above the centre
        (lambda a: a.T, (0.0, 2.0)),  # wall left of the object, view right of the centre
        (lambda a: a.T[:, ::-1], (0.0, -2.0)),  # wall on the right, view left of the centre
    ]
    for turn, offset in cases:
        out = fill_beyond_frame(turn(filled), turn(valid), jnp.array(offset))
        np.testing.assert_array_equal(out, turn(expected), err_msg=str(offset))
        # The opposite view: the wall's point lands inside the centre frame.
        back = fill_beyond_frame(turn(filled), turn(valid), -jnp.array(offset))
        np.testing.assert_array_equal(back, turn(filled), err_msg=str(offset))


def test_fill_beyond_frame_runs_along_the_views_displacement_only():
    # The right border column is a hole from top to bottom: the wall (-3) in rows 0-4, a
    # floor (-1) below, the holes filled with their row's value. Seen from a view two steps
    # left of the centre, every value of that column lies beyond the centre's right border
    # (9 - 2 * v > 9.5), so the column's run (its farthest value, the wall) would pass the
    # test on the floor's rows. On the centre row (dr = 0) only the row runs count: the
    # floor's run along its row is its own value, no change. Off the cross-hair the column
    # run counts too.
    H, W = 12, 10
    filled = np.full((H, W), -1.0, np.float32)
    filled[:5] = -3.0
    valid = np.ones((H, W), bool)
    valid[:, -1] = False
    out = np.asarray(fill_beyond_frame(filled, valid, jnp.array([0.0, -2.0])))
    np.testing.assert_array_equal(out, filled)
    diagonal = np.asarray(fill_beyond_frame(filled, valid, jnp.array([2.0, -2.0])))
    expected = filled.copy()
    expected[:, -1] = -3.0
    np.testing.assert_array_equal(diagonal, expected)


def test_fill_beyond_frame_half_pixel_past_the_frame():
    # One step below the centre: row 5's wall point lies at 5 - 5.25 = -0.25, within half a
    # pixel of the frame (a centre pixel still sees it), or at 5 - 5.75 = -0.75, beyond.
    for wall, changes in ((-5.25, False), (-5.75, True)):
        filled, valid = _wall_above_object(wall=wall)
        out = np.asarray(fill_beyond_frame(filled, valid, jnp.array([1.0, 0.0])))
        np.testing.assert_array_equal(out[5], wall if changes else filled[5])
        np.testing.assert_array_equal(out[:5], filled[:5])


def test_fill_beyond_frame_leaves_enclosed_holes_and_valid_pixels():
    filled, valid = _wall_above_object()
    valid[0] = True  # the runs no longer reach the top border; rows and columns: none
    out = np.asarray(fill_beyond_frame(filled, valid, jnp.array([2.0, 0.0])))
    np.testing.assert_array_equal(out, filled)
    # Valid pixels keep their values even where a run's value would pass the tests.
    f = np.full((4, 10), 2.0, np.float32)
    f[:, :3] = -2.0
    ok = np.ones((4, 10), bool)
    ok[:, :4] = False
    out = np.asarray(fill_beyond_frame(f, ok, jnp.array([0.0, 2.0])))
    np.testing.assert_array_equal(out[:, 3], -2.0)  # 3 + 2 * -2 < -0.5
    np.testing.assert_array_equal(out[:, 4:], f[:, 4:])
    np.testing.assert_array_equal(out[:, :3], f[:, :3])


def test_fill_beyond_frame_is_a_selection_differentiable_in_the_values():
    filled, valid = _wall_above_object()
    # Distinct values, 0.003 apart: no selection switches within the difference step.
    filled = filled + 0.003 * np.random.default_rng(0).permutation(filled.size).reshape(
        filled.shape
    ).astype(np.float32)
    f = lambda x: fill_beyond_frame(x, valid, jnp.array([2.0, 0.0]))  # noqa: E731
    check_grads(f, (jnp.asarray(filled, jnp.float32),), order=1, modes=("fwd", "rev"), eps=1e-4)
    other = filled[::-1].copy()
    stacked = jax.vmap(f)(jnp.stack([filled, other]))
    np.testing.assert_array_equal(stacked[0], f(filled))
    np.testing.assert_array_equal(stacked[1], f(other))


def test_fill_beyond_frame_rejects_bad_input():
    filled, valid = _wall_above_object()
    with pytest.raises(ValueError, match="filled must have shape"):
        fill_beyond_frame(filled[None], valid, jnp.zeros(2))
    with pytest.raises(ValueError, match="floating"):
        fill_beyond_frame(filled.astype(np.int32), valid, jnp.zeros(2))
    with pytest.raises(ValueError, match="valid"):
        fill_beyond_frame(filled, valid[:3], jnp.zeros(2))
    with pytest.raises(ValueError, match="offset"):
        fill_beyond_frame(filled, valid, jnp.zeros(3))
    with pytest.raises(ValueError, match="margin"):
        fill_beyond_frame(filled, valid, jnp.zeros(2), -1.0)


def test_fill_views_applies_fill_beyond_frame_with_the_views_offset():
    # View (2, 0) of a 3x3 grid, one step below and one left of the centre. Holes fill the
    # top-right corner (rows 0-5, columns 4-9) up to the top and right borders; the far
    # wall (-3) is valid left of them in rows 0-4, the near object (1) in row 5 and below.
    # The 2-D fill gives rows 0-4 the wall and row 5 the object. Row 5's wall point lies at
    # (5 - 3, x + 3) in the centre view: beyond its right border for x >= 7 only.
    H, W = 12, 10
    values = np.full((H, W), 1.0, np.float32)
    values[:5, :4] = -3.0
    conf = np.ones((H, W), np.float32)
    conf[:6, 4:] = 0.0
    guides = np.zeros((3, 3, H, W, 3), np.float32)
    config = ReconstructConfig(fill=FillConfig(hole_fill="background"))
    rows, cols = jnp.array([2], jnp.int32), jnp.array([0], jnp.int32)
    out, residual = _fill_views(
        jnp.asarray(values)[None],
        jnp.asarray(conf)[None],
        jnp.asarray(guides),
        jnp.ones((3, 3), bool),
        rows,
        cols,
        config,
    )
    assert residual is None
    expected = values.copy()
    expected[:5, 4:] = -3.0
    expected[5, 4:] = 1.0
    expected[5, 7:] = -3.0
    np.testing.assert_array_equal(out[0], expected)
    valid = conf > config.fill.min_confidence
    two_d = colour_fill(values, valid, guides[2, 0], config.fill.colour_margin)
    np.testing.assert_array_equal(
        out[0], fill_beyond_frame(two_d, valid, jnp.array([1.0, -1.0]), config.fill.frame_margin)
    )
