"""Boundary matting: put depth discontinuities on the right pixel from the colour mixture."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._fields import check_lower_bound
from .._pad import edge_pad
from ._photo import _window_extrema


def boundary_matte(
    disparity: Float[ArrayLike, "H W"],
    guide: Float[ArrayLike, "H W C"],
    *,
    radius: int = 2,
    jump: float | Array = 0.2,
    spatial_sigma: float = 1.0,
    impure_weight: float | Array = 0.05,
    min_separation: float | Array = 0.1,
    max_residual: float | Array = float("inf"),
    snap: float | Array = float("inf"),
    background: Float[ArrayLike, "H W C"] | None = None,
    background_valid: Bool[ArrayLike, "H W"] | None = None,
    others: Float[ArrayLike, "K H W C"] | None = None,
    other_weights: Float[ArrayLike, "K H W"] | None = None,
    align_tolerance: float | Array = 0.1,
    foreground_fit: float = 0.0,
    background_fit: float = 0.0,
    split_background: bool = False,
    split_pixels: Int[ArrayLike, " K"] | None = None,
    soft: float | Array = 0.0,
) -> Float[Array, "H W"]:
    """Decide the side of every pixel on a depth discontinuity from its colour mixture.

    A pixel that a depth edge crosses sees a mixture ``c = α F + (1 − α) B`` of the
    foreground colour ``F`` and the background colour ``B``; with ground truth sampled at the
    pixel centre it belongs to the foreground iff the edge covers its centre, i.e. (for a
    straight edge) iff ``α > 1/2``. Multi-view photo-consistency cannot make this decision: a
    mixed pixel moves with the foreground edge in every view, so it always looks like
    foreground (the "foreground fattening" of depth maps).

    For each pixel whose ``(2 radius + 1)²`` window spans a disparity range above ``jump``:
    the window's pixels (itself excluded) are split at the mid-range disparity into a
    foreground and a background set; ``F`` and ``B`` are their mean colours and ``D_F``,
    ``D_B`` their mean disparities, weighted by a Gaussian of the distance
    (``spatial_sigma`` pixels) and by ``impure_weight`` for pixels that lie on a discontinuity
    themselves (mixed colours). ``α`` is the projection of ``c − B`` on ``F − B``. A pixel with
    ``α > 1/2`` keeps its value when it is foreground and takes ``D_F`` otherwise;
    ``α ≤ 1/2`` likewise with the background, in both cases only if one of the pixel's 8
    neighbours is on the chosen side (where three surfaces meet, the window's mean
    background can resemble the foreground colour). Unchanged: pixels off every discontinuity,
    pixels whose ``F`` and ``B`` differ by less than ``min_separation`` (guide units) or
    whose window lacks one of the two sides, pixels whose colour lies off the line through
    ``B`` and ``F`` by more than ``max_residual`` (squared distance ``|c − B − α (F − B)|²``
    relative to ``|F − B|²``: a third colour the two-colour model does not explain, as
    between fine repeated structures), and near-ties ``|α − 1/2| ≤ 10⁻³``. A decided pixel
    already on its side whose value differs from that side's mean (``D_F`` or ``D_B``) by
    more than ``snap · |D_F − D_B|`` takes the mean as well: a value between the two
    surfaces, left where a blur or an average mixed them, belongs to neither (``snap = 0``:
    every decided pixel takes its side's mean; ``inf``: it keeps its value). With
    ``background`` (e.g. `observed_background`): where ``background_valid``, ``B`` is that
    colour, the background surface at the pixel itself as another view sees it unoccluded,
    instead of the window mean, which texture next to the edge biases.

    With ``others`` (e.g. `near_surface_colours`): ``K`` other views' colours sampled where
    each pixel's nearest surface lies in them. There the foreground edge is where it is in
    this view, while the background behind it is another stretch of its texture; each other
    view gives its own ``α`` (its own window means ``F``, ``B``, the same two sides), and the
    pixel's ``α`` is the mean of its own (weight 1) and theirs, each weighted by
    ``other_weights`` and counted only where its ``F`` and ``B`` differ by ``min_separation``.
    The texture of the background, which biases a single view's ``B``, then averages out.
    The other views count only where the window's largest disparity lies within
    ``align_tolerance · |D_F − D_B|`` of ``D_F`` (two surfaces: with a third, nearer one in
    the window, the samples follow that one).

    With ``foreground_fit`` / ``background_fit`` above 0, that side's colour is not the
    weighted mean of its window pixels but the value at the pixel of their weighted
    least-squares linear fit ``c(o) = m + g·o`` over the window offsets ``o`` (pixels), with
    the ridge ``|g|² / fit`` (weight units × pixels²) holding the gradient back: the side's
    pixels all lie on one side of the pixel, so the mean is the colour about a pixel away,
    and a colour gradient across the edge (shading, the texture's low frequencies) biases
    it; the fit reads it at the pixel itself. Larger values follow the gradient more
    closely; 0 is the mean. With ``others``, every view's sides are fitted alike.

    With ``split_background``, a background side that itself spans more than ``jump`` over
    the window's pure pixels (three surfaces, e.g. a strip of far wall between a near object
    and a nearer floor) is split at its own mid-range into a far and a near part, each with
    its own mean colour and disparity. Where the far part's colour lies farther than
    ``min_separation`` from the segment between the near part's colour and ``F`` (a third
    colour, not a mixture of the other two: a run of wrong far values along the boundary of
    the near part is one), a pixel on the background side is matted against the part whose
    two-colour model explains its colour better (the smaller squared distance of its colour
    from the segment between that part's colour and ``F``), and when decided to the
    background takes that part's mean disparity. Foreground pixels, and every pixel where
    the parts are not distinct, use the whole side as without the split. Where
    ``background`` holds, it replaces the colour of the part that holds the 3×3 window's
    farthest disparity. ``F`` in these two tests is the foreground side's window mean (also
    with ``foreground_fit``); the pixel is then matted against the chosen part as against
    a whole side. Only this view's colours are split (not ``others``), and only at the
    listed pixels (``split_pixels``; by default the first ``max(1024, H·W / 256)`` in
    row-major order that may choose a part, `split_candidates`; the others keep the whole
    side). Without the split the two background surfaces' mixed mean colour can resemble
    the foreground's, and their mean disparity lies between them.

    With ``soft > 0``, a decided pixel whose ``α`` lies within ``soft / 2`` of 1/2 takes
    ``p V_F + (1 − p) V_B`` with ``p = 1/2 + (α − 1/2) / soft``, ``V_F`` and ``V_B`` the
    values it takes when decided to the foreground and to the background (its own value on
    its side, else the side's mean, as ``snap`` says). Where the mixture leaves the side
    uncertain, a value between the two surfaces has a lower expected squared error than
    either; it is off both surfaces, so such pixels count as bad pixels at a tight
    threshold. Outside that band, and with ``soft = 0``, the pixel takes one side's value.

    One pass; jit/vmap-able. Not differentiable in the side chosen (a selection); the output
    is piecewise a weighted mean of the input.

    The mixture is linear in light, so the model holds for a guide in linear light
    (`srgb_to_linear` of the sRGB values; `SharpenConfig.matte_colour`): in CIELAB or in the
    encoded values the line from ``B`` to ``F`` is bent and mostly-background pixels can look
    like foreground.

    Not in the thesis (it sharpens with the weighted median alone); measurements in
    docs/ACCURACY.md.

    Args:
        disparity: ``(H, W)`` float disparity (pixels per view step; larger = nearer).
        guide: ``(H, W, C)`` float colour of the same view (linear light for the mixture
            model to hold; see `SharpenConfig.matte_colour`).
        radius: window radius (static int >= 1).
        jump: disparity range (pixels per view step) that marks a discontinuity.
        spatial_sigma: Gaussian distance scale of the colour means, pixels (static float).
        impure_weight: weight (in [0, 1]) of window pixels that lie on a discontinuity.
        min_separation: minimum colour distance ``|F − B|`` (guide units) to decide.
        max_residual: largest squared distance of the pixel's colour from the ``B``–``F``
            line, relative to ``|F − B|²`` (dimensionless), to decide; ``inf`` = no test.
        snap: largest difference, relative to ``|D_F − D_B|`` (dimensionless, >= 0), between
            a decided pixel's value and its side's mean disparity that it keeps; ``inf``: a
            pixel on its side keeps its value.
        background: ``(H, W, C)`` background colour behind every pixel (guide units), or
            ``None`` (the window mean everywhere).
        background_valid: ``(H, W)`` bool, where ``background`` holds (with ``background``).
        others: ``(K, H, W, C)`` other views' colours at each pixel's nearest surface
            (guide units), or ``None`` (this view's colours alone).
        other_weights: ``(K, H, W)`` weights in [0, 1] of ``others`` (with ``others``).
        align_tolerance: largest difference between the window's largest disparity and
            ``D_F``, relative to ``|D_F − D_B|`` (dimensionless), for ``others`` to count.
        foreground_fit, background_fit: strength of the linear fit of the foreground /
            background side's colours (static float, finite, >= 0; the inverse of the ridge
            on the fit's gradient, 1 / (weight units × pixels²)); 0: the side's mean.
        split_background: split a background side that holds two surfaces of distinct
            colours (static bool; requires ``background_fit = 0``).
        split_pixels: ``(K,)`` int, the row-major flat indices of the pixels that may
            choose a part (`split_candidates`, padded with ``H·W``), with
            ``split_background``; ``None``: `split_candidates` of ``disparity`` here. A list
            made before a loop over views is materialised once, where XLA's CPU backend
            would recompute the candidates' window pass inside this function.
        soft: width (in ``α``, dimensionless, >= 0) of the band around 1/2 in which a
            decided pixel takes the blend of its two sides' values; 0: one side's value.

    Returns:
        ``(H, W)`` disparity, same dtype as ``disparity``.

    Raises:
        ValueError: on a non-2-D disparity, a guide of another ``(H, W)``, ``radius < 1`` or
            ``spatial_sigma <= 0``, or ``background`` / ``background_valid`` of another shape
            or given without the other, or ``others`` / ``other_weights`` likewise, or a
            fit strength that is negative or not finite, or ``split_background`` with
            ``background_fit`` above 0, or a negative ``soft`` (a Python number).
    """
    d = jnp.asarray(disparity)
    g = jnp.asarray(guide, d.dtype)
    if d.ndim != 2:
        raise ValueError(f"disparity must have shape (H, W); got {tuple(d.shape)}")
    if g.ndim != 3 or g.shape[:2] != d.shape:
        raise ValueError(f"guide must have shape {d.shape + ('C',)}; got {tuple(g.shape)}")
    radius = int(radius)
    if radius < 1:
        raise ValueError(f"radius must be >= 1; got {radius}")
    if not spatial_sigma > 0:
        raise ValueError(f"spatial_sigma must be > 0; got {spatial_sigma}")
    if isinstance(soft, (int, float)) and not soft >= 0:
        raise ValueError(f"soft must be >= 0; got {soft}")
    strength = {"f": float(foreground_fit), "b": float(background_fit)}
    for side, name in (("f", "foreground_fit"), ("b", "background_fit")):
        if not 0 <= strength[side] < float("inf"):
            raise ValueError(
                f"{name} must be finite and >= 0 (0: the window mean); got {strength[side]}"
            )
    if split_background and strength["b"] > 0:
        raise ValueError("split_background needs background_fit = 0 (the side's mean colours)")
    H, W = d.shape
    if (background is None) != (background_valid is None):
        raise ValueError("background and background_valid must be given together")
    if background is not None:
        background = jnp.asarray(background, d.dtype)
        background_valid = jnp.asarray(background_valid, bool)
        if background.shape != g.shape or background_valid.shape != d.shape:
            raise ValueError(
                f"background must have shape {g.shape} and background_valid {d.shape}; got "
                f"{tuple(background.shape)} and {tuple(background_valid.shape)}"
            )
    if (others is None) != (other_weights is None):
        raise ValueError("others and other_weights must be given together")
    if others is None:
        g_all = g[None]
    else:
        others = jnp.asarray(others, d.dtype)
        other_weights = jnp.asarray(other_weights, d.dtype)
        K = others.shape[0] if others.ndim == 4 else -1
        if others.shape != (K, *g.shape) or other_weights.shape != (K, H, W):
            raise ValueError(
                f"others must have shape (K, {H}, {W}, {g.shape[-1]}) and other_weights "
                f"(K, {H}, {W}); got {tuple(others.shape)} and {tuple(other_weights.shape)}"
            )
        g_all = jnp.concatenate([g[None], others])
    lo, hi = _window_extrema(d, radius)
    band = (hi - lo) > jump
    lo1, hi1 = _window_extrema(d, 1)
    purity = jnp.where((hi1 - lo1) > jump, jnp.asarray(impure_weight, d.dtype), 1.0)
    mid = 0.5 * (lo + hi)
    if split_background:
        if split_pixels is None:
            split_pixels = split_candidates(d, radius=radius, jump=jump)
        split_pixels = jnp.asarray(split_pixels, jnp.int32)
        if split_pixels.ndim != 1:
            raise ValueError(f"split_pixels must have shape (K,); got {tuple(split_pixels.shape)}")

    r = radius
    C = g.shape[-1]
    # Channels as separate (H, W) planes: XLA's CPU backend runs the window loop ~25 %
    # faster on them than on (H, W, C) arrays with the channels innermost.
    # ``(1 + K, H, W)`` per channel: this view, then the others.
    gc = [g_all[..., c] for c in range(C)]
    d_p = edge_pad(d, r)
    g_p = [edge_pad(x, ((0, 0), (r, r), (r, r))) for x in gc]
    p_p = edge_pad(purity, r)
    zeros = jnp.zeros_like(d)
    wf = wb = df = db = zeros
    cf = [zeros] * C
    cb = [zeros] * C
    # For the sides with a linear fit (``foreground_fit``, ``background_fit``): moments of
    # their weights over the window offsets (a, b) and their colours' first moments.
    fitted = [side for side in "fb" if strength[side] > 0]
    moments = {side: [zeros] * 5 for side in fitted}  # Σw a, Σw b, Σw a², Σw b², Σw a b
    colour_moments = {side: ([zeros] * C, [zeros] * C) for side in fitted}  # Σw a c, Σw b c
    # Static unrolled loop over the window offsets: XLA fuses it into one pass.
    for a in range(-r, r + 1):
        for b in range(-r, r + 1):
            if a == 0 and b == 0:
                continue
            s = float(np.exp(-(a * a + b * b) / (2.0 * spatial_sigma**2)))
            ds = d_p[r + a : r + a + H, r + b : r + b + W]
            w = s * p_p[r + a : r + a + H, r + b : r + b + W]
            fg = ds > mid
            # Two selections, not ``w - w_f``: a compiler may contract the difference into
            # a fused multiply-add and leave the rounding error of ``w`` (~1e-17) as the
            # weight of an empty side, which then passes the ``wb > 0`` test.
            w_f = jnp.where(fg, w, 0.0)
            w_b = jnp.where(fg, 0.0, w)
            wf, wb = wf + w_f, wb + w_b
            df, db = df + w_f * ds, db + w_b * ds
            side_weights = {"f": w_f, "b": w_b}
            for side in fitted:
                w_s = side_weights[side]
                terms = (a * w_s, b * w_s, (a * a) * w_s, (b * b) * w_s, (a * b) * w_s)
                moments[side] = [x + t for x, t in zip(moments[side], terms, strict=True)]
            for c in range(C):
                gs = g_p[c][:, r + a : r + a + H, r + b : r + b + W]
                cf[c] = cf[c] + w_f * gs
                cb[c] = cb[c] + w_b * gs
                for side in fitted:
                    w_s = side_weights[side]
                    ca, cb_ = colour_moments[side]
                    ca[c] = ca[c] + (a * w_s) * gs
                    cb_[c] = cb_[c] + (b * w_s) * gs
    tiny = jnp.asarray(1e-12, d.dtype)

    def side_colour(side, w0, c0):
        if side in moments:
            return _fit_at_pixel(w0, c0, moments[side], colour_moments[side], 1 / strength[side])
        return [x / jnp.maximum(w0, tiny) for x in c0]

    F, B = side_colour("f", wf, cf), side_colour("b", wb, cb)
    chosen = None
    if split_background:
        chosen, part_colour, part_w, part_d = _split_background(
            d, split_pixels, jump, lo, mid, lo1, hi1, [x[0] for x in gc], d_p,
            [x[0] for x in g_p], p_p, r, spatial_sigma, min_separation, background,
            background_valid,
        )  # fmt: skip
        B = [x.at[0].set(jnp.where(chosen, y, x[0])) for x, y in zip(B, part_colour, strict=True)]
        wb, db = jnp.where(chosen, part_w, wb), jnp.where(chosen, part_d, db)
    if background is not None:  # this view's background only (index 0)
        # A pixel that chose a part has the observed colour in that part already, or the
        # observed surface is the other part.
        where = background_valid if chosen is None else background_valid & ~chosen
        B = [x.at[0].set(jnp.where(where, background[..., c], x[0])) for c, x in enumerate(B)]
    sep = [F[c] - B[c] for c in range(C)]
    sep_all = sum(x * x for x in sep)
    alpha_all = sum((gc[c] - B[c]) * sep[c] for c in range(C)) / jnp.maximum(sep_all, tiny)
    sep2, alpha = sep_all[0], alpha_all[0]
    sep, gc, B = [x[0] for x in sep], [x[0] for x in gc], [x[0] for x in B]
    # Two-colour model test: the pixel's colour must lie near the line through B and F.
    off_line = sum((gc[c] - B[c] - alpha * sep[c]) ** 2 for c in range(C))
    d_f = df / jnp.maximum(wf, tiny)
    d_b = db / jnp.maximum(wb, tiny)
    if others is not None:
        w = other_weights * (sep_all[1:] > min_separation**2)
        # A view weighted 0 adds nothing, even where its colours are not finite.
        weighted = jnp.where(w > 0, w * alpha_all[1:], 0.0)
        mean = (alpha + jnp.sum(weighted, axis=0)) / (1.0 + jnp.sum(w, axis=0))
        aligned = jnp.abs(hi - d_f) <= align_tolerance * jnp.abs(d_f - d_b)
        alpha = jnp.where(aligned, mean, alpha)
    # Near-ties (alpha ~ 1/2, e.g. an edge through the centre of a pixel) keep their value,
    # so that rounding differences cannot flip a decision.
    decide = band & (wf > 0) & (wb > 0) & (sep2 > min_separation**2) & (jnp.abs(alpha - 0.5) > 1e-3)
    decide = decide & (off_line <= max_residual * sep2)
    is_fg = d > mid
    # A pixel only joins a side that one of its 8 neighbours is on: where three surfaces
    # meet, the mean background of the window can look like the foreground's colour.
    decide = decide & jnp.where(alpha > 0.5, hi1 > mid, lo1 <= mid)
    # The value a decided pixel takes on each side: its own where it is on that side within
    # ``snap`` of the side's mean, else the mean.
    limit = snap * jnp.abs(d_f - d_b)
    v_f = jnp.where(is_fg & (jnp.abs(d - d_f) <= limit), d, d_f)
    v_b = jnp.where(~is_fg & (jnp.abs(d - d_b) <= limit), d, d_b)
    # Within the soft band around 1/2, the blend of the two.
    p = jnp.clip(0.5 + (alpha - 0.5) / jnp.where(soft > 0, soft, 1.0), 0.0, 1.0)
    uncertain = jnp.abs(alpha - 0.5) < 0.5 * soft
    side = jnp.where(uncertain, p * v_f + (1.0 - p) * v_b, jnp.where(alpha > 0.5, v_f, v_b))
    return jnp.where(decide, side, d)


def _background_extent(d: Array, pure: Array, mid: Array, radius: int) -> Array:
    """Largest disparity at or below ``mid`` of the ``pure`` pixels (off every
    discontinuity) over each pixel's ``(2 radius + 1)²`` window, the pixel itself excluded
    (edge-replicated border; ``-inf`` where there is none). Only pure pixels count: a value
    between two surfaces on their boundary (a blend) is not a third surface."""
    H, W = d.shape
    r = radius
    d_p = edge_pad(jnp.where(pure, d, -jnp.inf), r)
    out = jnp.full_like(d, -jnp.inf)
    for a in range(-r, r + 1):
        for b in range(-r, r + 1):
            if a == 0 and b == 0:
                continue
            ds = d_p[r + a : r + a + H, r + b : r + b + W]
            out = jnp.maximum(out, jnp.where(ds <= mid, ds, -jnp.inf))
    return out


def split_candidates(
    disparity: Float[ArrayLike, "H W"],
    *,
    radius: int = 2,
    jump: float | Array = 0.2,
    capacity: int | None = None,
) -> Int[Array, " K"]:
    """The pixels where `boundary_matte` with ``split_background`` may split a background
    side: on the background side of a ``(2 radius + 1)²`` window whose background pixels off
    every discontinuity (3×3 range at most ``jump``) span, with the window's minimum, more
    than ``jump`` pixels per view step (three surfaces).

    Args:
        disparity: ``(H, W)`` float disparity (pixels per view step).
        radius, jump: as `boundary_matte`'s.
        capacity: length of the list (static int >= 1); default ``max(1024, H·W / 256)``
            (at most ``H·W``). Real 512² views have about 5–150 such pixels.

    Returns:
        ``(capacity,)`` int32: the row-major flat indices of the first ``capacity`` such
        pixels in order, padded with ``H·W`` (`pixel_subset`). jit/vmap-able.

    Raises:
        ValueError: on a non-2-D disparity, ``radius < 1`` or ``capacity < 1``.
    """
    d = jnp.asarray(disparity)
    if d.ndim != 2:
        raise ValueError(f"disparity must have shape (H, W); got {tuple(d.shape)}")
    radius = int(radius)
    if radius < 1:
        raise ValueError(f"radius must be >= 1; got {radius}")
    n = d.size
    capacity = min(n, max(1024, -(-n // 256))) if capacity is None else int(capacity)
    if capacity < 1:
        raise ValueError(f"capacity must be >= 1; got {capacity}")

    def may_choose(d):
        lo, hi = _window_extrema(d, radius)
        lo1, hi1 = _window_extrema(d, 1)
        mid = 0.5 * (lo + hi)
        bg_hi = _background_extent(d, (hi1 - lo1) <= jump, mid, radius)
        return (bg_hi - lo > jump) & (d <= mid)

    # The mask as the branch of a `lax.cond` whose predicate XLA cannot fold (a finite map's
    # first value equals itself), so that it is materialised: fused into `pixel_subset`,
    # XLA's CPU backend recomputes its window pass there (~6x the time of both). Under
    # `vmap` the cond becomes a select and the mask is fused again (correct, slower).
    mask = lax.cond(d[0, 0] == d[0, 0], may_choose, lambda d: jnp.zeros(d.shape, bool), d)
    return pixel_subset(mask.ravel(), capacity)


def _split_background(
    d, idx, jump, lo, mid, lo1, hi1, gc, d_p, g_p, p_p, r, spatial_sigma, min_separation,
    background, background_valid,
):  # fmt: skip
    """`boundary_matte`'s ``split_background`` for this view (index 0 of its stacks), at
    the listed pixels ``idx`` (`split_candidates`).

    The window sums of the two parts are gathered for the listed pixels only, from the
    padded inputs, not from `boundary_matte`'s full-frame sums, which XLA's CPU backend
    would recompute for every such use. The foreground colour of the part tests is the
    window mean of the foreground side's pixels.

    Args: the maps of `boundary_matte` (``gc``: this view's colour planes; ``d_p``, ``g_p``,
    ``p_p``: the map, this view's colour planes and the purities, padded by ``r``).

    Returns:
        ``(chosen, colour, weight, weighted_disparity)``: ``(H, W)`` bool, the pixels that
        chose a part, and that part's colour planes (a list of ``(H, W)``), weight and
        weighted disparity sums there (0 elsewhere).
    """
    H, W = d.shape
    n = H * W
    Wp = W + 2 * r
    C = len(gc)
    at = jnp.clip(idx, 0, n - 1)
    iy, ix = at // W, at % W

    def pick(x):
        return x.ravel()[at]

    # The background side's far/near threshold at each listed pixel, as `split_candidates`
    # finds it: +inf where the part does not exist. Gathered, the full-frame window pass
    # of `_background_extent` is evaluated at the listed pixels only.
    upper = pick(mid)
    lo_w = pick(lo)
    bg_hi = pick(_background_extent(d, (hi1 - lo1) <= jump, mid, r))
    threshold = jnp.where(bg_hi - lo_w > jump, 0.5 * (lo_w + bg_hi), jnp.inf)
    flat_d = d_p.ravel()
    zeros = jnp.zeros(idx.shape, d.dtype)
    w0 = w1 = d1 = w2 = d2 = zeros
    c0 = [zeros] * C
    c1 = [zeros] * C
    c2 = [zeros] * C
    flat_p, flat_g = p_p.ravel(), [x.ravel() for x in g_p]
    for a in range(-r, r + 1):
        for b in range(-r, r + 1):
            if a == 0 and b == 0:
                continue
            s = float(np.exp(-(a * a + b * b) / (2.0 * spatial_sigma**2)))
            fi = (iy + r + a) * Wp + (ix + r + b)
            ds = flat_d[fi]
            w = s * flat_p[fi]
            far = ds <= threshold
            fg = ds > upper
            w_0 = jnp.where(fg, w, 0.0)
            w_1 = jnp.where(far, w, 0.0)
            w_2 = jnp.where(far | fg, 0.0, w)
            w0, w1, w2 = w0 + w_0, w1 + w_1, w2 + w_2
            d1, d2 = d1 + w_1 * ds, d2 + w_2 * ds
            for c in range(C):
                gs = flat_g[c][fi]
                c0[c] = c0[c] + w_0 * gs
                c1[c] = c1[c] + w_1 * gs
                c2[c] = c2[c] + w_2 * gs
    tiny = jnp.asarray(1e-12, d.dtype)
    f = [x / jnp.maximum(w0, tiny) for x in c0]
    B_far = [x / jnp.maximum(w1, tiny) for x in c1]
    B_near = [x / jnp.maximum(w2, tiny) for x in c2]
    col = [pick(x) for x in gc]
    # Distinct parts: the far part's colour lies farther than ``min_separation`` from the
    # segment between the near part's and F (a third colour; a run of wrong far values
    # along the boundary between the near part and the foreground mixes those two).
    axis = [f[c] - B_near[c] for c in range(C)]
    t = sum((B_far[c] - B_near[c]) * axis[c] for c in range(C))
    t = jnp.clip(t / jnp.maximum(sum(x * x for x in axis), tiny), 0.0, 1.0)
    off_segment = sum((B_far[c] - B_near[c] - t * axis[c]) ** 2 for c in range(C))
    listed = (idx >= 0) & (idx < n) & (pick(d) <= upper)
    distinct = listed & (w0 > 0) & (w1 > 0) & (w2 > 0) & (off_segment > min_separation**2)
    if background is not None:
        # The observed background is the 3×3 window's farthest surface: the far part's,
        # unless that surface lies in the near part (the far one is then off the 3×3).
        valid = pick(background_valid)
        observed_near = pick(lo1) > threshold
        colour = [background[..., c].ravel()[at] for c in range(C)]
        B_far = [
            jnp.where(valid & ~observed_near, o, x) for o, x in zip(colour, B_far, strict=True)
        ]
        B_near = [
            jnp.where(valid & observed_near, o, x) for o, x in zip(colour, B_near, strict=True)
        ]

    def segment_distance(Bk):  # the pixel's colour from the segment between Bk and F
        sep = [f[c] - Bk[c] for c in range(C)]
        alpha = sum((col[c] - Bk[c]) * sep[c] for c in range(C))
        alpha = jnp.clip(alpha / jnp.maximum(sum(x * x for x in sep), tiny), 0.0, 1.0)
        return sum((col[c] - Bk[c] - alpha * sep[c]) ** 2 for c in range(C))

    near = segment_distance(B_near) < segment_distance(B_far)

    inside = jnp.where((idx >= 0) & (idx < n), idx, n)

    def frame(value):
        return jnp.zeros((n,), value.dtype).at[inside].set(value, mode="drop").reshape(H, W)

    colour = [frame(jnp.where(near, x2, x1)) for x2, x1 in zip(B_near, B_far, strict=True)]
    return (
        frame(distinct),
        colour,
        frame(jnp.where(near, w2, w1)),
        frame(jnp.where(near, d2, d1)),
    )


def _fit_at_pixel(
    w0: Array, c0: list[Array], moments: list[Array], colour_moments, ridge: float
) -> list[Array]:
    """Per channel, the value at the window centre of the weighted least-squares fit
    ``c(o) = m + g·o`` of one side's colours over the window offsets ``o = (a, b)``, with
    ``ridge · |g|²`` added (pixels² in weight units): ``m``, the first component of
    ``M⁻¹ (Σw c, Σw a c, Σw b c)``, ``M`` the side's ``3 × 3`` moment matrix plus the ridge.
    ``M`` is positive definite wherever the side has weight (``det M ≥ Σw · ridge²``), so
    the first row of its inverse comes from its cofactors; a side without weight gets 0."""
    sa, sb, saa, sbb, sab = moments
    saa, sbb = saa + ridge, sbb + ridge
    c00 = saa * sbb - sab * sab
    c01 = sab * sb - sa * sbb
    c02 = sa * sab - saa * sb
    det = w0 * c00 + sa * c01 + sb * c02
    inv = 1.0 / jnp.maximum(det, jnp.asarray(1e-12, w0.dtype))
    r0, r1, r2 = c00 * inv, c01 * inv, c02 * inv
    ca, cb = colour_moments
    return [r0 * c0[c] + r1 * ca[c] + r2 * cb[c] for c in range(len(c0))]


def near_surface_colours(
    disparity: Float[ArrayLike, "H W"],
    guides: Float[ArrayLike, "K H W C"],
    offsets: Float[ArrayLike, "K 2"],
    *,
    radius: int = 2,
    phase: float | Array = 0.5,
) -> tuple[Float[Array, "K H W C"], Float[Array, "K H W"]]:
    """Other views' colours where each pixel's nearest surface lies in them (the ``others``
    of `boundary_matte`).

    The nearest surface at pixel ``x`` of the view whose map is ``disparity`` has the
    largest disparity ``h`` of the pixel's ``(2 radius + 1)²`` window; in the view
    ``Δ = (dr, dc)`` view steps away it lies at ``x − h·Δ`` (the SPEC's sign). The sample is
    that view's pixel nearest to this position, not an interpolation: a pixel a
    depth edge crosses mixes the two surfaces by the share of its area each covers, and only
    a whole pixel at the same position relative to the foreground edge has the same share.
    Its weight falls with the distance ``φ`` (pixels, at most 1/2: the larger of the row and
    column distances) between the pixel and the position: ``max(0, 1 − φ / phase)``;
    samples whose position lies outside the frame weigh 0.

    Not in the thesis; measurements in docs/ACCURACY.md ("Colour mixtures from several
    views").

    Args:
        disparity: ``(H, W)`` float disparity of this view (pixels per view step).
        guides: ``(K, H, W, C)`` float colours of ``K`` other views (those of the matte).
        offsets: ``(K, 2)`` ``(dr, dc)`` of each other view relative to this view, in view
            steps.
        radius: window radius of the nearest surface (static int >= 1; the matte's).
        phase: distance (pixels, > 0; a scalar, may be traced, then unchecked) at which a
            sample's weight reaches 0.

    The nearest surface is taken per pixel, so across a matte window it is one value only
    where one foreground lies within ``radius`` of every window pixel; a window pixel farther
    from the foreground is sampled at its own surface, which in views where the foreground
    moves over it can be the foreground (docs/ACCURACY.md).

    Returns:
        ``(colours (K, H, W, C), weights (K, H, W))``: the colours in the guides' dtype, the
        weights in the disparity's. Not differentiable (a selection of pixels; the weights
        carry no gradient).

    Raises:
        ValueError: on a non-2-D disparity, guides that are not ``(K, H, W, C)`` of the
            disparity's ``(H, W)``, offsets that are not ``(K, 2)``, ``radius < 1`` or
            ``phase <= 0``.
    """
    d = jnp.asarray(disparity)
    g = jnp.asarray(guides)
    offsets = jnp.asarray(offsets, d.dtype)
    if d.ndim != 2:
        raise ValueError(f"disparity must have shape (H, W); got {tuple(d.shape)}")
    H, W = d.shape
    if g.ndim != 4 or g.shape[1:3] != (H, W):
        raise ValueError(f"guides must have shape (K, {H}, {W}, C); got {tuple(g.shape)}")
    if offsets.shape != (g.shape[0], 2):
        raise ValueError(f"offsets must have shape {(g.shape[0], 2)}; got {tuple(offsets.shape)}")
    radius = int(radius)
    if radius < 1:
        raise ValueError(f"radius must be >= 1; got {radius}")
    check_lower_bound("phase", phase, 0.0, open_=True)
    h = lax.stop_gradient(_window_extrema(d, radius)[1])
    ys = jnp.arange(H, dtype=d.dtype)[:, None]
    xs = jnp.arange(W, dtype=d.dtype)[None, :]

    def one(guide, off):
        sy, sx = ys - off[0] * h, xs - off[1] * h
        py, px = jnp.round(sy), jnp.round(sx)
        dist = jnp.maximum(jnp.abs(sy - py), jnp.abs(sx - px))
        inside = (py >= 0) & (py <= H - 1) & (px >= 0) & (px <= W - 1)
        weight = jnp.where(inside, jnp.clip(1.0 - dist / phase, 0.0, 1.0), 0.0)
        iy = jnp.clip(py, 0, H - 1).astype(jnp.int32)
        ix = jnp.clip(px, 0, W - 1).astype(jnp.int32)
        return guide[iy, ix], weight

    return jax.vmap(one)(g, offsets)


# Directions (row, column) along which `observed_background` looks for the background.
_AXES = ((0, 1), (0, -1), (1, 0), (-1, 0))


def observed_background(
    row: Int[ArrayLike, ""],
    col: Int[ArrayLike, ""],
    background_disparity: Float[ArrayLike, "H W"],
    guides: Float[ArrayLike, "U V H W C"],
    maps: Float[ArrayLike, "U V H W"],
    present: Bool[ArrayLike, "U V"],
    *,
    steps: int = 4,
    tolerance: float | Array = 0.5,
    where: Bool[ArrayLike, "H W"] | None = None,
    capacity: int | None = None,
) -> tuple[Float[Array, "H W C"], Bool[Array, "H W"]]:
    """The colour of the background surface at every pixel of one view, seen by other views.

    Where a depth edge crosses pixel ``x`` of view ``(row, col)``, the pixel mixes the
    foreground and the background colour. The background surface point at ``x``, of
    disparity ``b = background_disparity[x]``, lies at ``x − b·Δ`` in the view ``Δ`` view
    steps away (``Δ = (dr, dc)``, rows and columns; the SPEC's sign), and views on the far side
    of the edge see it unoccluded, away from the foreground edge, which moves with the
    foreground's larger disparity. Candidates: the views ``1 … steps`` steps away along the
    four axis directions (those inside the grid and ``present``). A candidate sample, at the
    nearest pixel of ``x − b·Δ`` inside the frame, counts where the candidate view's map
    (``maps``) spans less than ``tolerance`` over the 3×3 window there and lies within
    ``tolerance`` of ``b``: the sample is the background surface, away from its boundary.
    The result is the mean colour of the samples that count.

    With ``where``, only the pixels of ``where`` are computed, the first ``capacity`` of them
    in row-major order (a fixed-size subset, e.g. the depth edges, whose size must be
    static); the others are not valid.

    Not in the thesis; it is the background colour of `boundary_matte` for the views'
    maps (`SharpenConfig.matte_view_steps`); measurements in docs/ACCURACY.md.

    Args:
        row, col: the view (int scalars; may be traced).
        background_disparity: ``(H, W)`` background disparity of every pixel of the view
            (pixels per view step), e.g. the window minimum of its map.
        guides: ``(U, V, H, W, C)`` colour guides of every view (those of the matte).
        maps: ``(U, V, H, W)`` disparity map of every view (pixels per view step).
        present: ``(U, V)`` bool, views that hold an image (partial grids).
        steps: largest distance of a candidate view, view steps (static int >= 1).
        tolerance: largest range of the candidate's map over the 3×3 window, and largest
            difference from ``b``, pixels per view step.
        where: ``(H, W)`` bool, the pixels to compute (default: all).
        capacity: how many pixels of ``where`` at most (static int >= 1; default: all
            ``H·W``).

    Returns:
        ``(colour (H, W, C), valid (H, W) bool)``: the mean observed background colour and
        where at least one sample counts (colour 0 elsewhere). Not differentiable (a
        selection of samples).

    Raises:
        ValueError: on shapes that do not match, ``steps < 1`` or ``capacity < 1``.
    """
    g = jnp.asarray(guides)
    b = jnp.asarray(background_disparity)
    maps = jnp.asarray(maps)
    present = jnp.asarray(present, bool)
    if g.ndim != 5:
        raise ValueError(f"guides must have shape (U, V, H, W, C); got {tuple(g.shape)}")
    U, V, H, W, C = g.shape
    if b.shape != (H, W) or maps.shape != (U, V, H, W):
        raise ValueError(
            f"background_disparity must have shape {(H, W)} and maps {(U, V, H, W)}; "
            f"got {tuple(b.shape)} and {tuple(maps.shape)}"
        )
    if present.shape != (U, V):
        raise ValueError(f"present must have shape {(U, V)}; got {tuple(present.shape)}")
    steps = int(steps)
    if steps < 1:
        raise ValueError(f"steps must be >= 1; got {steps}")
    n = H * W
    capacity = n if capacity is None else int(capacity)
    if capacity < 1:
        raise ValueError(f"capacity must be >= 1; got {capacity}")
    if where is None:
        where = jnp.ones((H, W), bool)
    else:
        where = jnp.asarray(where, bool)
        if where.shape != (H, W):
            raise ValueError(f"where must have shape {(H, W)}; got {tuple(where.shape)}")
    lo, hi = jax.vmap(jax.vmap(lambda m: _window_extrema(m, 1)))(maps)
    surface = smooth_surface(maps, lo, hi, tolerance)
    flat = pixel_subset(where.ravel(), min(capacity, n))
    bs = lax.stop_gradient(b.ravel()[jnp.minimum(flat, n - 1)])
    colour, valid = background_samples(
        row, col, flat, bs, g, surface, present, steps=steps, tolerance=tolerance
    )
    return samples_to_frame(flat, colour, valid, (H, W))


def samples_to_frame(
    flat: Int[Array, " K"], colour: Float[Array, "K C"], valid: Bool[Array, " K"], shape
) -> tuple[Float[Array, "H W C"], Bool[Array, "H W"]]:
    """The samples of `background_samples` at the flat indices ``flat`` (padding dropped)
    placed in an ``(H, W)`` frame: ``(colour (H, W, C), 0 where not valid; valid (H, W))``
    (one scatter: the invalid entries travel as NaN)."""
    H, W = shape
    C = colour.shape[-1]
    coded = jnp.where(valid[:, None], colour, jnp.nan)
    frame = jnp.full((H * W, C), jnp.nan, colour.dtype).at[flat].set(coded, mode="drop")
    frame = frame.reshape(H, W, C)
    ok = jnp.isfinite(frame[..., 0])
    return jnp.where(ok[..., None], frame, 0.0), ok


def smooth_surface(maps: Array, low: Array, high: Array, tolerance) -> Array:
    """``maps`` where the 3×3 window (extrema ``low``, ``high``) spans less than
    ``tolerance``, NaN elsewhere (no sample of `background_samples` counts there)."""
    return jnp.where(high - low < tolerance, maps, jnp.nan)


#: Multiples of the jump threshold that `largest_jumps` tries, smallest first.
LIST_STEPS = (1.0, 1.25, 1.5, 2.0, 3.0, 4.0, 8.0)


def largest_jumps(
    span: Float[Array, "N H W"], jump: Float[ArrayLike, ""], capacity: int
) -> Bool[Array, "N H W"]:
    """Per map, the pixels whose disparity span exceeds the smallest threshold of
    ``jump × LIST_STEPS`` that at most ``capacity`` pixels of the map exceed.

    Where more pixels than a fixed-size list holds are on a discontinuity, this keeps the
    list for the largest jumps instead of the first pixels in raster order. The pixels above
    each threshold are counted on every other row and column (times 4: one pass over a
    quarter of the map, ~30 ms for 80 maps of 512²), so a map can exceed ``capacity`` by a
    few pixels, which the list then leaves out. A map whose pixels exceed even the largest
    threshold more than ``capacity`` times gets that threshold's mask. A list that holds the
    whole map takes every pixel above ``jump`` (nothing is counted).

    Args:
        span: ``(N, H, W)`` disparity range of each pixel's window (pixels per view step).
        jump: the smallest threshold (scalar, pixels per view step).
        capacity: the list's size (static int >= 1).

    Returns:
        ``(N, H, W)`` bool.
    """
    span = jnp.asarray(span)
    if capacity >= span[0].size:
        return span > jump
    thresholds = jnp.asarray(jump, span.dtype) * jnp.asarray(LIST_STEPS, span.dtype)
    k_max = len(LIST_STEPS)
    sub = span[:, ::2, ::2]
    # Number of thresholds each sampled pixel exceeds, 0..k_max, and its histogram per map.
    level = sum((sub > thresholds[k]).astype(jnp.int32) for k in range(k_max))
    hist = jax.vmap(lambda m: jnp.bincount(m.ravel(), length=k_max + 1))(level)
    # Pixels above threshold k: the histogram's tail from k + 1, scaled to the whole map.
    above = jnp.cumsum(hist[:, ::-1], axis=1)[:, ::-1][:, 1:] * (span[0].size / sub[0].size)
    fits = above <= capacity
    k = jnp.where(fits.any(axis=1), jnp.argmax(fits, axis=1), k_max - 1)
    return span > thresholds[k][:, None, None]


def pixel_subset(where: Bool[Array, "*B N"], capacity: int) -> Int[Array, "*B K"]:
    """The flat indices of the first ``capacity`` pixels of ``where`` (a flattened frame),
    in order, padded with ``N`` (an index outside the frame) to ``capacity``; per frame of
    a leading batch ``*B``.

    Equal to ``jnp.nonzero(where, size=capacity, fill_value=N)`` per frame; the running
    count is formed by two levels of 64-wide triangular matrix products (exact in float32
    below 2²⁴ pixels), ~1.5x faster than the cumulative sum of `jnp.nonzero` on XLA's CPU
    backend. Below 2²⁴ pixels per frame the frames of a batch share one unbatched scatter
    (rather than the batched one that ``vmap`` would make: see
    `mvedge_jax.lightfield.forward_project_views`).
    """
    batch, n = where.shape[:-1], where.shape[-1]
    rows = where.reshape(-1, n)
    b = rows.shape[0]
    if n >= 2**24:
        return (
            jax.vmap(lambda w: jnp.nonzero(w, size=capacity, fill_value=n)[0])(rows)
            .astype(jnp.int32)
            .reshape(*batch, capacity)
        )
    slot = jax.vmap(lambda w: _subset_slots(w, capacity))(rows)
    # One flat list of ``b`` frames' slots; a pixel beyond its frame's capacity is dropped.
    flat = jnp.where(
        slot < capacity, slot + capacity * jnp.arange(b, dtype=jnp.int32)[:, None], b * capacity
    )
    index = jnp.broadcast_to(jnp.arange(n, dtype=jnp.int32), (b, n))
    out = jnp.full((b * capacity,), n, jnp.int32).at[flat.ravel()].set(index.ravel(), mode="drop")
    return out.reshape(*batch, capacity)


def _subset_slots(where: Bool[Array, " N"], capacity: int) -> Int[Array, " N"]:
    """Each pixel's slot in `pixel_subset`'s list (its rank among the pixels of ``where``),
    ``capacity`` for the pixels that are not listed."""
    n = where.size
    block = 64
    m = -(-n // block**2) * block**2
    x = jnp.pad(where.astype(jnp.float32), (0, m - n)).reshape(m // block, block)
    tri = jnp.triu(jnp.ones((block, block), jnp.float32))
    hi = lax.Precision.HIGHEST  # exact either way (0/1 and counts <= 64); explicit for GPUs
    within = jnp.matmul(x, tri, precision=hi)  # inclusive running count per block of 64
    totals = within[:, -1].reshape(-1, block)
    groups = jnp.matmul(totals, tri, precision=hi)  # ... of the block totals per 64 blocks
    before_group = jnp.cumsum(groups[:, -1]) - groups[:, -1]
    before_block = (groups - totals + before_group[:, None]).ravel()
    rank = (within + before_block[:, None]).ravel()[:n].astype(jnp.int32) - 1
    return jnp.where(where & (rank < capacity), rank, capacity)


def background_samples(
    row: Int[ArrayLike, ""],
    col: Int[ArrayLike, ""],
    flat: Int[Array, " K"],
    background_disparity: Float[Array, " K"],
    guides: Float[Array, "U V H W C"],
    surface: Float[Array, "U V H W"],
    present: Bool[Array, "U V"],
    *,
    steps: int,
    tolerance: float | Array,
) -> tuple[Float[Array, "K C"], Bool[Array, " K"]]:
    """`observed_background` at the pixels ``flat`` (row-major indices; ``H·W`` or above =
    padding, never valid) of background disparity ``background_disparity``, with the
    `smooth_surface` of every view's map: the mean colour of the samples that count and
    whether any does (shapes checked by the caller)."""
    U, V, H, W, C = guides.shape
    n = H * W
    used = flat < n
    pix = jnp.minimum(flat, n - 1)
    ys, xs = pix // W, pix % W
    bs = background_disparity
    total = jnp.zeros((pix.shape[0], C), guides.dtype)
    count = jnp.zeros(pix.shape, jnp.int32)
    for dr, dc in _AXES:
        for k in range(1, steps + 1):
            r2, c2 = row + dr * k, col + dc * k
            view_ok = (r2 >= 0) & (r2 < U) & (c2 >= 0) & (c2 < V)
            r2, c2 = jnp.clip(r2, 0, U - 1), jnp.clip(c2, 0, V - 1)
            view_ok = view_ok & present[r2, c2]
            py = jnp.round(ys - (dr * k) * bs).astype(jnp.int32)
            px = jnp.round(xs - (dc * k) * bs).astype(jnp.int32)
            inside = (py >= 0) & (py < H) & (px >= 0) & (px < W)
            py, px = jnp.clip(py, 0, H - 1), jnp.clip(px, 0, W - 1)
            # NaN (a window across a discontinuity) fails the comparison.
            ok = view_ok & used & inside & (jnp.abs(surface[r2, c2, py, px] - bs) < tolerance)
            total = total + jnp.where(ok[:, None], guides[r2, c2, py, px], 0.0)
            count = count + ok.astype(jnp.int32)
    return total / jnp.maximum(count, 1)[:, None].astype(guides.dtype), count > 0
