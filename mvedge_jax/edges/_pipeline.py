"""`detect_edges`: the multi-view edge detector end to end (thesis Ch. 4.1)."""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Float

from ..lightfield import LightField, rgb_to_lab
from ._bank import bank_width, blur_images, filter_disparities, prewitt_bank
from ._config import EdgeConfig
from ._detect import (
    centre_response_magnitude,
    detect_centre_row,
    local_std,
    non_max_suppress,
    parabola_offset,
    soft_select,
    top_candidates,
)
from ._edgeset import HORIZONTAL, VERTICAL, EdgeSet, concatenate
from ._fit import fit_lines
from ._global import reject_outliers, trilateral_filter
from ._refine import (
    alignment_cosines,
    best_side_std,
    entropy_search,
    sample_epi,
    sobel_tensor,
    variance_search,
)

# LAB is scaled by 1/100 inside the detector (L* in [0, 1], a*, b* in about [-1.3, 1.3]).
_LAB_SCALE = 0.01


def resolve_d_max(config: EdgeConfig, disparity_range: tuple[float, float] | None) -> float:
    """Half-range of the filter bank for a scene (see `FilterConfig.d_max`).

    Raises:
        ValueError: if the scene's disparity range is not covered by ``config.filter.d_max``.
    """
    fc = config.filter
    if fc.d_max is not None:
        if disparity_range is not None:
            lo, hi = disparity_range
            if max(abs(lo), abs(hi)) > fc.d_max:
                raise ValueError(
                    f"the filter bank covers disparities [-{fc.d_max}, {fc.d_max}] but "
                    f"the scene's range is [{lo}, {hi}]; raise EdgeConfig.filter.d_max"
                )
        return float(fc.d_max)
    if disparity_range is not None:
        lo, hi = disparity_range
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise ValueError(f"invalid disparity range {disparity_range}")
        return max(abs(lo), abs(hi)) + fc.d_margin
    return float(fc.d_max_fallback)


def build_bank(config: EdgeConfig, n_views: int, d_max: float):
    """The bank of one EPI direction: ``(disparities (n,), bank (n, h, Fw))``.

    Alg. 1 uses filters of about twice the EPI height so that every EPI row sees the whole
    EPI; centred on the centre row (the only row evaluated here), only the central ``h`` rows
    of such a filter meet the EPI, so the bank is built with height ``h`` and the width its
    steepest line needs.
    """
    disps = filter_disparities(config.filter.n_filters, d_max)
    h = n_views if n_views % 2 else n_views + 1
    width = bank_width(h, d_max, 1.5) + 2  # room for edge_shift up to 1.5 and anti-aliasing
    return disps, prewitt_bank(
        disps, h, width, shift=config.filter.edge_shift, aa_sigma=config.filter.aa_sigma
    )


def _to_lab(views: Float[Array, "N H W 3"], config: EdgeConfig):
    lab = rgb_to_lab(views) * _LAB_SCALE
    blur = blur_images(lab, config.filter.presmooth_sigma, config.filter.blur_radius)
    return lab, blur


def _candidates(blur, disps, bank, d_max: float, config: EdgeConfig) -> dict[str, Array]:
    """Alg. 1 on the centre row of EPIs ``(N, h, W, C)``: the ``K`` strongest candidates per EPI
    with sub-pixel position and initial disparity (label, plus the parabolic offset)."""
    N, h, W, _ = blur.shape
    n = disps.shape[0]
    spacing = 2.0 * d_max / (n - 1)  # static
    lc = config.label
    det = detect_centre_row(blur, bank, chunk=config.filter.chunk)
    std3 = local_std(blur)
    craw = det["conf"]
    conf = (non_max_suppress(craw) if lc.nms else craw) * std3
    conf = jnp.where(std3 >= lc.min_local_std, conf, 0.0)
    cap = W if lc.line_capacity is None else lc.line_capacity
    idx, cvalid, overflow = top_candidates(conf, cap, lc.min_confidence)
    g = lambda a: jnp.take_along_axis(a, idx, axis=1)
    label = g(det["label"])
    # Sub-pixel position across the edge: parabola through the max response at x-1, x, x+1.
    cm = jnp.take_along_axis(craw, jnp.clip(idx - 1, 0, W - 1), 1)
    cp = jnp.take_along_axis(craw, jnp.clip(idx + 1, 0, W - 1), 1)
    xc = idx.astype(jnp.float32) + parabola_offset(cm, g(craw), cp)
    d = disps[label]
    if lc.subpixel in ("parabolic", "variance"):
        interior = (label > 0) & (label < n - 1)
        off = parabola_offset(g(det["r_prev"]), g(craw), g(det["r_next"]))
        d = d + jnp.where(interior, off, 0.0) * spacing
    return {
        "pos": xc,
        "disparity": d,
        "confidence": g(conf),
        "label": label,
        "valid": cvalid,
        "overflow": jnp.sum(overflow),
    }


