"""Stages that look across EPIs in the centre view: outlier rejection (eqs 4.1–4.2) and the
trilateral filter of the sparse disparities (eq 4.6)."""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Bool, Float, Int

from ._config import EdgeConfig
from ._edgeset import EdgeSet


def _box_sum(img: Float[Array, "... H W"], ry: int, rx: int) -> Float[Array, "... H W"]:
    """Sum over the (2ry+1) x (2rx+1) window around each pixel (zero outside), via cumsums."""
    H, W = img.shape[-2:]

    def along(a, r, axis):
        n = a.shape[axis]
        c = jnp.cumsum(a, axis=axis)
        pad = [(0, 0)] * a.ndim
        pad[axis] = (1, 0)
        c = jnp.pad(c, pad)  # c[i] = sum a[:i]
        hi = jnp.clip(jnp.arange(n) + r + 1, 0, n)
        lo = jnp.clip(jnp.arange(n) - r, 0, n)
        return jnp.take(c, hi, axis=axis) - jnp.take(c, lo, axis=axis)

    return along(along(img, ry, img.ndim - 2), rx, img.ndim - 1)


def reject_outliers(
    edges: EdgeSet, labels: Int[Array, " N"], shape: tuple[int, int], config: EdgeConfig
) -> Bool[Array, " N"]:
    """Keep-mask of the neighbour-count outlier test (eqs 4.1–4.2), per EPI direction.

    ``A(l_i)`` = lines of the same direction within a ``p x q`` window (``p, q`` =
    ``outliers.window_frac`` of the width / height) whose filter label is within
    ``outliers.label_tol`` of ``l_i``'s. With ``config.outliers.test = "count"`` (the thesis)
    ``l_i`` is discarded when ``c_i |A(l_i)| / (p q) < τ``; with ``"agreement"`` when
    ``|A(l_i)| / |N(l_i)| < outliers.min_agreement``, ``N(l_i)`` all lines of the direction in
    the window: a point is an outlier when its neighbours disagree with it, not when it has
    few neighbours (isolated points on sparsely textured surfaces are kept).

    Args:
        edges: the edge set (centre-view positions).
        labels: ``(N,)`` int filter label of each point.
        shape: ``(H, W)`` of the centre view.
        config: `EdgeConfig` (``outliers.window_frac``, ``outliers.label_tol``, ``outliers.tau``).

    Returns:
        ``(N,)`` bool, True = keep (invalid points are returned False).

    References:
        Thesis Sec. 4.1.3, eqs 4.1–4.2.
    """
    H, W = shape
    n = config.filter.n_filters
    p = max(1, round(W * config.outliers.window_frac))
    q = max(1, round(H * config.outliers.window_frac))
    xi = jnp.clip(jnp.round(edges.x).astype(jnp.int32), 0, W - 1)
    yi = jnp.clip(jnp.round(edges.y).astype(jnp.int32), 0, H - 1)
    lab = jnp.clip(labels, 0, n - 1)
    keep = jnp.zeros_like(edges.valid)
    for direction in (0, 1):
        sel = edges.valid & (edges.direction == direction)
        grid = jnp.zeros((n, H, W), jnp.float32).at[lab, yi, xi].add(sel.astype(jnp.float32))
        counts = _box_sum(grid, q // 2, p // 2)  # (n, H, W)
        total = jnp.sum(counts, axis=0)[yi, xi]
        tol = config.outliers.label_tol
        if tol:
            cs = jnp.pad(jnp.cumsum(counts, axis=0), ((1, 0), (0, 0), (0, 0)))
            hi = jnp.clip(jnp.arange(n) + tol + 1, 0, n)
            lo = jnp.clip(jnp.arange(n) - tol, 0, n)
            counts = cs[hi] - cs[lo]
        a = counts[lab, yi, xi]
        if config.outliers.test == "agreement":
            ok = a >= config.outliers.min_agreement * total
        else:
            ok = edges.confidence * a / (p * q) >= config.outliers.tau
        keep = keep | (sel & ok)
    return keep


def trilateral_filter(
    edges: EdgeSet, shape: tuple[int, int], config: EdgeConfig
) -> Float[Array, " N"]:
    """Joint spatial / disparity / colour filter of the sparse disparities (eq 4.6).

    ``f(p_d) = Σ_q N_σs(|p_s - q_s|) N_σd(p_d - q_d) N_σc(|p_c - q_c|) q_d / W`` over the valid
    visible points ``q`` (both directions) in a ``(2r+1)^2`` window,
    ``r = refine.trilateral_radius``. Points are rasterised to the centre-view pixel grid (one
    per pixel and EPI direction: of several points on one pixel, the one of the highest index)
    and the filter runs densely on the grids: a ``lax.fori_loop``
    over the window rows, each step a few element-wise operations on ``(H, W)`` grids per
    window column and pair of directions. Colour distances use LAB / 100.

    Returns:
        ``(N,)`` filtered disparities (unchanged for invalid points).

    References:
        Thesis Sec. 4.1.5, eq 4.6.
    """
    H, W = shape
    r = config.refine.trilateral_radius
    xi = jnp.clip(jnp.round(edges.x).astype(jnp.int32), 0, W - 1)
    yi = jnp.clip(jnp.round(edges.y).astype(jnp.int32), 0, H - 1)
    use = edges.valid & edges.visible
    lab = edges.lab * 0.01
    # Rasterise: channels (mask, d, L, a, b), one grid per direction.
    vals = jnp.concatenate(
        [jnp.ones_like(edges.disparity)[:, None], edges.disparity[:, None], lab], 1
    )
    ch = edges.direction.astype(jnp.int32)
    ys = jnp.where(use, yi, H + 1)  # out of bounds: not rasterised
    dt = vals.dtype
    # The point kept on a pixel is chosen by an integer max, not left to the order in which a
    # scatter applies repeated indices (unspecified, and not fixed from run to run on a GPU).
    n_pts = vals.shape[0]
    last = jnp.full((2, H, W), -1, jnp.int32)
    last = last.at[ch, ys, xi].max(jnp.arange(n_pts, dtype=jnp.int32), mode="drop")
    grid = jnp.where((last >= 0)[..., None], vals[jnp.maximum(last, 0)], 0.0)
    p = jnp.moveaxis(grid, -1, 0)  # (5, 2, H, W)
    q = jnp.pad(p, ((0, 0), (0, 0), (r, r), (r, r)))
    a_s = 0.5 / config.refine.sigma_s**2
    a_d = 0.5 / config.refine.sigma_d**2
    a_c = 0.5 / config.refine.sigma_c**2
    side = 2 * r + 1

    def body(dy, carry):
        # One window row per step; its columns are static slices of the row band. The terms
        # are written out per direction pair and channel: reducing over short leading axes
        # of stacked arrays runs several times slower on XLA's CPU backend.
        num, den = carry
        band = lax.dynamic_slice(q, (0, 0, dy, 0), (5, 2, H, W + 2 * r))
        for dx in range(side):
            qk = band[..., dx : dx + W]
            e_s = a_s * ((dy - r) ** 2 + (dx - r) ** 2).astype(dt)
            for i in range(2):  # direction of the filtered point
                w = []
                for j in range(2):  # direction of the neighbour
                    colour = sum((p[c, i] - qk[c, j]) ** 2 for c in (2, 3, 4))
                    e = e_s + a_d * (p[1, i] - qk[1, j]) ** 2 + a_c * colour
                    w.append(qk[0, j] * jnp.exp(-e))
                num = num.at[i].add(w[0] * qk[1, 0] + w[1] * qk[1, 1])
                den = den.at[i].add(w[0] + w[1])
        return num, den

    zero = jnp.zeros((2, H, W), dt)
    num, den = lax.fori_loop(0, side, body, (zero, zero))
    # A pixel that holds a point weighs itself by exp(0) = 1, so den >= 1 there; elsewhere the
    # quotient is not used, and dividing by 1 keeps its gradient finite.
    occupied = grid[..., 0] > 0
    filt = num / jnp.where(occupied, den, 1.0)
    ok = use & occupied[ch, yi, xi]
    return jnp.where(ok, filt[ch, yi, xi], edges.disparity)
