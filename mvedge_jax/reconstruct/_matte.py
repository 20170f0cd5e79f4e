"""Boundary matting: put depth discontinuities on the right pixel from the colour mixture."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

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
    between fine repeated structures), and near-ties ``|α − 1/2| ≤ 10⁻³``. One pass;
    jit/vmap-able. Not differentiable in the side chosen (a selection); the output is
    piecewise a weighted mean of the input.

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

    Returns:
        ``(H, W)`` disparity, same dtype as ``disparity``.

    Raises:
        ValueError: on a non-2-D disparity, a guide of another ``(H, W)``, ``radius < 1`` or
            ``spatial_sigma <= 0``.
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
    H, W = d.shape
    lo, hi = _window_extrema(d, radius)
    band = (hi - lo) > jump
    lo1, hi1 = _window_extrema(d, 1)
    purity = jnp.where((hi1 - lo1) > jump, jnp.asarray(impure_weight, d.dtype), 1.0)
    mid = 0.5 * (lo + hi)

    r = radius
    d_p = jnp.pad(d, r, mode="edge")
    g_p = jnp.pad(g, ((r, r), (r, r), (0, 0)), mode="edge")
    p_p = jnp.pad(purity, r, mode="edge")
    zeros = jnp.zeros_like(d)
    wf = wb = df = db = zeros
    cf = cb = jnp.zeros_like(g)
    # Static unrolled loop over the window offsets: XLA fuses it into one pass.
    for a in range(-r, r + 1):
        for b in range(-r, r + 1):
            if a == 0 and b == 0:
                continue
            s = float(np.exp(-(a * a + b * b) / (2.0 * spatial_sigma**2)))
            ds = d_p[r + a : r + a + H, r + b : r + b + W]
            gs = g_p[r + a : r + a + H, r + b : r + b + W]
            w = s * p_p[r + a : r + a + H, r + b : r + b + W]
            fg = ds > mid
            # Two selections, not ``w - w_f``: a compiler may contract the difference into
            # a fused multiply-add and leave the rounding error of ``w`` (~1e-17) as the
            # weight of an empty side, which then passes the ``wb > 0`` test.
            w_f = jnp.where(fg, w, 0.0)
            w_b = jnp.where(fg, 0.0, w)
            wf, wb = wf + w_f, wb + w_b
            df, db = df + w_f * ds, db + w_b * ds
            cf, cb = cf + w_f[..., None] * gs, cb + w_b[..., None] * gs
    tiny = jnp.asarray(1e-12, d.dtype)
    F = cf / jnp.maximum(wf, tiny)[..., None]
    B = cb / jnp.maximum(wb, tiny)[..., None]
    sep = F - B
    sep2 = jnp.sum(sep * sep, axis=-1)
    alpha = jnp.sum((g - B) * sep, axis=-1) / jnp.maximum(sep2, tiny)
    # Near-ties (alpha ~ 1/2, e.g. an edge through the centre of a pixel) keep their value,
    # so that rounding differences cannot flip a decision.
    decide = band & (wf > 0) & (wb > 0) & (sep2 > min_separation**2) & (jnp.abs(alpha - 0.5) > 1e-3)
    # Two-colour model test: the pixel's colour must lie near the line through B and F.
    off_line = g - B - alpha[..., None] * sep
    decide = decide & (jnp.sum(off_line * off_line, axis=-1) <= max_residual * sep2)
    is_fg = d > mid
    d_f = df / jnp.maximum(wf, tiny)
    d_b = db / jnp.maximum(wb, tiny)
    # A pixel only joins a side that one of its 8 neighbours is on: where three surfaces
    # meet, the mean background of the window can look like the foreground's colour.
    decide = decide & jnp.where(alpha > 0.5, hi1 > mid, lo1 <= mid)
    new = jnp.where(alpha > 0.5, jnp.where(is_fg, d, d_f), jnp.where(is_fg, d_b, d))
    return jnp.where(decide, new, d)