def _refine_lines(raw, blur, cand, radius: float, config: EdgeConfig, key) -> dict[str, Array]:
    """Sub-pixel search, filters, line fitting, alignment / visibility tests and the entropy
    search for candidate lines ``(N, K)`` of EPIs ``(N, h, W, C)``."""
    N, h, W, _ = raw.shape
    xc, d, valid = cand["pos"], cand["disparity"], cand["valid"]
    lc, rc = config.label, config.refine
    if lc.subpixel == "variance":
        d, std, _, ratio = jax.lax.map(
            lambda a: variance_search(
                a[0],
                a[1],
                a[2],
                radius=radius,
                offset=lc.variance_offset,
                steps=lc.variance_steps,
                cubic=lc.cubic,
            ),
            (blur if lc.variance_on_blurred else raw, xc, d),
            batch_size=min(lc.refine_chunk, N),
        )
        valid = valid & (ratio >= lc.min_ratio)
    else:
        std = jax.vmap(lambda e, x, dd: best_side_std(e, x, dd, lc.variance_offset))(raw, xc, d)
    valid = valid & (std <= lc.max_colour_std)
    # ---- line fitting (4.1.2) among the reliable candidates ----------------------------------
    uc = jnp.full_like(xc, h // 2)
    lam = lc.lambda_frac * h
    valid = jax.vmap(fit_lines, in_axes=(0, 0, 0, 0, None))(uc, xc, d, valid, lam)
    # ---- gradient alignment (eq 4.3) and centre-view visibility (eq 4.4) --------------------
    if rc.gradient_alignment:
        tens = jax.vmap(sobel_tensor)(blur)
        cos = jax.vmap(alignment_cosines)(tens, xc, d)  # (N, K, h)
        visible = cos[..., h // 2] > jnp.cos(rc.tau_v)
        aligned = jnp.sum(cos > jnp.cos(rc.tau_f), axis=-1)
        valid = valid & (aligned >= h / rc.alignment_c)
    else:  # only the centre row is needed for the visibility test
        tens = jax.vmap(sobel_tensor)(blur[:, h // 2 - 1 : h // 2 + 2])[:, 1:2]
        cos = jax.vmap(alignment_cosines)(tens, xc, d)  # (N, K, 1)
        visible = cos[..., 0] > jnp.cos(rc.tau_v)
    if rc.drop_invisible:
        valid = valid & visible
    # ---- entropy-based random search of the intercepts (eq 4.5) ------------------------------
    xt = xc + (h // 2) * d
    xb = xc - (h - 1 - h // 2) * d
    if rc.entropy_search:
        keys = jax.random.split(key, N)
        xt, xb = jax.vmap(
            lambda e, a, b, act, k: entropy_search(
                e,
                a,
                b,
                act,
                k,
                iters=rc.entropy_iters,
                t=rc.entropy_t,
                alpha=rc.entropy_alpha,
                bins=rc.entropy_bins,
            )
        )(raw[..., 0], xt, xb, valid & visible, keys)
        d = (xt - xb) / (h - 1)
        xc = xt - (h // 2) * d
    lab = jax.vmap(lambda e, x: sample_epi(e[h // 2][None], x[:, None])[:, 0])(raw, xc)
    inside = (xc >= 0) & (xc <= W - 1)
    return {
        "pos": xc,
        "disparity": d,
        "confidence": cand["confidence"],
        "label": cand["label"],
        "valid": valid & inside,
        "visible": visible,
        "lab": lab / _LAB_SCALE,
        "xt": xt,
        "xb": xb,
        "overflow": cand["overflow"],
    }


def _epis(views, perm, config):
    raw, blur = _to_lab(views, config)
    # Materialise the transposed EPIs once (otherwise the transpose fuses into the consumers).
    return lax.optimization_barrier((jnp.transpose(raw, perm), jnp.transpose(blur, perm)))


def _direction_lines(views, perm, d_max: float, config: EdgeConfig, key) -> dict[str, Array]:
    """All lines of one EPI direction; ``views (n, H, W, 3)``, ``perm`` makes EPIs from them."""
    n_views = views.shape[0]
    spacing = 2.0 * d_max / (config.filter.n_filters - 1)
    radius = max(
        config.label.variance_radius * spacing, config.label.variance_min_shift / (n_views // 2)
    )
    disps, bank = build_bank(config, n_views, d_max)
    raw, blur = _epis(views, perm, config)
    k1, k2 = jax.random.split(key)
    lines = _refine_lines(
        raw, blur, _candidates(blur, disps, bank, d_max, config), radius, config, k1
    )
    if not config.refine.multiscale:
        return lines
    # ---- spatial multi-scale (4.1.4): 2x coarser views, lines a fine line does not explain --
    n, H, W, C = views.shape
    cv = views[:, : H // 2 * 2, : W // 2 * 2]
    cv = 0.25 * (cv[:, 0::2, 0::2] + cv[:, 1::2, 0::2] + cv[:, 0::2, 1::2] + cv[:, 1::2, 1::2])
    craw, cblur = _epis(cv, perm, config)
    cdisps, cbank = build_bank(config, n_views, d_max / 2)
    cand = _candidates(cblur, cdisps, cbank, d_max / 2, config)
    coarse = _refine_lines(
        craw, cblur, cand, radius / 2, config, k2
    )  # filtered at the coarse scale
    Nf, h = raw.shape[0], raw.shape[1]
    rep = lambda a: jnp.repeat(a, 2, axis=0)[:Nf]
    pad = lambda a: jnp.pad(a, [(0, Nf - a.shape[0])] + [(0, 0)] * (a.ndim - 1))
    cpos = pad(rep(2.0 * coarse["pos"] + 0.5))
    cd = pad(rep(2.0 * coarse["disparity"]))
    cvalid = pad(rep(coarse["valid"]))
    cxt = cpos + (h // 2) * cd
    cxb = cpos - (h - 1 - h // 2) * cd
    lam = config.refine.multiscale_lambda_frac * h
    close = (
        (jnp.abs(cxt[:, :, None] - lines["xt"][:, None, :]) < lam)
        & (jnp.abs(cxb[:, :, None] - lines["xb"][:, None, :]) < lam)
        & lines["valid"][:, None, :]
    )
    keep = cvalid & ~jnp.any(close, axis=-1)
    cand_f = {
        "pos": cpos,
        "disparity": cd,
        "valid": keep,
        "confidence": pad(rep(coarse["confidence"])),
        "label": pad(rep(coarse["label"])),
        "overflow": coarse["overflow"],
    }
    extra = _refine_lines(raw, blur, cand_f, 2.0 * radius, config, k2)
    return jax.tree.map(
        lambda a, b: jnp.concatenate([a, b], axis=1) if a.ndim >= 2 else a + b, lines, extra
    )


def _to_edgeset(lines: dict[str, Array], direction: int) -> tuple[EdgeSet, Array]:
    N, K = lines["pos"].shape
    epi = jnp.broadcast_to(jnp.arange(N, dtype=jnp.float32)[:, None], (N, K))
    pos = lines["pos"]
    x, y = (pos, epi) if direction == HORIZONTAL else (epi, pos)
    f = lambda a: a.reshape((N * K,) + a.shape[2:])
    es = EdgeSet(
        x=f(x),
        y=f(y),
        disparity=f(lines["disparity"]),
        confidence=f(lines["confidence"]),
        visible=f(lines["visible"]),
        lab=f(lines["lab"]),
        direction=jnp.full((N * K,), direction, jnp.int32),
        intercepts=f(jnp.stack([lines["xt"], lines["xb"]], -1)),
        valid=f(lines["valid"]),
        n_dropped=lines["overflow"].astype(jnp.int32),
    )
    return es, f(lines["label"])


def _sample_rows(maps: Array, x: Array, y: Array) -> Array:
    """Rows of ``maps (H, W, n)`` at points ``(x, y)``: linear along x, nearest along y
    (points lie on pixel rows of the centre view)."""
    H, W = maps.shape[:2]
    yi = jnp.clip(jnp.round(y), 0, H - 1).astype(jnp.int32)
    xc = jnp.clip(x, 0, W - 1)
    x0 = jnp.clip(jnp.floor(xc), 0, max(W - 2, 0))
    f = (xc - x0)[:, None]
    xi = x0.astype(jnp.int32)
    return maps[yi, xi] * (1 - f) + maps[yi, jnp.minimum(xi + 1, W - 1)] * f


def soft_labels(
    edges: EdgeSet,
    row_views: Float[Array, "V H W 3"],
    col_views: Float[Array, "U H W 3"],
    config: EdgeConfig,
    *,
    d_max: float,
) -> EdgeSet:
    """Relabel edge points with the soft (softmax) disparity of the filter bank.

    At each point the filter-response magnitudes ``r_i`` of its own EPI direction
    (`soft_filter_responses`, interpolated linearly along the EPI's spatial axis) give
    ``p = softmax(r / τ)`` with ``τ = config.label.temperature · max_i r_i`` (relative, so the
    softmax does not depend on the image contrast) and the label ``Σ p_i d_i``. The points,
    their validity and confidence are unchanged; the intercepts follow the new disparity. The
    labels are smooth functions of the views and of ``presmooth_sigma``, ``edge_shift``,
    ``aa_sigma`` and ``temperature``.

    Args:
        edges: edge set of `detect_edges_arrays` (capacity ``N``).
        row_views: ``(V, H, W, 3)`` central row of views, RGB in [0, 1].
        col_views: ``(U, H, W, 3)`` central column of views.
        config: `EdgeConfig`.
        d_max: the bank's half-range, pixels per view step (static).

    Returns:
        The `EdgeSet` with soft ``disparity`` and matching ``intercepts``.

    References:
        Thesis Alg. 1, relaxed (softmax for argmax).
    """
    kw = dict(
        d_max=d_max,
        n_filters=config.filter.n_filters,
        presmooth_sigma=config.filter.presmooth_sigma,
        edge_shift=config.filter.edge_shift,
        aa_sigma=config.filter.aa_sigma,
        blur_radius=config.filter.blur_radius,
    )
    disparity = edges.disparity
    for direction, views in ((HORIZONTAL, row_views), (VERTICAL, col_views)):
        mag, disps = soft_filter_responses(views, direction=direction, **kw)
        if direction == HORIZONTAL:  # EPIs of pixel rows: the spatial axis is x
            r = _sample_rows(mag, edges.x, edges.y)
        else:  # EPIs of pixel columns: the spatial axis is y
            r = _sample_rows(jnp.swapaxes(mag, 0, 1), edges.y, edges.x)
        tau = config.label.temperature * jnp.max(r, axis=-1, keepdims=True)
        d, _ = soft_select(r, disps, tau)
        disparity = jnp.where(edges.direction == direction, d.astype(disparity.dtype), disparity)
    n = jnp.where(edges.direction == HORIZONTAL, row_views.shape[0], col_views.shape[0])
    pos = jnp.where(edges.direction == HORIZONTAL, edges.x, edges.y)
    intercepts = jnp.stack([pos + (n // 2) * disparity, pos - (n - 1 - n // 2) * disparity], -1)
    disparity = jnp.where(edges.valid, disparity, edges.disparity)
    return eqx.tree_at(lambda e: (e.disparity, e.intercepts), edges, (disparity, intercepts))


def detect_edges_arrays(
    row_views: Float[Array, "V H W 3"],
    col_views: Float[Array, "U H W 3"],
    config: EdgeConfig,
    *,
    d_max: float,
    key: Array,
) -> EdgeSet:
    """`detect_edges` on arrays: pure and jittable, without the host-side checks.

    Use `check_cross_hair` first (it validates the views and returns ``d_max``) and
    `warn_dropped` after; `detect_edges` does all three.

    Args:
        row_views: ``(V, H, W, 3)`` central row of views, RGB in [0, 1], finite.
        col_views: ``(U, H, W, 3)`` central column of views.
        config: `EdgeConfig` (its ``strategy`` selects hard or soft labels).
        d_max: the bank's half-range, pixels per view step (static).
        key: PRNG key of the entropy search.

    Returns:
        The `EdgeSet` (see `detect_edges`).

    References:
        Thesis Ch. 4.1 (Alg. 1, Secs. 4.1.1–4.1.5).
    """
    _, H, W, _ = row_views.shape
    kh, kv = jax.random.split(key)
    sets = []
    if config.filter.directions in ("both", "horizontal"):
        # (V, H, W, C) -> EPIs (H, V, W, C)
        lines = _direction_lines(row_views, (1, 0, 2, 3), d_max, config, kh)
        sets.append(_to_edgeset(lines, HORIZONTAL))
    if config.filter.directions in ("both", "vertical"):
        # (U, H, W, C) -> EPIs (W, U, H, C)
        lines = _direction_lines(col_views, (2, 0, 1, 3), d_max, config, kv)
        sets.append(_to_edgeset(lines, VERTICAL))
    edges = sets[0][0]
    labels = sets[0][1]
    for es, lab in sets[1:]:
        edges = concatenate(edges, es)
        labels = jnp.concatenate([labels, lab])
    if config.label.strategy == "soft":
        edges = soft_labels(edges, row_views, col_views, config, d_max=d_max)
    few_views = min(row_views.shape[0], col_views.shape[0]) <= config.outliers.auto_views
    if config.outliers.enabled or (config.outliers.enabled is None and few_views):
        keep = reject_outliers(edges, labels, (H, W), config)
        edges = eqx.tree_at(lambda e: e.valid, edges, edges.valid & keep)
    if config.refine.trilateral:
        d = trilateral_filter(edges, (H, W), config)
        # Keep the intercepts on the filtered line through the same centre-view position.
        n = jnp.where(edges.direction == HORIZONTAL, row_views.shape[0], col_views.shape[0])
        pos = jnp.where(edges.direction == HORIZONTAL, edges.x, edges.y)
        top = pos + (n // 2) * d
        bottom = pos - (n - 1 - n // 2) * d
        edges = eqx.tree_at(
            lambda e: (e.disparity, e.intercepts), edges, (d, jnp.stack([top, bottom], -1))
        )
    return edges


def detect_edges(lf: LightField, config: EdgeConfig = EdgeConfig(), *, key=None) -> EdgeSet:
    """Multi-view edge points of a light field's central cross-hair of views.

    Every EPI of the central row of views (one per pixel row) and of the central column (one per
    pixel column) is processed on its centre row (the centre view), then the two sets are
    merged. With the default `EdgeConfig`:

    1. CIELAB / 100, Gaussian pre-blur (0.85 px); filter-bank responses (Alg. 1, 61 filters
       over ``±d_max``) on the centre row, label = argmax, confidence = max x 3x3 EPI std.
       Every pixel is a candidate (``nms=False``; NMS is optional).
    2. Sub-pixel disparity: parabola through the neighbouring filters' responses, then a search
       minimising the colour variance along the EPI line on the less-varying side of the edge
       (grid over ``±1.5`` filter spacings + Gauss–Newton polish, cubic sampling).
    3. A candidate is kept only when its variance minimum is distinct (``min_ratio``: the
       variance ``1.5`` spacings away is at least 3x the minimum): flat or ambiguous lines
       are dropped, since a wrong label costs more downstream than a missing one.
    4. Line fitting in confidence order with λ suppression (4.1.2; λ = 0 by default).
    5. Outlier rejection by same-disparity neighbours (4.1.3, eqs 4.1–4.2).
    6. Trilateral filter of the sparse disparities (eq 4.6, radius 3).

    With ``config.label.strategy = "soft"`` the points are then relabelled by `soft_labels` (a
    softmax over the filter responses; smooth in the hyperparameters) before steps 5–6.

    Optional stages: gradient-alignment test (eq 4.3), dropping points not visible in the
    centre view (eq 4.4; the ``visible`` flag is always computed), entropy-based random search
    of the intercepts (eq 4.5), spatial multi-scale (4.1.4). `EdgeConfig` documents every
    option; ``experiments/bench_edges.py`` measures each stage's effect.

    Args:
        lf: the light field (only the central row and column of views are read).
        config: `EdgeConfig`.
        key: PRNG key of the entropy search (``None``: ``jax.random.key(0)``). The bank's
            half-range ``d_max`` comes from ``config.filter.d_max``, else from the scene's
            ``disparity_range`` (+ ``filter.d_margin``), else ``filter.d_max_fallback``.

    Returns:
        An `EdgeSet` of capacity ``H * K_h + W * K_v`` (one direction only: the matching term),
        ``K = config.label.line_capacity`` or the EPI width; ``n_dropped`` counts candidates lost to
        the capacity.

    Raises:
        ValueError: fewer than 3 views in a direction, a disparity range the bank cannot cover
            (scene range beyond ``config.filter.d_max``, or lines wider than the image), or
            non-finite pixels.

    Warns:
        UserWarning: when candidates were dropped because ``config.label.line_capacity`` was too
            small.

    References:
        Thesis Ch. 4.1 (Alg. 1, Secs. 4.1.1–4.1.5); SPEC §1.
    """
    d_max = check_cross_hair(lf, config)
    if key is None:
        key = jax.random.key(0)
    row, col = lf.cross_hair()
    edges = _detect_jit(row, col, config, d_max=d_max, key=key)
    warn_dropped(edges, config)
    return edges


_detect_jit = jax.jit(detect_edges_arrays, static_argnames=("d_max",))


def check_cross_hair(lf: LightField, config: EdgeConfig) -> float:
    """Host-side checks of `detect_edges`' input; returns the bank's half-range ``d_max``.

    Args:
        lf: the light field (its central row and column of views are read).
        config: `EdgeConfig`.

    Returns:
        ``d_max`` in pixels per view step (`resolve_d_max`).

    Raises:
        ValueError: fewer than 3 views in a direction, a disparity range the bank cannot
            cover, or non-finite pixels in the cross-hair.
    """
    U, V = lf.grid
    H, W = lf.size
    if U < 3 or V < 3:
        raise ValueError(f"need at least 3 views per direction; got a {U}x{V} grid")
    d_max = resolve_d_max(config, lf.disparity_range)
    reach = (max(U, V) // 2) * d_max
    if reach + 2 >= min(H, W) / 2:
        raise ValueError(
            f"disparity range ±{d_max:.3g} moves a line by {reach:.1f} px across the views, too "
            f"much for {H}x{W} views; lower d_max"
        )
    row, col = lf.cross_hair()
    if isinstance(row, jax.core.Tracer) or isinstance(col, jax.core.Tracer):
        return d_max
    if not (np.isfinite(np.asarray(row)).all() and np.isfinite(np.asarray(col)).all()):
        raise ValueError("light field views contain NaN or Inf")
    return d_max


def warn_dropped(edges: EdgeSet, config: EdgeConfig) -> int:
    """Warn when candidates did not fit in ``config.label.line_capacity``; returns their number.

    Warns:
        UserWarning: when ``edges.n_dropped > 0``.
    """
    if isinstance(edges.n_dropped, jax.core.Tracer):
        return 0
    dropped = int(edges.n_dropped)
    if dropped > 0:
        warnings.warn(
            f"detect_edges: {dropped} edge candidates did not fit in line_capacity="
            f"{config.label.line_capacity} per EPI and were dropped; raise "
            "EdgeConfig.label.line_capacity",
            stacklevel=3,
        )
    return dropped


def soft_filter_responses(
    views: Float[Array, "n H W 3"],
    *,
    d_max: float,
    n_filters: int = 61,
    presmooth_sigma: Float[ArrayLike, ""] = 0.85,
    edge_shift: Float[ArrayLike, ""] = 1.0,
    aa_sigma: Float[ArrayLike, ""] = 0.0,
    blur_radius: int = 3,
    direction: int = HORIZONTAL,
) -> tuple[Float[Array, "H W n"], Float[Array, " n"]]:
    """Filter-bank response magnitudes of every centre-view pixel (differentiable).

    The pre-processing of `detect_edges` (CIELAB / 100, Gaussian pre-blur) and the Prewitt
    bank applied on the centre row of every EPI of a row or column of views. Gradients reach
    the views, ``presmooth_sigma``, ``edge_shift`` and ``aa_sigma``.

    Args:
        views: ``(n, H, W, 3)`` RGB in [0, 1]: the central row of views (``direction =
            HORIZONTAL``) or the central column (``VERTICAL``), ``n >= 3``.
        d_max: the bank covers ``[-d_max, d_max]`` (static).
        n_filters: number of filters (static).
        presmooth_sigma: pre-blur, pixels.
        edge_shift, aa_sigma: see `prewitt_bank`.
        blur_radius: pre-blur kernel half-width (static).
        direction: `HORIZONTAL` or `VERTICAL` EPIs.

    Returns:
        ``(magnitude (H, W, n_filters), disparities (n_filters,))``: response magnitudes (LAB
        / 100 units) and the bank's disparities (pixels per view step), in the dtype of
        ``views`` (at least float32).

    Raises:
        ValueError: fewer than 3 views, a bad shape or an unknown direction.

    References:
        Thesis Alg. 1 (the responses its argmax / max act on).
    """
    views = jnp.asarray(views)
    if views.ndim != 4 or views.shape[-1] != 3 or views.shape[0] < 3:
        raise ValueError(f"views must have shape (n >= 3, H, W, 3); got {tuple(views.shape)}")
    if direction not in (HORIZONTAL, VERTICAL):
        raise ValueError(f"direction must be HORIZONTAL (0) or VERTICAL (1); got {direction!r}")
    dt = jnp.result_type(views, jnp.float32)
    views = views.astype(dt)
    n = views.shape[0]
    h = n if n % 2 else n + 1
    disps = filter_disparities(n_filters, d_max).astype(dt)
    bank = prewitt_bank(
        disps,
        h,
        bank_width(h, d_max, 1.5) + 2,
        shift=jnp.asarray(edge_shift, dt),
        aa_sigma=jnp.asarray(aa_sigma, dt),
    )
    blur = blur_images(rgb_to_lab(views) * _LAB_SCALE, presmooth_sigma, blur_radius)
    perm = (1, 0, 2, 3) if direction == HORIZONTAL else (2, 0, 1, 3)
    mag = centre_response_magnitude(jnp.transpose(blur, perm), bank)  # (A, B, n)
    return (mag if direction == HORIZONTAL else jnp.swapaxes(mag, 0, 1)), disps


def soft_edge_maps(
    views: Float[Array, "n H W 3"],
    *,
    d_max: float,
    n_filters: int = 61,
    presmooth_sigma: Float[ArrayLike, ""] = 0.85,
    temperature: Float[ArrayLike, ""] = 0.02,
    edge_shift: Float[ArrayLike, ""] = 1.0,
    aa_sigma: Float[ArrayLike, ""] = 0.0,
    blur_radius: int = 3,
    direction: int = HORIZONTAL,
) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """Differentiable (soft) edge detection on the centre view of a row or column of views.

    `soft_filter_responses` (the pre-processing and bank of `detect_edges`), then
    `soft_select`: a softmax over the filter responses instead of argmax / max (as
    `soft_detect` does on EPIs). Gradients reach the views, ``presmooth_sigma``,
    ``temperature``, ``edge_shift`` and ``aa_sigma``.

    Args:
        views, d_max, n_filters, presmooth_sigma, edge_shift, aa_sigma, blur_radius,
            direction: as `soft_filter_responses` (``views`` is ``(n, H, W, 3)`` RGB in
            [0, 1], ``n >= 3``).
        temperature: softmax temperature (response units, LAB / 100).

    Returns:
        ``(disparity, confidence)``, each ``(H, W)``: expected disparity and soft confidence of
        every centre-view pixel.

    Raises:
        ValueError: fewer than 3 views, a bad shape or an unknown direction.

    References:
        Thesis Alg. 1, relaxed (softmax for argmax).
    """
    mag, disps = soft_filter_responses(
        views,
        d_max=d_max,
        n_filters=n_filters,
        presmooth_sigma=presmooth_sigma,
        edge_shift=edge_shift,
        aa_sigma=aa_sigma,
        blur_radius=blur_radius,
        direction=direction,
    )
    return soft_select(mag, disps, temperature)
