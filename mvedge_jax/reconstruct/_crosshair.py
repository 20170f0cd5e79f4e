"""Cross-hair projection and angular (EPI) inpainting (thesis Sec. 6.1, eqs 6.4–6.8)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..edges import EdgeSet
from ..lightfield import backward_warp_planar, forward_project_views
from ..solve import SolveResult, guide_edge_weights, solve_poisson
from ._config import ReconstructConfig


def project_cross_hair(
    centre: Float[Array, "H W"],
    grid: tuple[int, int],
    *,
    crack_parallax: float = 0.5,
) -> tuple[
    Float[Array, "V H W"], Bool[Array, "V H W"], Float[Array, "U H W"], Bool[Array, "U H W"]
]:
    """Forward-project the centre disparity into every view of the central cross-hair.

    View ``(U // 2, col)`` receives ``forward_project(centre, (0, col - V // 2))`` and view
    ``(row, V // 2)`` receives ``forward_project(centre, (row - U // 2, 0))``: z-buffered (the
    larger disparity, nearer, wins), holes (disocclusions) marked invalid.

    Args:
        centre: ``(H, W)`` centre-view disparity (pixels per view step).
        grid: ``(U, V)`` angular size of the light field (static).
        crack_parallax: forwarded to `forward_project`.

    Returns:
        ``(proj_h (V, H, W), valid_h (V, H, W), proj_v (U, H, W), valid_v (U, H, W))``.

    References:
        Thesis Sec. 6.1, "Cross-hair View Projection".
    """
    U, V = grid
    dc = jnp.arange(V, dtype=jnp.float32) - V // 2
    dr = jnp.arange(U, dtype=jnp.float32) - U // 2
    zv = jnp.zeros((V,), jnp.float32)
    zu = jnp.zeros((U,), jnp.float32)

    # One projection of all cross-hair views: a single z-buffer over the stacked frames.
    offsets = jnp.concatenate([jnp.stack([zv, dc], axis=1), jnp.stack([dr, zu], axis=1)])
    p, v = forward_project_views(centre, offsets, crack_parallax=crack_parallax)
    return p[:V], v[:V], p[V:], v[V:]


def photometric_confidence(
    projected: Float[Array, "K H W"],
    offsets: Float[Array, "K 2"],
    source: Float[Array, "H W C"],
    targets: Float[Array, "K H W C"],
    sigma: Array,
) -> Float[Array, "K H W"]:
    """Colour agreement of reprojected disparities with the views they were projected into.

    A pixel of view ``k`` holding the reprojected disparity ``d`` came from the source pixel
    ``(x + dc d, y + dr d)``; its confidence is ``exp(-(|I_k(x, y) − I_src(x + dc d, y + dr d)|
    / σ)²)`` (Euclidean colour distance). Wrongly placed pixels at occlusion boundaries (a
    foreground value on a background-coloured pixel, from sub-pixel rounding) get a low
    confidence.

    Args:
        projected: ``(K, H, W)`` disparities reprojected into the ``K`` views.
        offsets: ``(K, 2)`` ``(dr, dc)`` of each view relative to the source view.
        source: ``(H, W, C)`` colour of the source view.
        targets: ``(K, H, W, C)`` colours of the ``K`` views (same units as ``source``).
        sigma: colour scale σ.

    Returns:
        ``(K, H, W)`` confidence in ``[0, 1]``.
    """

    src = jnp.moveaxis(source, -1, 0)  # channels first: see `backward_warp_planar`

    def one(p, off, img):
        back = backward_warp_planar(src, p, -off)
        dist2 = sum((back[c] - img[..., c]) ** 2 for c in range(back.shape[0]))
        return jnp.exp(-dist2 / (sigma * sigma))

    return jax.vmap(one)(projected, offsets, targets)


def rasterise_lines(
    slice_index: Float[Array, " N"],
    position: Float[Array, " N"],
    disparity: Float[Array, " N"],
    weight: Float[Array, " N"],
    shape: tuple[int, int, int],
) -> tuple[Float[Array, "S A L"], Float[Array, "S A L"]]:
    """Rasterise EPI lines into a stack of EPIs.

    Point ``i`` lies in EPI ``round(slice_index_i)`` and traces ``l(a) = position_i −
    (a − A // 2) · disparity_i`` through angular rows ``a = 0 … A−1``; each sample is split
    linearly between the two nearest pixels along ``l``. Returns the accumulated weight and the
    weighted-mean label per pixel (as `splat_bilinear`).

    Args:
        slice_index, position, disparity, weight: ``(N,)``; zero weight = unused.
        shape: ``(S, A, L)`` of the EPI stack.

    Returns:
        ``(weight (S, A, L), label (S, A, L))``.
    """
    S, A, L = shape
    a = jnp.arange(A, dtype=jnp.float32) - A // 2
    s = jnp.round(slice_index).astype(jnp.int32)
    pos = position[:, None] - a[None, :] * disparity[:, None]  # (N, A)
    l0 = jnp.floor(pos)
    f = pos - l0
    l0 = l0.astype(jnp.int32)
    ai = jnp.broadcast_to(jnp.arange(A, dtype=jnp.int32)[None, :], pos.shape)
    si = jnp.broadcast_to(s[:, None], pos.shape)
    w = jnp.broadcast_to(weight[:, None], pos.shape)
    v = jnp.broadcast_to(disparity[:, None], pos.shape)
    dt = jnp.result_type(weight, disparity, jnp.float32)
    lam = jnp.zeros((S, A, L), dt)
    num = jnp.zeros((S, A, L), dt)
    for dl, b in ((0, 1.0 - f), (1, f)):
        li = l0 + dl
        ok = (li >= 0) & (li < L) & (si >= 0) & (si < S)
        wb = jnp.where(ok, w * b, 0.0)
        sidx = jnp.where(ok, si, S)
        lam = lam.at[sidx, ai, li].add(wb, mode="drop")
        num = num.at[sidx, ai, li].add(wb * v, mode="drop")
    pos_ = lam > 0
    return lam, jnp.where(pos_, num / jnp.where(pos_, lam, 1.0), 0.0)


def _background_1d(values: Array, valid: Array) -> Array:
    """Per hole pixel of a 1-D signal: the smaller (farther) of the nearest valid values to
    its left and right (0 when there is none)."""
    n = values.shape[0]
    idx = jnp.arange(n)
    left = jax.lax.cummax(jnp.where(valid, idx, -1))
    right = jax.lax.cummin(jnp.where(valid, idx, n), reverse=True)
    big = jnp.asarray(jnp.inf, values.dtype)
    vl = jnp.where(left >= 0, values[jnp.clip(left, 0, n - 1)], big)
    vr = jnp.where(right < n, values[jnp.clip(right, 0, n - 1)], big)
    out = jnp.minimum(vl, vr)
    return jnp.where(valid, values, jnp.where(jnp.isfinite(out), out, 0.0))


def solve_epis(
    projected: Float[Array, "S A L"],
    valid: Bool[Array, "S A L"],
    epi_guide: Float[Array, "S A L C"],
    line_weight: Float[Array, "S A L"],
    line_label: Float[Array, "S A L"],
    config: ReconstructConfig,
    confidence: Float[Array, "S A L"] | None = None,
) -> SolveResult:
    """Solve eq 6.4 on every EPI of a stack (batched `solve_poisson`): `inpaint_epis` with
    the `SolveResult` (per-EPI iterations, residual and status) instead of its ``x`` alone.

    Data weight (eq 6.8): ``epi.data_weight`` on reprojected pixels (``valid``;
    ``epi.centre_weight`` on the centre angular row, the view the map was estimated in), the
    line weight on EPI-line pixels that are not occluded by a reprojected value nearer by more
    than ``epi.occlusion_tol``, 0 elsewhere; the terms add where they overlap. Holes
    (disocclusions) additionally get a weak prior (``epi.hole_weight``) towards the
    background: the farther of the nearest reprojected values to either side along the
    spatial axis. Smoothness (eq 6.7): ``epi.c / (|∇I| + epi.eps)`` along both EPI axes
    (angular and spatial).

    Args:
        projected: ``(S, A, L)`` reprojected disparities (any value where not ``valid``).
        valid: ``(S, A, L)`` bool.
        epi_guide: ``(S, A, L, C)`` EPI colours (guide units).
        line_weight, line_label: ``(S, A, L)`` from `rasterise_lines`.
        config: `ReconstructConfig`.
        confidence: optional ``(S, A, L)`` factor in ``[0, 1]`` on the reprojection weight
            (`photometric_confidence`); the centre row is never down-weighted. Pixels off
            the centre row with confidence at most ``config.epi.min_confidence`` count as
            holes (a value carried across a disocclusion).

    Returns:
        The `SolveResult`: ``x`` ``(S, A, L)`` the inpainted disparity, and per EPI ``(S,)``
        its iterations, relative residual and status.

    References:
        Thesis Sec. 6.1, "Angular Inpainting", eqs 6.4–6.8.
    """
    S, A, L = projected.shape
    is_centre = (jnp.arange(A) == A // 2)[None, :, None]
    if confidence is not None:
        # A value whose colour does not match was carried across a disocclusion: a hole.
        valid = valid & (is_centre | (confidence > config.epi.min_confidence))
    occluded = valid & (projected > line_label + config.epi.occlusion_tol)
    lw = jnp.where(occluded, 0.0, line_weight)
    # Reprojected pixels; the centre row (the view the map was estimated in) can be pinned.
    row_w = jnp.where(jnp.arange(A) == A // 2, config.epi.centre_weight, config.epi.data_weight)
    cw = jnp.where(valid, row_w[None, :, None], 0.0)
    if confidence is not None:
        cw = cw * jnp.where(is_centre, 1.0, confidence)
    # Holes are disocclusions: prior = the farther of the nearest valid values along the
    # spatial axis (the background), weight epi.hole_weight.
    bg = jax.vmap(jax.vmap(_background_1d))(projected, valid)
    hw = jnp.where(valid, 0.0, config.epi.hole_weight)
    lam = cw + lw + hw
    num = cw * jnp.where(valid, projected, 0.0) + lw * line_label + hw * bg
    pos = lam > 0
    target = jnp.where(pos, num / jnp.where(pos, lam, 1.0), 0.0)
    # Initial guess: the reprojection where valid, else the background prior.
    x0 = jnp.where(valid, projected, bg)
    wx, wy = jax.vmap(lambda g: guide_edge_weights(g, scale=config.epi.c, eps=config.epi.eps))(
        epi_guide
    )
    # guide_edge_weights on an (A, L) grid: weight_x along L (A, L-1), weight_y along A (A-1, L).
    return solve_poisson(lam, target, wx, wy, x0=x0, config=config.epi.solver)


def inpaint_epis(
    projected: Float[Array, "S A L"],
    valid: Bool[Array, "S A L"],
    epi_guide: Float[Array, "S A L C"],
    line_weight: Float[Array, "S A L"],
    line_label: Float[Array, "S A L"],
    config: ReconstructConfig,
    confidence: Float[Array, "S A L"] | None = None,
) -> Float[Array, "S A L"]:
    """Solve eq 6.4 on every EPI of a stack: the ``(S, A, L)`` inpainted disparity of
    `solve_epis` (which documents the arguments and the weights).

    References:
        Thesis Sec. 6.1, "Angular Inpainting", eqs 6.4–6.8.
    """
    return solve_epis(projected, valid, epi_guide, line_weight, line_label, config, confidence).x


def edge_lines(
    edges: EdgeSet,
    offset: Float[Array, "N 2"],
    step_response: Float[Array, " N"],
    config: ReconstructConfig,
):
    """Per-point line parameters shared by the horizontal and vertical EPI stacks.

    Returns:
        ``(qx, qy, weight)``: the offset centre-view position ``p + centre.offset_scale · n``
        and the line weight ``max(epi.line_scale · λ_e, epi.line_floor)`` (0 for invalid
        points).
    """
    off = jnp.asarray(offset, jnp.result_type(offset, jnp.float32))
    qx = edges.x + config.centre.offset_scale * off[:, 0]
    qy = edges.y + config.centre.offset_scale * off[:, 1]
    lam_e = jnp.clip(
        jnp.asarray(step_response, jnp.result_type(step_response, jnp.float32)),
        0.0,
        config.centre.lambda_e_max,
    )
    w = jnp.maximum(config.epi.line_scale * lam_e, config.epi.line_floor)
    return qx, qy, jnp.where(edges.valid, w, 0.0)
