"""`reconstruct`: the smooth 4D reconstruction end to end (thesis Ch. 6); `sharpen` and
`propagate`: its second half (a centre-view map → sharpened → every view)."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float

from .._fields import check_lower_bound
from .._jit import filter_jit_bound
from .._loop import map_where
from ..edges import EdgeSet
from ..lightfield import forward_project
from ..solve import guide_edge_weights, solve_poisson
from ._centre import (
    _check_inputs,
    colour_guide,
    label_positions,
    solve_centre,
    splat_bilinear,
)
from ._config import ReconstructConfig
from ._crosshair import (
    edge_lines,
    photometric_confidence,
    project_cross_hair,
    rasterise_lines,
    solve_epis,
)
from ._matte import (
    background_samples,
    boundary_matte,
    largest_jumps,
    near_surface_colours,
    pixel_subset,
    samples_to_frame,
    smooth_surface,
    split_candidates,
)
from ._photo import (
    _window_extrema,
    photo_refine,
    photo_seeds,
    photo_select,
    photo_sweep,
    remove_shading,
    shading_bias,
)
from ._wmf import disparity_slopes, weighted_mean_filter, weighted_median_filter

if TYPE_CHECKING:  # pragma: no cover
    from ..surface import SurfaceResult


class Reconstruction(eqx.Module):
    """Output of `reconstruct` (and `propagate`).

    Attributes:
        disparity: ``(U, V, H, W)`` float32 disparity of every view (pixels per view step).
        centre: ``(H, W)`` centre-view diffusion result (eq 6.1), before sharpening.
        centre_sharp: ``(H, W)`` after the weighted median filter (the projected map).
        cross_h: ``(V, H, W)`` centre row of views after angular inpainting.
        cross_v: ``(U, H, W)`` centre column of views after angular inpainting.
        solver_residual: the largest relative residual of each stage's linear solves
            (0-d arrays; NaN where a solve met non-finite values): ``"centre"`` (eq 6.1; not
            in `propagate`'s output), ``"epi"`` (eq 6.4, every EPI) and ``"fill"`` (the
            off-cross-hair hole filling; absent with ``fill.hole_fill = "background"`` or
            without off-cross-hair views). Compare with the stage's ``solver.rtol``.
    """

    disparity: Float[Array, "U V H W"]
    centre: Float[Array, "H W"]
    centre_sharp: Float[Array, "H W"]
    cross_h: Float[Array, "V H W"]
    cross_v: Float[Array, "U H W"]
    solver_residual: dict[str, Float[Array, ""]] = eqx.field(default_factory=dict)


def _nearest_index(valid: Array, axis: int, reverse: bool) -> tuple[Array, Array]:
    """Index of the nearest valid pixel before (or after, ``reverse``) each pixel on an axis
    (clipped into range) and whether there is one."""
    n = valid.shape[axis]
    shape = [1] * valid.ndim
    shape[axis] = n
    idx = jnp.arange(n, dtype=jnp.int32).reshape(shape)
    if reverse:
        near = lax.cummin(jnp.where(valid, idx, n), axis=axis, reverse=True)
        found = near < n
    else:
        near = lax.cummax(jnp.where(valid, idx, -1), axis=axis)
        found = near >= 0
    return jnp.clip(near, 0, n - 1), found


def _nearest_along(values: Array, valid: Array, axis: int, reverse: bool) -> tuple[Array, Array]:
    """Value of the nearest valid pixel before (or after, ``reverse``) each pixel on an axis."""
    near, found = _nearest_index(valid, axis, reverse)
    return jnp.take_along_axis(values, near, axis=axis), found


def _farthest_nearest(values: Array, valid: Array, axes: tuple[int, ...]) -> Array:
    """The smallest (farthest) of the nearest valid values before and after each pixel along
    each of ``axes``; ``inf`` where none of those rays meets a valid value."""
    big = jnp.asarray(jnp.inf, values.dtype)
    best = jnp.full(values.shape, big)
    for axis in axes:
        for reverse in (False, True):
            v, found = _nearest_along(values, valid, axis, reverse)
            best = jnp.minimum(best, jnp.where(found, v, big))
    return best


def background_fill(values: Float[Array, "H W"], valid: Bool[Array, "H W"]) -> Float[Array, "H W"]:
    """Fill holes with the farthest (smallest) of the nearest valid values left, right, above
    and below — disocclusions show the background. Pixels with no valid value on any of the
    four rays (an all-invalid map) stay 0."""
    best = _farthest_nearest(values, valid, (0, 1))
    best = jnp.where(jnp.isfinite(best), best, 0.0)
    return jnp.where(valid, values, best)


def merge_reprojections(
    cross_h: Float[Array, "V H W"],
    cross_v: Float[Array, "U H W"],
    views: Float[Array, "U V H W 3"],
    row: Array,
    col: Array,
    config: ReconstructConfig,
) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """Merge the reprojections of views ``(U//2, col)`` and ``(row, V//2)`` into view
    ``(row, col)`` (thesis Sec. 6.1, "Non-cross-hair View Reprojection").

    ``config.fill.merge == "mean"``: the mean where both land (the thesis); ``"photo"``: the mean
    weighted by each reprojection's `photometric_confidence` against view ``(row, col)``
    (occlusion-aware: a value whose colour does not match loses). Where only one lands, that
    one. Returns the merged map and its confidence (0 at holes; 1 or the best photometric
    confidence elsewhere).
    """
    U = cross_v.shape[0]
    V = cross_h.shape[0]
    rc, cc = U // 2, V // 2
    dr = (row - rc).astype(cross_h.dtype)
    dc = (col - cc).astype(cross_h.dtype)
    zero = jnp.zeros((), cross_h.dtype)
    off_a = jnp.stack([dr, zero])
    off_b = jnp.stack([zero, dc])
    cp = config.fill.crack_parallax
    a, va = forward_project(cross_h[col], off_a, crack_parallax=cp)
    b, vb = forward_project(cross_v[row], off_b, crack_parallax=cp)
    wa = va.astype(a.dtype)
    wb = vb.astype(a.dtype)
    if config.fill.merge == "photo":
        # A view missing from a partial grid (all zero) has no colour to compare with.
        present = jnp.max(views[row, col]) > 0
        target = views[row, col][None]
        sigma = config.epi.photo_sigma
        pa = photometric_confidence(a[None], off_a[None], views[rc, col], target, sigma)[0]
        pb = photometric_confidence(b[None], off_b[None], views[row, cc], target, sigma)[0]
        wa = jnp.where(present, wa * jnp.maximum(pa, 1e-6), wa)
        wb = jnp.where(present, wb * jnp.maximum(pb, 1e-6), wb)
    conf = jnp.maximum(wa, wb)
    n = wa + wb
    s = wa * jnp.where(va, a, 0.0) + wb * jnp.where(vb, b, 0.0)
    return jnp.where(n > 0, s / jnp.where(n > 0, n, 1.0), 0.0), conf


def _fill_views(values, conf, guides, present, rows, cols, config: ReconstructConfig):
    """Fill the holes of the merged off-cross-hair views.

    ``values``, ``conf``: ``(K, H, W)`` from `merge_reprojections` for the views
    ``(rows[k], cols[k])``; ``guides`` ``(U, V, H, W, C)``: every view's `colour_guide`;
    ``present`` ``(U, V)``: views that exist (a partial grid's missing views are all zero and
    keep the 2-D fill, with no solve). Returns ``(K, H, W)`` and the ``(K,)`` relative
    residuals of the solves (None with ``hole_fill = "background"``).
    """
    fc = config.fill
    # A merged value whose colour matches poorly was carried across a disocclusion, or is a
    # mixed pixel on a boundary: a hole.
    valid = conf > fc.min_confidence

    # One view at a time: the loop's inputs are the merge's materialised outputs, and the
    # guide of a view is sliced, not gathered for the whole stack (64 views of 512² RGB
    # would take another 200 MB). A view missing from a partial grid has an all-zero guide:
    # every candidate ties in colour and the 2-D fill is `background_fill` (then
    # `fill_beyond_frame`, as for every view).
    U, V = guides.shape[:2]

    def fill(f, v, r, col):
        filled = colour_fill(f, v, guides[r, col], fc.colour_margin)
        offset = jnp.stack([r - U // 2, col - V // 2]).astype(filled.dtype)
        return fill_beyond_frame(filled, v, offset, fc.frame_margin)

    if fc.hole_fill == "background":
        return lax.map(lambda a: fill(*a), (values, valid, rows, cols)), None

    def one(args):
        f, c, v, r, col = args
        filled = fill(f, v, r, col)
        lam = jnp.where(v, fc.data_weight * c, fc.hole_weight)
        wx, wy = guide_edge_weights(guides[r, col], scale=fc.c, eps=config.epi.eps)
        sol = solve_poisson(lam, filled, wx, wy, x0=filled, config=fc.solver)
        return (
            jnp.where(present[r, col], sol.x, filled),
            jnp.where(present[r, col], sol.residual, 0),
        )

    return lax.map(one, (values, conf, valid, rows, cols))


#: Values within this of the farthest (pixels per view step) tie with it in `colour_fill`.
_TIE = 1e-4


def colour_fill(
    values: Float[ArrayLike, "H W"],
    valid: Bool[ArrayLike, "H W"],
    guide: Float[ArrayLike, "H W C"],
    margin: float | Float[ArrayLike, ""] = 0.0,
) -> Float[Array, "H W"]:
    """Fill holes from the nearest valid value left, right, above or below whose pixel has
    the colour closest to the hole pixel's own.

    Of the (up to) four nearest valid pixels along the rows and columns, the one whose
    ``guide`` colour is nearest (L1 over the channels) to the hole pixel's ``guide`` colour
    gives its value if that colour distance is smaller than the farthest (smallest) value's
    by more than ``margin``; otherwise the farthest value does (as in `background_fill`).
    Among equally near colours the farthest value wins. The hole shows the surface that its
    colour matches, which a disocclusion behind a nearer surface need not share with the
    farthest neighbour; where the colours barely tell the candidates apart (low contrast,
    noise, view-dependent shading), the margin falls back to the background, which a hole
    next to a depth edge mostly shows. Candidates within 10⁻⁴ of the farthest value tie with
    it: the margin counts from the nearest colour among them, so that two equal farthest
    values (copies of one value, as in filled cracks) that a perturbation separates do not
    switch the decision. ``margin = 0``: the colour alone decides; ``inf``:
    `background_fill`. Pixels with no valid value on any of the four rays stay 0.
    jit/vmap-able; piecewise a selection of the input values (differentiable in them, not
    in the choice).

    Args:
        values: ``(H, W)`` disparity (pixels per view step), meaningful where ``valid``.
        valid: ``(H, W)`` bool, the pixels that keep their value.
        guide: ``(H, W, C)`` colour of the same view (e.g. its `colour_guide`).
        margin: scalar >= 0 (guide units, L1 over the channels; may be traced): how much
            closer in colour than the farthest value's pixel the chosen pixel must be.

    Returns:
        ``(H, W)`` filled disparity, the dtype of ``values``.

    Raises:
        ValueError: on a non-2-D ``values``, ``valid`` / ``guide`` of another ``(H, W)``, or
            a negative or NaN ``margin`` given as a Python number.

    References:
        Not in the thesis (its angular inpainting leaves disocclusions to the EPI solve,
        Sec. 6.1, eqs 6.4–6.8).
    """
    values = jnp.asarray(values)
    valid = jnp.asarray(valid, bool)
    guide = jnp.asarray(guide, values.dtype)
    if values.ndim != 2:
        raise ValueError(f"values must have shape (H, W); got {tuple(values.shape)}")
    if valid.shape != values.shape or guide.ndim != 3 or guide.shape[:2] != values.shape:
        raise ValueError(
            f"valid must have shape {values.shape} and guide {values.shape + ('C',)}; got "
            f"{tuple(valid.shape)} and {tuple(guide.shape)}"
        )
    check_lower_bound("margin", margin, 0.0)
    big = jnp.asarray(jnp.inf, values.dtype)
    # The guide's channels as separate (H, W) planes: gathers and arithmetic on them run
    # ~5 % faster on XLA's CPU backend than on (H, W, C) with the channels innermost.
    planes = [guide[..., c] for c in range(guide.shape[-1])]
    cands, dists = [], []
    for axis in (0, 1):
        for reverse in (False, True):
            near, found = _nearest_index(valid, axis, reverse)
            dist = sum(jnp.abs(jnp.take_along_axis(p, near, axis=axis) - p) for p in planes)
            cands.append(jnp.where(found, jnp.take_along_axis(values, near, axis=axis), big))
            dists.append(jnp.where(found, dist, big))
    # The four candidates' values and colour distances (inf where none) are combined
    # pairwise, not stacked and reduced over the stack: on XLA's CPU backend that is ~1.4x
    # faster (a 512² map: 17 against 24 ms). The colour-nearest candidate; among equal
    # distances the farthest value.
    best_dist = functools.reduce(jnp.minimum, dists)
    best = functools.reduce(
        jnp.minimum, [jnp.where(d == best_dist, c, big) for c, d in zip(cands, dists, strict=True)]
    )
    far = functools.reduce(jnp.minimum, cands)
    # The farthest value's colour distance: the nearest colour among the candidates within
    # `_TIE` of it, so that two (nearly) equal farthest values crossing each other do not
    # switch the comparison with the margin (copies of one value are common: filled cracks).
    far_dist = functools.reduce(
        jnp.minimum, [jnp.where(c <= far + _TIE, d, big) for c, d in zip(cands, dists, strict=True)]
    )
    pick = jnp.where(best_dist < far_dist - jnp.asarray(margin, values.dtype), best, far)
    pick = jnp.where(jnp.isfinite(pick), pick, 0.0)
    return jnp.where(valid, values, pick)


def fill_beyond_frame(
    filled: Float[ArrayLike, "H W"],
    valid: Bool[ArrayLike, "H W"],
    offset: Float[ArrayLike, " 2"],
    margin: float | Float[ArrayLike, ""] = 0.1,
) -> Float[Array, "H W"]:
    """Give the holes that reach the frame's border the far surface beyond the centre frame.

    A view ``offset = (dr, dc)`` view steps from the centre (rows, columns) sees, along its
    border, surfaces whose points lie beyond the centre view's frame: the reprojections
    merged into the view leave them holes (or values whose colour does not match), and a
    2-D fill (`colour_fill`) can give such a hole only the values its rays meet. Where the
    hole region is cut off by the border, a hole next to a nearer surface may meet that
    surface alone (the row of the far wall just above a near object's top edge, with the
    rest of the wall's holes above it up to the border).

    For every run of holes along a row (where ``dc != 0``) or a column (where ``dr != 0``)
    that reaches the frame's border (no valid pixel between the pixel and the border), the
    run's farthest (smallest) filled value ``v`` replaces a hole's own where it is farther
    by more than ``margin`` and the surface point it stands for lies beyond the centre
    frame: ``x + (dr, dc)·v`` (the inverse of `forward_project`) more than half a pixel
    outside it, so the centre view could not have seen that surface there. Of the (up to)
    four runs (from the top, bottom, left and right border) the farthest such value wins.
    Only runs along an axis of the view's displacement count: a surface beyond the frame
    enters the view along that axis, while across it (a column of a view on the centre
    row) a run may span surfaces at other depths, any of which would pass the test at a
    border the displacement crosses. Valid pixels and holes of runs that do not reach the
    border are unchanged. jit/vmap-able; a selection of the input values
    (differentiable in them, not in the choice).

    Args:
        filled: ``(H, W)`` float disparity (pixels per view step), holes already filled
            (e.g. by `colour_fill`).
        valid: ``(H, W)`` bool, the pixels that are not holes.
        offset: ``(2,)`` the view's ``(dr, dc)`` from the centre view, view steps.
        margin: scalar >= 0, pixels per view step (may be traced); ``inf`` (or 1e9): no
            change.

    Returns:
        ``(H, W)`` disparity, the dtype of ``filled``.

    Raises:
        ValueError: on a non-2-D or non-floating ``filled``, ``valid`` of another shape, an
            ``offset`` not of shape ``(2,)``, or a negative or NaN ``margin`` given as a
            Python number.

    References:
        Not in the thesis (its off-cross-hair views are the mean of two reprojections, Sec.
        6.1).
    """
    filled = jnp.asarray(filled)
    valid = jnp.asarray(valid, bool)
    offset = jnp.asarray(offset, filled.dtype)
    if filled.ndim != 2:
        raise ValueError(f"filled must have shape (H, W); got {tuple(filled.shape)}")
    if not jnp.issubdtype(filled.dtype, jnp.floating):
        raise ValueError(f"filled must be a floating array; got {filled.dtype}")
    if valid.shape != filled.shape:
        raise ValueError(f"valid must have shape {filled.shape}; got {tuple(valid.shape)}")
    if offset.shape != (2,):
        raise ValueError(f"offset must have shape (2,); got {tuple(offset.shape)}")
    check_lower_bound("margin", margin, 0.0)
    H, W = filled.shape
    big = jnp.asarray(jnp.inf, filled.dtype)
    hole = ~valid
    values = jnp.where(hole, filled, big)
    rows = jnp.arange(H)[:, None]
    cols = jnp.arange(W)[None, :]
    any_col, any_row = jnp.any(valid, axis=0), jnp.any(valid, axis=1)
    # The first and last valid index of every column and row (H, -1, W, -1 where none).
    top = jnp.where(any_col, jnp.argmax(valid, axis=0), H)[None, :]
    bottom = jnp.where(any_col, H - 1 - jnp.argmax(valid[::-1], axis=0), -1)[None, :]
    left = jnp.where(any_row, jnp.argmax(valid, axis=1), W)[:, None]
    right = jnp.where(any_row, W - 1 - jnp.argmax(valid[:, ::-1], axis=1), -1)[:, None]
    ys, xs = rows.astype(filled.dtype), cols.astype(filled.dtype)
    best = jnp.full(filled.shape, big)
    for run, axis in ((rows < top, 0), (rows > bottom, 0), (cols < left, 1), (cols > right, 1)):
        far = jnp.min(jnp.where(run, values, big), axis=axis, keepdims=True)
        cy, cx = ys + offset[0] * far, xs + offset[1] * far
        beyond = (cy < -0.5) | (cy > H - 0.5) | (cx < -0.5) | (cx > W - 0.5)
        along = offset[axis] != 0  # column runs (axis 0) move with dr, row runs with dc
        best = jnp.minimum(best, jnp.where(run & beyond & along, far, big))
    margin = jnp.asarray(margin, filled.dtype)
    return jnp.where(hole & (best < filled - margin), best, filled)


def contradicted_by_centre(
    candidate: Float[Array, "H W"],
    centre: Float[Array, "H W"],
    offset: Float[Array, " 2"],
    tol: float | Array,
) -> Bool[Array, "H W"]:
    """Where the centre view's map rules out a disparity for the pixels of another view.

    Each pixel's ``candidate`` is traced back into the centre view, to
    ``(x + dc d, y + dr d)`` (the inverse of `forward_project`). It is ruled out where that
    point lies inside the frame and the nearest of the four centre pixels around it is not
    nearer than ``d + tol``: the centre view would see that surface there and would have
    projected it to the pixel. A hole of the projection (a disocclusion, or content entering
    over the frame) can only hold a surface that the centre view does not see at that spot:
    one hidden behind a nearer surface, or outside its frame.

    Args:
        candidate: ``(H, W)`` disparity of the view's pixels (pixels per view step).
        centre: ``(H, W)`` the centre view's disparity map.
        offset: ``(2,)`` ``(dr, dc)`` of the view relative to the centre view (view steps).
        tol: disparity margin (pixels per view step).

    Returns:
        ``(H, W)`` bool.

    References:
        Not in the thesis; the visibility reasoning of its forward projection (Sec. 6.1,
        eq 6.5) applied to the holes that the projection leaves.
    """
    H, W = candidate.shape
    ys, xs = jnp.meshgrid(
        jnp.arange(H, dtype=candidate.dtype), jnp.arange(W, dtype=candidate.dtype), indexing="ij"
    )
    yc = ys + offset[0] * candidate
    xc = xs + offset[1] * candidate
    inside = (yc >= 0) & (yc <= H - 1) & (xc >= 0) & (xc <= W - 1)
    y0 = jnp.clip(jnp.floor(yc), 0, H - 1).astype(jnp.int32)
    x0 = jnp.clip(jnp.floor(xc), 0, W - 1).astype(jnp.int32)
    y1 = jnp.minimum(y0 + 1, H - 1)
    x1 = jnp.minimum(x0 + 1, W - 1)
    # The nearest of the four pixels around the traced point: a boundary between the
    # centre's surfaces may lie anywhere between them.
    at = jnp.maximum(
        jnp.maximum(centre[y0, x0], centre[y0, x1]), jnp.maximum(centre[y1, x0], centre[y1, x1])
    )
    return inside & (at <= candidate + tol)


def _cross_hair_fill(
    maps, valid, conf, centre: int, offsets, centre_map, guides, config: ReconstructConfig
):
    """``config.epi.cross_hair_fill`` on a stack of cross-hair maps ``(K, H, W)`` with their
    projection's ``valid`` and photometric confidence; entry ``centre`` is kept.
    ``offsets`` ``(K, 2)``: the views' ``(dr, dc)``; ``centre_map``: the projected map;
    ``guides`` ``(K, H, W, C)``: the views' colour guides. The filled maps then go
    through `fill_beyond_frame` with ``config.epi.frame_margin``."""
    ok = valid & (conf > config.epi.min_confidence)

    def view_fill(values, keep, guide):
        if config.epi.fill_choice == "colour":
            return colour_fill(values, keep, guide, config.epi.colour_margin)
        return background_fill(values, keep)

    view_bg = jax.vmap(view_fill)(maps, ok, guides)
    # The value a hole takes: the view background, or the farther of it and the inpainted
    # value (``hole_value = "farther"``); `inpainted` marks where that is the inpainted one.
    if config.epi.hole_value == "fill":
        hole, inpainted = view_bg, jnp.zeros(maps.shape, bool)
    else:
        hole, inpainted = jnp.minimum(maps, view_bg), maps <= view_bg
    fallback = jnp.where(ok, maps, hole)
    if config.epi.visibility_fill:
        # The farther of the nearest valid values of the same pixel in the views before and
        # after along the cross-hair (the EPI's angular axis).
        epi_bg = _farthest_nearest(maps, ok, (0,))
        epi_bg = jnp.where(jnp.isfinite(epi_bg), epi_bg, hole)
        tol = config.epi.visibility_tol
        cands = jnp.stack([maps, view_bg, epi_bg])
        bad = jax.vmap(jax.vmap(contradicted_by_centre, (0, None, 0, None)), (0, None, None, None))(
            cands, centre_map, offsets, tol
        )
        bad_hole = jnp.where(inpainted, bad[0], bad[1])
        # Keep `hole` unless the centre view contradicts it; else the nearest of inpainted
        # value, view background and angular background that the centre view does not
        # contradict.
        best = jnp.max(jnp.where(bad, -jnp.inf, cands), axis=0)
        all_bad = jnp.all(bad, axis=0)
        chosen = jnp.where(bad_hole & ~all_bad, best, hole)
        fallback = jnp.where(ok, maps, jnp.where(valid, hole, chosen))

        def refill(args):
            # Holes with every candidate contradicted ("stuck"): the view's 2-D fill again,
            # from every pixel that is not stuck (the resolved holes included), where the
            # centre view does not contradict it. Views without such holes skip the fill.
            values, stuck, guide, offset = args

            def again(_):
                filled = view_fill(values, ~stuck, guide)
                take = stuck & ~contradicted_by_centre(filled, centre_map, offset, tol)
                return jnp.where(take, filled, values), stuck & ~take

            return lax.cond(jnp.any(stuck), again, lambda _: (values, stuck), None)

        if config.epi.visibility_passes > 1:
            fallback, _ = lax.fori_loop(
                1,
                config.epi.visibility_passes,
                lambda _, state: lax.map(refill, (*state, guides, offsets)),
                (fallback, ~valid & all_bad),
            )
    fallback = jax.vmap(fill_beyond_frame, (0, 0, 0, None))(
        fallback, ok, offsets, config.epi.frame_margin
    )
    return fallback.at[centre].set(maps[centre])


def _cross_hair_positions(U: int, V: int) -> np.ndarray:
    """``(U + V - 1, 2)`` ``(row, col)`` of the cross-hair views: the centre row, then the
    centre column without the centre."""
    rc, cc = U // 2, V // 2
    return np.asarray([(rc, c) for c in range(V)] + [(r, cc) for r in range(U) if r != rc])


def _cross_hair_views(views: Array) -> tuple[Array, Array]:
    """The ``K = U + V - 1`` cross-hair views and their ``(row, col)`` positions."""
    idx = _cross_hair_positions(*views.shape[:2])
    return views[idx[:, 0], idx[:, 1]], jnp.asarray(idx, views.dtype)


def _sweep_positions(U: int, V: int, min_offset: int) -> np.ndarray:
    """``(K, 2)`` ``(row, col)`` of the cross-hair views at least ``min_offset`` view steps
    from the centre (every cross-hair view but the centre when none is that far)."""
    pos = _cross_hair_positions(U, V)
    dist = np.abs(pos - np.array([U // 2, V // 2])).sum(axis=1)
    return pos[(dist > 0) & (dist >= min(min_offset, int(dist.max())))]


def _refine(d, row, col, views, ch_views, ch_pos, config: ReconstructConfig, iterations: int):
    """`photo_refine` of view ``(row, col)`` against the cross-hair views."""
    if iterations == 0:
        return d
    sc = config.sharpen
    offsets = ch_pos - jnp.stack([row, col]).astype(ch_pos.dtype)[None]
    return photo_refine(
        d,
        views[row, col],
        ch_views,
        offsets,
        radius=sc.refine_radius,
        jump=sc.refine_jump,
        margin=sc.refine_margin,
        iterations=iterations,
        near_weight=sc.refine_near_weight,
        aggregate=sc.refine_aggregate,
    )


def _matte(
    d: Array,
    guide: Array,
    config: ReconstructConfig,
    jump: Array,
    snap: Array,
    background: tuple[Array, Array] | None = None,
    others: tuple[Array, Array] | None = None,
    fits: tuple[float, float] = (0.0, 0.0),
    split_at: Array | None = None,
    soft: Array | float = 0.0,
) -> Array:
    """`boundary_matte` of one view's map (``guide``: the view's `colour_guide`) with the
    config's settings, the discontinuity threshold ``jump``, the ``snap`` fraction and
    optionally an observed ``(background colour, valid)`` (`observed_background`) and other
    views' ``(colours, weights)`` (`near_surface_colours`), and the ``(foreground,
    background)`` strengths of the sides' colour fits (``*_fit``); with ``split_at``, a
    background side that holds two surfaces is split at those pixels (`boundary_matte`'s
    ``split_background`` with ``split_pixels``); ``soft``: `boundary_matte`'s band of
    blended values."""
    sc = config.sharpen
    colour, valid = (None, None) if background is None else background
    other, weight = (None, None) if others is None else others
    return boundary_matte(
        d,
        guide,
        radius=sc.matte_radius,
        jump=jump,
        spatial_sigma=sc.matte_sigma,
        impure_weight=sc.matte_impure_weight,
        min_separation=sc.matte_min_separation,
        max_residual=sc.matte_max_residual,
        snap=snap,
        background=colour,
        background_valid=valid,
        others=other,
        other_weights=weight,
        align_tolerance=sc.matte_align_tolerance,
        foreground_fit=fits[0],
        background_fit=fits[1],
        split_background=split_at is not None,
        split_pixels=split_at,
        soft=soft,
    )


def _matte_others(centre: Array, views: Array, config: ReconstructConfig):
    """The ``others`` of the centre map's matte: `near_surface_colours` of the cross-hair
    views up to ``sharpen.matte_other_steps`` steps away (a view without an image weighs 0);
    ``None`` at 0 steps."""
    sc = config.sharpen
    steps = sc.matte_other_steps
    if steps == 0:
        return None
    U, V = views.shape[:2]
    rc, cc = U // 2, V // 2
    pos = _cross_hair_positions(U, V)
    off = pos - np.array([rc, cc])
    near = (np.abs(off).max(axis=1) <= steps) & (np.abs(off).max(axis=1) > 0)
    pos, off = pos[near], off[near]
    others = views[pos[:, 0], pos[:, 1]]
    present = jnp.max(others, axis=(1, 2, 3)) > 0
    colours, weights = near_surface_colours(
        centre,
        colour_guide(others, sc.matte_colour),
        jnp.asarray(off, centre.dtype),
        radius=sc.matte_radius,
        phase=sc.matte_phase,
    )
    return colours, weights * present[:, None, None]


def _matte_views(disparity: Array, views: Array, guides: Array, present: Array, config) -> Array:
    """Step 4 of `propagate`: `boundary_matte` of the map of every view but the centre, with
    the background colour `observed_background` gives (``sharpen.matte_view_steps > 0``).
    A view without an image (``present`` false; partial grids) keeps its map (`map_where`)."""
    U, V = disparity.shape[:2]
    rc, cc = U // 2, V // 2
    sc = config.sharpen
    others = np.nonzero((np.arange(U)[:, None] != rc) | (np.arange(V)[None, :] != cc))
    r_j, c_j = (jnp.asarray(i, jnp.int32) for i in others)
    same = sc.matte_colour == config.colour_space
    jump, snap = sc.matte_view_jump, sc.matte_view_snap
    fits = (sc.matte_view_foreground_fit, sc.matte_view_background_fit)
    split = sc.matte_view_split
    # The pixels where each view's matte may split its background side, listed for every
    # view before the matte's loop (inside it XLA's CPU backend fuses the list's window
    # pass into the matte, which then takes ~50 % longer), one view at a time (under `vmap`
    # `split_candidates`' mask is fused into its list and recomputed, ~5x as long).
    split_at = ()
    if split:
        split_at = (
            lax.map(
                lambda m: split_candidates(m, radius=sc.matte_radius, jump=jump),
                disparity[r_j, c_j],
            ),
        )

    def view_matte(d, guide, background, split_px):
        return _matte(
            d,
            guide,
            config,
            jump,
            snap,
            background,
            fits=fits,
            split_at=split_px,
            soft=sc.matte_view_soft,
        )

    if sc.matte_view_steps == 0:
        # The maps and guides are gathered before the loop: slicing them by the loop's
        # traced index inside `lax.map` is ~25 % slower on XLA's CPU backend.
        own = guides[r_j, c_j] if same else colour_guide(views[r_j, c_j], sc.matte_colour)
        return _map_views(
            lambda args: view_matte(*args[:2], None, args[2] if split else None),
            (disparity[r_j, c_j], own, *split_at),
            disparity,
            present,
            (r_j, c_j),
        )
    # The samples come from every view, the centre included.
    matte_guides = guides if same else colour_guide(views, sc.matte_colour)
    H, W = disparity.shape[2:]
    n = H * W
    # Each view's pixels on a 3×3 discontinuity (whose window minimum is their background
    # disparity) take a background colour, up to a sixteenth of the frame (at least 4096
    # pixels, so the small frames of the synthetic scenes fit: 12 % of them at most;
    # backgammon 9 % at a jump of 0.5). Where more are on a discontinuity, the list keeps
    # the largest jumps (`largest_jumps`) and the others keep the window mean.
    capacity = min(n, max(4096, -(-n // 16)))
    lo, hi = jax.vmap(jax.vmap(lambda m: _window_extrema(m, 1)))(disparity)
    surface = smooth_surface(disparity, lo, hi, sc.matte_view_tolerance)
    edge = largest_jumps((hi - lo)[r_j, c_j], jump, capacity)
    # A view without an image (partial grids) has no colour to compare: no samples.
    edge = edge & present[r_j, c_j][:, None, None]
    flat = pixel_subset(edge.reshape(edge.shape[0], -1), capacity)
    back_d = jax.vmap(lambda r, c, f: lo[r, c].ravel()[jnp.minimum(f, n - 1)])(r_j, c_j, flat)
    # All views at once: the gathers from the stacks of every view's guide and map run ~2x
    # slower inside a `lax.map` on XLA's CPU backend.
    colour, valid = jax.vmap(
        lambda r, c, f, b: background_samples(
            r,
            c,
            f,
            lax.stop_gradient(b),
            matte_guides,
            surface,
            present,
            steps=sc.matte_view_steps,
            tolerance=sc.matte_view_tolerance,
        )
    )(r_j, c_j, flat, back_d)

    def one(args):
        d, guide, f, col, ok = args[:5]
        background = samples_to_frame(f, col, ok, (H, W))
        return view_matte(d, guide, background, args[5] if split else None)

    inputs = (disparity[r_j, c_j], matte_guides[r_j, c_j], flat, colour, valid, *split_at)
    return _map_views(one, inputs, disparity, present, (r_j, c_j))


def _map_views(matte, inputs, disparity: Array, present: Array, views) -> Array:
    """``disparity`` with the maps of the ``views`` (``(rows, cols)``) replaced by
    ``matte`` of their ``inputs`` (whose first entry is the map), one view at a time; a view
    without an image (partial grids) keeps its map: no colours to decide on (`map_where`)."""
    matted = map_where(matte, lambda args: args[0], present[views], inputs)
    return disparity.at[views].set(matted)


def _check_views(views) -> tuple[int, int, int, int]:
    if views.ndim != 5 or views.shape[-1] != 3:
        raise ValueError(f"views must have shape (U, V, H, W, 3); got {tuple(views.shape)}")
    U, V, H, W, _ = views.shape
    if U < 3 or V < 3:
        raise ValueError(f"the light field needs at least 3x3 views; got {U}x{V}")
    return U, V, H, W


def _check_views_and_centre(views, centre_disparity) -> tuple[Array, Array]:
    """Floating views and centre map (float32, or float64 when either is), shapes checked
    (`_check_views`, centre ``(H, W)``)."""
    dt = jnp.result_type(views, centre_disparity, jnp.float32)
    views = jnp.asarray(views, dt)
    _, _, H, W = _check_views(views)
    centre = jnp.asarray(centre_disparity, dt)
    if centre.shape != (H, W):
        raise ValueError(
            f"centre_disparity must have shape {(H, W)} (the views' H, W); "
            f"got {tuple(centre.shape)}"
        )
    return views, centre


def _sharpen(views: Array, centre: Array, config: ReconstructConfig) -> Array:
    """Step 2 of `reconstruct` (traced inline; see `sharpen`)."""
    U, V = views.shape[:2]
    rc, cc = U // 2, V // 2
    sc = config.sharpen
    sharp = centre
    ch_views, ch_pos = _cross_hair_views(views)
    ch_offsets = ch_pos - jnp.asarray([rc, cc], ch_pos.dtype)
    if sc.shading_sigma > 0 and (sc.refine or sc.sweep_steps):
        bias = shading_bias(
            centre,
            views[rc, cc],
            ch_views,
            ch_offsets,
            sigma=sc.shading_sigma,
            threshold=sc.shading_threshold,
            floor=sc.shading_floor,
            jump=sc.shading_jump,
            edge_radius=sc.shading_edge_radius,
        )
        ch_views = remove_shading(ch_views, bias, centre, ch_offsets)
    if sc.refine:
        rc_j, cc_j = jnp.int32(rc), jnp.int32(cc)
        sharp = _refine(sharp, rc_j, cc_j, views, ch_views, ch_pos, config, sc.refine_iterations)
    if sc.matte:
        guide = colour_guide(views[rc, cc], sc.matte_colour)
        sharp = _matte(
            sharp,
            guide,
            config,
            sc.matte_jump,
            sc.matte_snap,
            others=_matte_others(sharp, views, config),
            fits=(sc.matte_foreground_fit, sc.matte_background_fit),
            soft=sc.matte_soft,
        )
    if sc.sweep_steps:
        pos = _sweep_positions(U, V, sc.sweep_min_offset)
        offsets = jnp.asarray(pos - np.array([rc, cc]), sharp.dtype)
        index = {tuple(p): k for k, p in enumerate(_cross_hair_positions(U, V).tolist())}
        sharp = photo_sweep(
            sharp,
            views[rc, cc],
            ch_views[np.asarray([index[tuple(p)] for p in pos.tolist()])],
            offsets,
            steps=sc.sweep_steps,
            search=sc.sweep_search,
            aggregate=sc.sweep_aggregate,
            ssim=sc.sweep_ssim,
            margin=sc.sweep_margin,
            support_jump=sc.sweep_support_jump,
        )
    slope = None
    if sc.enabled and sc.wmf_slope_baseline > 0:
        slope = disparity_slopes(sharp, baseline=sc.wmf_slope_baseline, max_slope=sc.wmf_slope_max)
    if sc.enabled and sc.filter == "mean":
        sharp = weighted_mean_filter(
            sharp,
            views[rc, cc],
            radius=sc.wmf_radius,
            sigma=sc.wmf_sigma,
            weight_type=sc.wmf_weight,
            slope=slope,
        )
    elif sc.enabled:
        sharp = weighted_median_filter(
            sharp,
            views[rc, cc],
            radius=sc.wmf_radius,
            sigma=sc.wmf_sigma,
            weight_type=sc.wmf_weight,
            iterations=sc.wmf_iterations,
            slope=slope,
        )
    return sharp


@filter_jit_bound
def sharpen(
    views: Float[ArrayLike, "U V H W 3"],
    centre_disparity: Float[ArrayLike, "H W"],
    config: ReconstructConfig = ReconstructConfig(),
) -> Float[Array, "H W"]:
    """Sharpen a centre-view disparity map at depth discontinuities (step 2 of `reconstruct`).

    With ``config.sharpen.refine``: pixels next to depth discontinuities are snapped to the
    photo-consistent side with the cross-hair views (`photo_refine`; not in the thesis: it
    removes the foreground halos that labels on the wrong side of an occlusion edge leave).
    With ``config.sharpen.shading_sigma > 0`` the cross-hair views of the snapping and the
    plane sweep first lose their view-dependent shading (`shading_bias` estimated with
    ``centre_disparity``, `remove_shading`; not in the thesis).
    With ``config.sharpen.matte``: `boundary_matte` puts every pixel on a discontinuity on the side
    its colour mixture says (not in the thesis: snapping cannot decide mixed pixels); with
    ``config.sharpen.matte_other_steps`` the mixture is read in the cross-hair views up to
    that many steps away too, at the pixel's nearest surface (`near_surface_colours`; only
    the centre map is matted here). With
    ``config.sharpen.sweep_steps``: every pixel is corrected by a local plane sweep of
    ``sweep_steps`` hypotheses within ``± sweep_search`` (`photo_sweep` against the
    cross-hair views at least ``sweep_min_offset`` steps away; not in the thesis: the
    interpolated Ch. 6 map is only as exact as the interpolation, the colours say more
    where there is texture). With
    ``config.sharpen.enabled``: `weighted_median_filter` guided by the centre view (thesis
    Sec. 6.1, r = 7; Sec. 7.2.1 uses the same filter to post-process the Ch. 7 result); with
    ``config.sharpen.wmf_slope_baseline > 0`` its samples enter extrapolated to the window
    centre along their own `disparity_slopes` (first-order filtering, not in the thesis: the
    plain median flattens slanted surfaces).
    All off (``sweep_steps = 0``): the map is returned unchanged. jit-compiled
    (`equinox.filter_jit`).

    Args:
        views: ``(U, V, H, W, 3)`` float RGB in [0, 1], ``U, V >= 3``.
        centre_disparity: ``(H, W)`` float disparity of the centre view ``(U//2, V//2)``,
            pixels per view step.
        config: `ReconstructConfig` (its ``sharpen`` sub-config, and ``colour_space``).

    Returns:
        ``(H, W)`` float32 sharpened disparity.

    Raises:
        ValueError: on inconsistent shapes (quoted).

    References:
        Thesis Sec. 6.1 (weighted median sharpening), Sec. 7.2.1 (WMF post-processing).
    """
    views, centre = _check_views_and_centre(views, centre_disparity)
    return _sharpen(views, centre, config)


def _centre_seeds(views: Array, edges: EdgeSet, surface, config: ReconstructConfig):
    """`centre_seeds` on checked, floating views (traced inline)."""
    U, V, H, W = views.shape[:4]
    rc, cc = U // 2, V // 2
    sd = config.seeds
    qx, qy, use = label_positions(edges, surface, config)
    label_weight, label_value = splat_bilinear(
        qx, qy, edges.disparity, use.astype(views.dtype), (H, W)
    )
    support = label_weight > 0
    any_label = jnp.any(use)
    low = jnp.where(any_label, jnp.min(jnp.where(use, edges.disparity, jnp.inf)), 0.0)
    high = jnp.where(any_label, jnp.max(jnp.where(use, edges.disparity, -jnp.inf)), 0.0)
    pos = _sweep_positions(U, V, 1)
    value, valid = photo_seeds(
        views[rc, cc],
        views[pos[:, 0], pos[:, 1]],
        jnp.asarray(pos - np.array([rc, cc]), views.dtype),
        support,
        low - sd.margin,
        high + sd.margin,
        steps=sd.steps,
        scale=sd.scale,
        aggregate=sd.aggregate,
        min_distance=sd.min_distance,
        exclusion=sd.exclusion,
        ratio=sd.ratio,
        min_contrast=sd.min_contrast,
        support_values=label_value,
        behind_jump=sd.behind_jump,
    )
    return jnp.where(valid, sd.weight, 0.0).astype(views.dtype), value.astype(views.dtype)


@filter_jit_bound
def centre_seeds(
    views: Float[ArrayLike, "U V H W 3"],
    edges: EdgeSet,
    surface: SurfaceResult,
    config: ReconstructConfig = ReconstructConfig(),
) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """Photo-consistent disparity samples of the centre view where no edge label is near.

    `photo_seeds` of the centre view against the other views of the central cross-hair,
    with the hypotheses spanning the disparity range of the edge labels visible in the
    centre view widened by ``config.seeds.margin``; ``support`` are the pixels the labels
    are splatted onto (at ``p + centre.offset_scale · n``, as in `centre_disparity`), and
    ``support_values`` their splatted disparities (``config.seeds.behind_jump``). The
    result is `centre_disparity`'s ``seeds`` argument; `reconstruct` adds it with
    ``config.seeds.steps > 0``. Differentiable in ``config.seeds.weight`` and, within
    the hypothesis choice, in the colours. jit-compiled (`equinox.filter_jit`).

    Args:
        views: ``(U, V, H, W, 3)`` float RGB in [0, 1], ``U, V >= 3``.
        edges: `EdgeSet` (capacity ``N``; centre-view positions, disparities, ``visible``).
        surface: `SurfaceResult` (``offset (N, 2)``).
        config: `ReconstructConfig` (its ``seeds`` sub-config; ``seeds.steps`` ≥ 3).

    Returns:
        ``(weight (H, W), value (H, W))``: ``config.seeds.weight`` where a pixel has a
        sample and 0 elsewhere, and the sample disparity (pixels per view step).

    Raises:
        ValueError: on inconsistent shapes (quoted), or ``config.seeds.steps == 0``.

    References:
        Thesis eq 7.15 (warping error), Sec. 8.1.1 (adding samples); not in the thesis.
    """
    views = jnp.asarray(views, jnp.result_type(views, jnp.float32))
    U, V, H, W = _check_views(views)
    _check_inputs(edges, surface, views[U // 2, V // 2])
    if config.seeds.steps == 0:
        raise ValueError("config.seeds.steps is 0 (samples off); set it to >= 3")
    return _centre_seeds(views, edges, surface, config)


@filter_jit_bound
def select_centre(
    views: Float[ArrayLike, "U V H W 3"],
    incumbent: Float[ArrayLike, "H W"],
    candidate: Float[ArrayLike, "H W"],
    config: ReconstructConfig = ReconstructConfig(),
) -> tuple[Float[Array, "H W"], Bool[Array, "H W"]]:
    """Merge two centre-view disparity maps pixel by pixel by photo-consistency with the
    cross-hair views (`photo_select`; not in the thesis).

    Where ``candidate`` differs from ``incumbent`` by more than ``config.select.min_change``
    and has the lower occlusion-aware colour cost (`photo_cost`: colour L1 plus
    ``config.select.ssim`` times the SSIM dissimilarity; by ``config.select.margin``,
    aggregated over a ``(2 select.aggregate + 1)²`` colour-weighted window), it wins;
    elsewhere the incumbent stays. `optimize_disparity` merges the sharpened Ch. 7 map
    (candidate) into the Ch. 6 centre map (incumbent) this way: the optimisation corrects
    gross errors at depth edges, while the Ch. 6 map keeps its fine accuracy elsewhere.
    jit-compiled.

    Args:
        views: ``(U, V, H, W, 3)`` float RGB in [0, 1], ``U, V >= 3``.
        incumbent: ``(H, W)`` centre-view disparity (pixels per view step).
        candidate: ``(H, W)`` alternative centre-view disparity.
        config: `ReconstructConfig` (its ``select`` sub-config).

    Returns:
        ``(merged (H, W) float32, took (H, W) bool)``: where ``took``, the candidate's value.

    Raises:
        ValueError: on inconsistent shapes (quoted).

    References:
        Multi-view photo-consistency as in Sec. 7.1 (eq 7.15 warping loss); selection not in
        the thesis.
    """
    views, incumbent = _check_views_and_centre(views, incumbent)
    _, candidate = _check_views_and_centre(views, candidate)
    U, V = views.shape[:2]
    rc, cc = U // 2, V // 2
    ch_views, ch_pos = _cross_hair_views(views)
    offsets = ch_pos - jnp.asarray([rc, cc], ch_pos.dtype)[None]
    return photo_select(
        incumbent,
        candidate,
        views[rc, cc],
        ch_views,
        offsets,
        min_change=config.select.min_change,
        margin=config.select.margin,
        aggregate=config.select.aggregate,
        ssim=config.select.ssim,
    )


def _propagate(
    views: Array,
    centre: Array,
    edges: EdgeSet,
    surface: SurfaceResult,
    config: ReconstructConfig,
) -> tuple[Array, Array, Array, dict[str, Array]]:
    """Steps 3–6 of `reconstruct` (traced inline; see `propagate`); the last output is the
    worst relative residual of the ``"epi"`` (and ``"fill"``) solves."""
    U, V, H, W, _ = views.shape
    rc, cc = U // 2, V // 2
    centre_view = views[rc, cc]
    # The colour guides of all views at once: converting a view picked by a traced index
    # inside `lax.map` is ~6x slower on XLA's CPU backend (35 ms against 5 ms per 512² view).
    guides = colour_guide(views, config.colour_space)
    present = jnp.max(views, axis=(2, 3, 4)) > 0  # (U, V): views missing from a partial grid
    ph, vh, pv, vv = project_cross_hair(centre, (U, V), crack_parallax=config.fill.crack_parallax)

    qx, qy, lw = edge_lines(edges, surface.offset, surface.step_response, config)
    d = edges.disparity
    # Horizontal EPIs: stack (H, V, W); vertical EPIs: stack (W, U, H).
    gh = jnp.transpose(guides[rc], (1, 0, 2, 3))
    gv = jnp.transpose(guides[:, cc], (2, 0, 1, 3))
    lwh, llh = rasterise_lines(qy, qx, d, lw, (H, V, W))
    lwv, llv = rasterise_lines(qx, qy, d, lw, (W, U, H))
    zv, zu = jnp.zeros((V,)), jnp.zeros((U,))
    off_h = jnp.stack([zv, jnp.arange(V) - cc], axis=1).astype(views.dtype)
    off_v = jnp.stack([jnp.arange(U) - rc, zu], axis=1).astype(views.dtype)
    ch = photometric_confidence(ph, off_h, centre_view, views[rc], config.epi.photo_sigma)
    cv = photometric_confidence(pv, off_v, centre_view, views[:, cc], config.epi.photo_sigma)
    eh = solve_epis(
        jnp.transpose(ph, (1, 0, 2)),
        jnp.transpose(vh, (1, 0, 2)),
        gh,
        lwh,
        llh,
        config,
        jnp.transpose(ch, (1, 0, 2)),
    )
    ev = solve_epis(
        jnp.transpose(pv, (2, 0, 1)),
        jnp.transpose(vv, (2, 0, 1)),
        gv,
        lwv,
        llv,
        config,
        jnp.transpose(cv, (2, 0, 1)),
    )
    residual = {"epi": _worst(jnp.concatenate([eh.residual, ev.residual]))}
    cross_h = jnp.transpose(eh.x, (1, 0, 2))  # (V, H, W)
    cross_v = jnp.transpose(ev.x, (1, 2, 0))  # (U, H, W)
    if config.epi.cross_hair_fill:
        cross_h = _cross_hair_fill(cross_h, vh, ch, cc, off_h, centre, guides[rc], config)
        cross_v = _cross_hair_fill(cross_v, vv, cv, rc, off_v, centre, guides[:, cc], config)
    rows, cols = np.nonzero((np.arange(U)[:, None] != rc) & (np.arange(V)[None, :] != cc))
    disparity = jnp.zeros((U, V, H, W), cross_h.dtype)
    disparity = disparity.at[rc, :].set(cross_h)
    disparity = disparity.at[:, cc].set(cross_v)
    disparity = disparity.at[rc, cc].set(0.5 * (cross_h[cc] + cross_v[rc]))
    if rows.size:
        rows_j = jnp.asarray(rows, jnp.int32)
        cols_j = jnp.asarray(cols, jnp.int32)

        # One view at a time (each merge forward-projects two maps and warps two views);
        # the loop's stacked outputs are materialised before the fill (see `_fill_views`).
        vals, conf = lax.map(
            lambda p: merge_reprojections(cross_h, cross_v, views, p[0], p[1], config),
            (rows_j, cols_j),
        )
        off, fill_residual = _fill_views(vals, conf, guides, present, rows_j, cols_j, config)
        if fill_residual is not None:
            residual["fill"] = _worst(fill_residual)
        disparity = disparity.at[rows_j, cols_j].set(off)
    if config.sharpen.matte_views:
        # Every view but the centre (whose map was sharpened before the projection).
        disparity = _matte_views(disparity, views, guides, present, config)
    return disparity, cross_h, cross_v, residual


def _worst(residual: Array) -> Array:
    """The largest of a stack of relative residuals (NaN if any is NaN), without gradient."""
    return jnp.max(lax.stop_gradient(residual))


@filter_jit_bound
def propagate(
    views: Float[ArrayLike, "U V H W 3"],
    centre_disparity: Float[ArrayLike, "H W"],
    edges: EdgeSet,
    surface: SurfaceResult,
    config: ReconstructConfig = ReconstructConfig(),
) -> Reconstruction:
    """Spread a centre-view disparity map to every view (steps 3–6 of `reconstruct`).

    Everything `reconstruct` does after the sharpened centre map, for any centre map (e.g.
    the Ch. 7 optimised one):

    1. Forward projection of ``centre_disparity`` into every view of the central cross-hair
       (z-buffer: the larger disparity, nearer, wins; holes stay holes).
    2. Angular inpainting of every horizontal EPI ``(V, W)`` of the centre row of views and
       every vertical EPI ``(U, H)`` of the centre column (eqs 6.4–6.8): data weight
       ``epi.data_weight`` on reprojected pixels (times their photometric confidence),
       ``λ_e`` on the rasterised EPI lines of all edge points (including points not visible
       in the centre view), smoothness ``epi.c / (|∇I_EPI| + epi.eps)``; one batched
       `solve_poisson` per direction. Reprojected pixels whose colour does not match
       (photometric confidence ≤ ``epi.min_confidence``) count as holes. With
       ``config.epi.cross_hair_fill``, the holes of each cross-hair view then take the
       view's 2-D fill (`colour_fill` with ``epi.colour_margin``, or `background_fill` with
       ``epi.fill_choice = "farthest"``; with ``epi.hole_value = "farther"`` the farther of
       that and their inpainted value; with ``epi.visibility_fill`` checked against the
       centre map), then `fill_beyond_frame` with ``epi.frame_margin`` (holes cut off by
       the frame's border along the view's row or column take the far surface beyond the
       centre frame).
    3. Views off the cross-hair: mean of the reprojections of the nearest horizontal and
       vertical cross-hair views (weighted by their photometric confidence with
       ``fill.merge="photo"``); holes and pixels of confidence ≤ ``fill.min_confidence``
       filled (``config.fill.hole_fill``) from the 2-D fill of `colour_fill` with
       ``fill.colour_margin``, then `fill_beyond_frame` with ``fill.frame_margin`` (holes
       cut off by the frame's border take the far surface beyond the centre frame).
    4. With ``config.sharpen.matte_views``: `boundary_matte` of every view but the centre
       (reprojected boundaries are only pixel-accurate), discontinuities marked by
       ``sharpen.matte_view_jump``; with ``sharpen.matte_view_steps > 0`` its background
       colour is, where other views see it, the background surface behind the pixel itself
       (`observed_background`) instead of the window mean; its sides' colours are linear
       fits read at the pixel (``sharpen.matte_view_foreground_fit``,
       ``matte_view_background_fit``; 0: the means).

    The centre view's output is the mean of its two inpainted versions (row and column), so
    it is not ``centre_disparity`` itself. Fed the ``centre_sharp`` of a `reconstruct` call
    with the same inputs and config, it returns the same disparity. jit-compiled
    (`equinox.filter_jit`).

    Args:
        views: ``(U, V, H, W, 3)`` float RGB in [0, 1], ``U, V >= 3``.
        centre_disparity: ``(H, W)`` float disparity of the centre view ``(U//2, V//2)``,
            pixels per view step (SPEC §0 sign: larger = nearer).
        edges: `EdgeSet` (capacity ``N``) whose EPI lines constrain the inpainting.
        surface: `SurfaceResult` of ``edges`` (``offset (N, 2)``, ``step_response (N,)``).
        config: `ReconstructConfig` (the centre-view fields are unused).

    Returns:
        `Reconstruction` with ``disparity (U, V, H, W)``, the inpainted ``cross_h (V, H, W)``
        and ``cross_v (U, H, W)``; ``centre`` and ``centre_sharp`` are ``centre_disparity``.

    Raises:
        ValueError: on inconsistent shapes (quoted).

    References:
        Thesis Sec. 6.1, eqs 6.4–6.8 (forward projection, angular EPI inpainting, off-cross-hair
        views); SPEC §4 steps 3–6.
    """
    views, centre = _check_views_and_centre(views, centre_disparity)
    U, V = views.shape[:2]
    _check_inputs(edges, surface, views[U // 2, V // 2])
    disparity, cross_h, cross_v, residual = _propagate(views, centre, edges, surface, config)
    return Reconstruction(
        disparity=disparity,
        centre=centre,
        centre_sharp=centre,
        cross_h=cross_h,
        cross_v=cross_v,
        solver_residual=residual,
    )


@filter_jit_bound
def reconstruct(
    views: Float[ArrayLike, "U V H W 3"],
    edges: EdgeSet,
    surface: SurfaceResult,
    config: ReconstructConfig = ReconstructConfig(),
) -> Reconstruction:
    """Smooth, view-consistent disparity for every view of a light field (thesis Ch. 6).

    1. Centre view: `centre_disparity` (eq 6.1–6.3), with the photo-consistent samples of
       `centre_seeds` where no edge label is near (``config.seeds.steps > 0``; not in the
       thesis).
    2. Sharpening: pixels next to depth discontinuities are snapped to the photo-consistent
       side with the cross-hair views (`photo_refine`, ``config.sharpen.refine``; not in the
       thesis: it removes the foreground halos that labels on the wrong side of an occlusion
       edge leave), `boundary_matte` (``config.sharpen.matte``), the local plane sweep
       `photo_sweep` (``config.sharpen.sweep_steps``; not in the thesis), then
       `weighted_median_filter` guided by the centre view (``config.sharpen.enabled``;
       first-order along `disparity_slopes` with ``config.sharpen.wmf_slope_baseline > 0``).
    3. Forward projection into every view of the central cross-hair (z-buffer, holes kept).
    4. Angular inpainting of every horizontal EPI ``(V, W)`` of the centre row of views and
       every vertical EPI ``(U, H)`` of the centre column (eqs 6.4–6.8): data weight
       ``epi.data_weight`` on reprojected pixels, ``λ_e`` on the rasterised EPI lines of all
       edge points (including points not visible in the centre view), smoothness
       ``epi.c / (|∇I_EPI| + epi.eps)``; one batched `solve_poisson` per direction.
       Reprojected pixels whose colour does not match count as holes; with
       ``config.epi.cross_hair_fill`` the holes of each cross-hair view take the view's
       2-D fill (`colour_fill` with ``epi.colour_margin``, or `background_fill` with
       ``epi.fill_choice = "farthest"``; with ``epi.hole_value = "farther"`` the farther of
       that and the inpainted value), then `fill_beyond_frame` with ``epi.frame_margin``.
    5. Views off the cross-hair: mean of the reprojections of the nearest horizontal and
       vertical cross-hair views (weighted by their photometric confidence with
       ``fill.merge="photo"``); holes and low-confidence pixels filled
       (``config.fill.hole_fill``; 2-D fill `colour_fill` with ``fill.colour_margin``, then
       `fill_beyond_frame` with ``fill.frame_margin``).
    6. With ``config.sharpen.matte_views``: `boundary_matte` of every view but the centre,
       with the background colours of `observed_background` (``sharpen.matte_view_steps``).

    Step 2 is `sharpen` and steps 3–6 are `propagate` (each callable on its own with any
    centre map). The centre view's output is the mean of its two inpainted versions (row and
    column). jit-compiled (`equinox.filter_jit`, the default ``config`` passed like any
    other: a call without it runs the program of ``ReconstructConfig()``); array leaves of
    ``config`` can be swept without recompiling. Partial grids (views missing off the
    cross-hair are all zero): those views get the plain mean of the reprojections and the
    background fill.

    Args:
        views: ``(U, V, H, W, 3)`` float RGB in [0, 1].
        edges: `EdgeSet` (capacity ``N``).
        surface: `SurfaceResult` (``offset (N, 2)``, ``step_response (N,)``,
            ``depth_edge_confidence (H, W)``).
        config: `ReconstructConfig`.

    Returns:
        `Reconstruction`.

    Raises:
        ValueError: on inconsistent shapes (quoted).

    References:
        Thesis Sec. 6.1 (eqs 6.1–6.8); SPEC §4.
    """
    views = jnp.asarray(views, jnp.result_type(views, jnp.float32))
    U, V, H, W = _check_views(views)
    centre_view = views[U // 2, V // 2]
    _check_inputs(edges, surface, centre_view)

    seeds = _centre_seeds(views, edges, surface, config) if config.seeds.steps else None
    centre, centre_solve = solve_centre(edges, surface, centre_view, config, seeds)
    sharp = _sharpen(views, centre, config)
    disparity, cross_h, cross_v, residual = _propagate(views, sharp, edges, surface, config)
    return Reconstruction(
        disparity=disparity,
        centre=centre,
        centre_sharp=sharp,
        cross_h=cross_h,
        cross_v=cross_v,
        solver_residual={"centre": _worst(centre_solve.residual), **residual},
    )
