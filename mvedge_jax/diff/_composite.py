"""Occlusion-aware compositing by radiative transmittance, rendered in parallel screen tiles.

Model (thesis Sec. 7.1.3, App. C.4). Each point is a Gaussian density of peak ρ in
(x, y, depth) with standard deviations (σ_S, σ_S, σ_Z). Along the ray through pixel ``q`` the
point contributes the optical depth ``ρ g_p(q) σ_Z √(π/2) (erf(δ/σ_Z√2) + erf(L/√2))`` up to the
offset ``δ`` from its depth, on its local interval ``[-Lσ_Z, Lσ_Z]`` (eq 7.9 with μ_z = t/2), so
its full attenuation is ``T_p(q) = exp(-ρ σ_Z √(2π) erf(L/√2) g_p(q))`` (eq 7.10). With
σ_Z → 0 the points are independent along the ray: the transmittance in front of a point is
the product of the full attenuations of all nearer points (eq 7.8). The label contribution of
a point (eqs 7.12–7.14) is

    a_p(q) = T_before,p(q) · ρ g_p(q) Σ_{s ∈ N_p} ds exp(-τ_p(s)) exp(-(s - Z_p)²/2σ_Z²),

an 8-sample midpoint quadrature over ``N_p`` (→ ``T_before (1 - T_p)`` as the sample count
grows). The composited maps are

    α(q) = Σ_p a_p(q),    S^Z(q) = Σ_p a_p(q) Z_p / α(q),    λ^Z(q) = Σ_p T_before,p(q) λ_p(q),

i.e. the label is the opacity-weighted mean of the visible labels (the raw sum of eq 7.3 would
scale labels by the coverage α), and each point's super-Gaussian weight (eq 7.6) is attenuated
by the transmittance in front of it, so an occluded point loses its say in the diffusion.

Parallel rendering (Sec. 7.1.5, "Efficiency"): the image is split into ``T×T`` tiles; a point
is listed in every tile its ``(2r+1)²`` support overlaps (at most 2×2 tiles: the overlap equals
the kernel size), every list is sorted nearest first with one global ``lax.sort`` on
(tile, depth), truncated to the tile's capacity (``tile_levels``: busier tiles keep more; the
farthest points are dropped and counted),
and every tile is rendered densely with an exclusive cumulative sum of log-transmittance over
its depth-sorted points (``vmap`` over tiles; no loops over points).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._config import RenderConfig
from ._splat import check_points, check_shape, label_kernel_1d, weight_kernel


def _tiny(dtype) -> float:
    """Below this total weight a pixel has no label (its weight is ~0 anyway). ``eps²`` of the
    dtype: small enough to be negligible, large enough that the gradient of ``num / den``
    (``∝ 1 / den²``) stays finite (1e-20 overflowed in float32)."""
    return float(jnp.finfo(dtype).eps) ** 2


_DEFAULT_RENDER = RenderConfig()


class RenderResult(eqx.Module):
    """The composited maps fed to the diffusion of eq 7.2.

    Attributes:
        label: ``(H, W)`` S^Z, opacity-weighted depth label (eq 7.3 / 7.13), 0 where α = 0.
        weight: ``(H, W)`` λ^Z >= 0, occlusion-attenuated super-Gaussian label weight (eq 7.5).
        alpha: ``(H, W)`` total opacity Σ_p a_p in [0, 1) (approximately ``1 - Π T_p``).
        overflow: ``()`` int32, points dropped from at least one tile by its capacity.
    """

    label: Float[Array, "H W"]
    weight: Float[Array, "H W"]
    alpha: Float[Array, "H W"]
    overflow: Int[Array, ""]


def _attenuation_constants(config: RenderConfig, dtype):
    """Quadrature constants: ``log T_p = -kappa g`` and ``q(g) = Σ_k c_k g exp(-b_k g)``."""
    n = max(config.depth_samples, 1)
    L = jnp.asarray(config.depth_span, dtype)
    rho = jnp.asarray(config.density, dtype)
    sz = jnp.asarray(config.sigma_depth, dtype)
    # sample offsets from the point's depth, in units of σ_Z (midpoint rule on [-L, L])
    v = -L + (jnp.arange(n, dtype=dtype) + 0.5) * (2.0 * L / n)
    erf_L = jax.scipy.special.erf(L / math.sqrt(2.0))
    kappa = rho * sz * math.sqrt(2.0 * math.pi) * erf_L  # full optical depth per unit g
    b = rho * sz * math.sqrt(math.pi / 2.0) * (jax.scipy.special.erf(v / math.sqrt(2.0)) + erf_L)
    c = rho * sz * (2.0 * L / n) * jnp.exp(-0.5 * v * v)
    return kappa, b, c


def _quadrature(g, kappa, b, c, n: int):
    """``q(g) = g Σ_k c_k exp(-b_k g)`` (eq 7.14 with the erf optical depth of eq 7.9).

    The samples are symmetric about the point's depth, so ``b_k + b_{n-1-k} = kappa`` and
    ``exp(-b_{n-1-k} g) = exp(-kappa g) / exp(-b_k g)``: ⌈n/2⌉ + 1 exponentials instead of n.
    ``n == 0`` gives the exact integral ``1 - exp(-kappa g)``, the limit of many samples.
    """
    if n == 0:
        return -jnp.expm1(-kappa * g)
    full = jnp.exp(-kappa * g)
    acc = 0.0
    for k in range(n // 2):
        e = jnp.exp(-b[k] * g)
        acc = acc + c[k] * (e + full / e)
    if n % 2:
        acc = acc + c[n // 2] * jnp.exp(-b[n // 2] * g)
    return acc * g


def _bin_points(x, y, key, ok, H, W, config: RenderConfig):
    """Depth-sorted, capacity-limited point lists per tile.

    Every tile keeps up to ``c_1`` nearest points; the tiles holding the most points keep
    up to the larger capacities of ``tile_levels`` (see `RenderConfig`).

    Returns:
        ``table (n_tiles, C)`` int32 point indices nearest first (``-1`` = empty slot), the
        tile indices ``(n_tiles,)`` ordered by decreasing point count, and the number of points
        that lost at least one tile to the capacity.
    """
    T, C, r = config.tile_size, config.tile_capacity, config.radius
    n_ty, n_tx = -(-H // T), -(-W // T)
    n_tiles = n_ty * n_tx
    N = x.shape[0]
    # covered pixels: |px - x| < r + 1/2  →  [floor(x - r - 1/2) + 1, ceil(x + r + 1/2) - 1]
    lo_x = jnp.floor(x - r - 0.5).astype(jnp.int32) + 1
    hi_x = jnp.ceil(x + r + 0.5).astype(jnp.int32) - 1
    lo_y = jnp.floor(y - r - 0.5).astype(jnp.int32) + 1
    hi_y = jnp.ceil(y + r + 0.5).astype(jnp.int32) - 1
    lo_x, hi_x = jnp.maximum(lo_x, 0), jnp.minimum(hi_x, W - 1)
    lo_y, hi_y = jnp.maximum(lo_y, 0), jnp.minimum(hi_y, H - 1)
    inside = ok & (lo_x <= hi_x) & (lo_y <= hi_y)
    tx0, tx1 = lo_x // T, hi_x // T
    ty0, ty1 = lo_y // T, hi_y // T
    two_x, two_y = tx1 != tx0, ty1 != ty0
    cand_ty = jnp.stack([ty0, ty0, ty1, ty1])
    cand_tx = jnp.stack([tx0, tx1, tx0, tx1])
    use = jnp.stack([inside, inside & two_x, inside & two_y, inside & two_x & two_y])
    tile = jnp.where(use, cand_ty * n_tx + cand_tx, n_tiles).reshape(-1)
    pid = jnp.broadcast_to(jnp.arange(N, dtype=jnp.int32), (4, N)).reshape(-1)
    skey = jnp.broadcast_to(key, (4, N)).reshape(-1)
    tile_s, _, pid_s = lax.sort((tile, skey, pid), num_keys=2)
    counts = jnp.zeros((n_tiles + 1,), jnp.int32).at[tile_s].add(1)
    starts = jnp.cumsum(counts) - counts
    rank = jnp.arange(tile_s.shape[0], dtype=jnp.int32) - starts[tile_s]
    listed = tile_s < n_tiles
    order = jnp.argsort(-counts[:n_tiles], stable=True).astype(jnp.int32)  # busiest first
    cap = jnp.zeros((n_tiles + 1,), jnp.int32)
    for c_k, n_k in _levels(config, n_tiles):
        cap = cap.at[order[:n_k]].set(c_k)
    keep = listed & (rank < cap[tile_s])
    table = jnp.full((n_tiles, C), -1, jnp.int32)
    table = table.at[jnp.where(keep, tile_s, n_tiles), jnp.where(keep, rank, 0)].set(
        pid_s, mode="drop"
    )
    lost = jnp.zeros((N,), bool).at[pid_s].max(listed & ~keep)
    return table, order, jnp.sum(lost.astype(jnp.int32))


def _levels(config: RenderConfig, n_tiles: int) -> list[tuple[int, int]]:
    """Static ``[(capacity, number of tiles), ...]`` of the tile levels."""
    return [(int(c), max(1, min(n_tiles, math.ceil(f * n_tiles)))) for c, f in config.tile_levels]


def render(
    position: Float[ArrayLike, "N 2"],
    label: Float[ArrayLike, " N"],
    log_weight: Float[ArrayLike, " N"],
    shape: tuple[int, int],
    config: RenderConfig = _DEFAULT_RENDER,
    *,
    valid: Bool[ArrayLike, " N"] | None = None,
    value: Float[ArrayLike, " N"] | None = None,
) -> RenderResult:
    """Render a point set into a label map S^Z and a weight map λ^Z with occlusion.

    Nearer points (larger label when ``config.nearer == "larger"``, i.e. larger disparity)
    attenuate the contribution and the weight of farther points at every pixel they cover.
    Differentiable in ``position``, ``label`` and ``log_weight`` (the depth order itself is
    piecewise constant). jit- and vmap-able; ``shape`` and ``config``'s static fields are
    static.

    Args:
        position: ``(N, 2)`` sub-pixel ``(x, y)`` = (column, row), pixel centres at integers.
        label: ``(N,)`` depth label Z (disparity or depth, see ``config.nearer``).
        log_weight: ``(N,)`` R; label weight scale ``w = exp(-R)`` (Sec. 7.1.5).
        shape: ``(H, W)`` of the output.
        config: `RenderConfig` (σ_S, σ_λ, p, σ_Z, ρ, tiles).
        valid: ``(N,)`` bool; invalid points are ignored. Default: all valid.
        value: optional ``(N,)`` per-point quantity mixed into ``RenderResult.label`` in place
            of the label, with the same weights (the label still sets the depth order and
            the occlusion); `predict` uses it to splat the points' departures from a prior.

    Returns:
        A `RenderResult`; ``overflow`` counts points that did not fit some tile (those are
        missing from that tile's pixels; raise ``tile_levels`` when it is non-zero).

    Raises:
        ValueError: on mismatched shapes.

    References:
        Thesis eqs 7.3–7.14, App. C.4; Sec. 7.1.5 (σ_S = 1.3, 7×7, σ_Z = 1, 8 samples,
        p = 2, σ_λ = 0.71, overlapping tiles).
    """
    position = jnp.asarray(position)
    if not jnp.issubdtype(position.dtype, jnp.floating):
        position = position.astype(jnp.float32)
    dtype = position.dtype
    label = jnp.asarray(label, dtype)
    log_weight = jnp.asarray(log_weight, dtype)
    valid = None if valid is None else jnp.asarray(valid, bool)
    check_points(position, label, log_weight, valid)
    if value is None:
        value = label
    else:
        value = jnp.asarray(value, dtype)
        if value.shape != label.shape:
            raise ValueError(f"value must have the labels' shape {label.shape}; got {value.shape}")
    H, W = check_shape(shape)
    T, r = config.tile_size, config.radius
    n_ty, n_tx = -(-H // T), -(-W // T)
    if position.shape[0] == 0:
        zero = jnp.zeros((H, W), dtype)
        return RenderResult(label=zero, weight=zero, alpha=zero, overflow=jnp.zeros((), jnp.int32))

    x, y = position[:, 0], position[:, 1]
    ok = jnp.all(jnp.isfinite(position), axis=1) & jnp.isfinite(label) & jnp.isfinite(value)
    if valid is not None:
        ok = ok & valid
    sx, sy, slab = (lax.stop_gradient(a) for a in (x, y, label))
    key = -slab if config.nearer == "larger" else slab
    key = jnp.where(ok, key, jnp.inf)
    # far-away points stay far away but cannot overflow the integer pixel arithmetic
    m = 2 * r + 2
    sx = jnp.clip(jnp.where(ok, sx, 0.0), -m, W + m)
    sy = jnp.clip(jnp.where(ok, sy, 0.0), -m, H + m)
    table, order, overflow = _bin_points(sx, sy, key, ok, H, W, config)

    # gather the tile lists (n_tiles, C); empty slots point at index 0 and are masked
    used = table >= 0
    idx = jnp.maximum(table, 0)
    tx_, ty_, tz, tw = x[idx], y[idx], value[idx], jnp.exp(-log_weight[idx])
    tiles = jnp.arange(n_ty * n_tx, dtype=jnp.int32)
    oy = ((tiles // n_tx) * T).astype(dtype)
    ox = ((tiles % n_tx) * T).astype(dtype)
    kappa, b, c = _attenuation_constants(config, dtype)
    lim = r + 0.5
    pix = jnp.arange(T, dtype=dtype)

    n_tiles = n_ty * n_tx
    # Scan over the depth-sorted slots (nearest first) of all tiles at once; the carry holds
    # the accumulated log-transmittance of every tile pixel. Only carries are saved for the
    # backward pass (checkpointed body), so memory is O(C · H · W) scalars at most.
    cols = ox[:, None] + pix[None, :]  # (n_tiles, T) pixel x of each tile column
    rows = oy[:, None] + pix[None, :]

    def step(carry, slot, cols, rows):
        log_acc, alpha, num, lam_z = carry
        u, xs, ys, zs, ws = slot  # each (n_tiles,)
        dx = cols - xs[:, None]  # (n_tiles, T)
        dy = rows - ys[:, None]
        gx = label_kernel_1d(dx, config.sigma_label, r)
        gy = label_kernel_1d(dy, config.sigma_label, r) * u[:, None]
        g = gy[:, :, None] * gx[:, None, :]  # (n_tiles, T, T)
        inside = (jnp.abs(dy) < lim)[:, :, None] & (jnp.abs(dx) < lim)[:, None, :]
        sg = weight_kernel(
            dy[:, :, None] ** 2 + dx[:, None, :] ** 2, config.sigma_weight, config.weight_order
        )
        lam = jnp.where(inside, sg, 0.0) * (ws * u)[:, None, None]
        t_before = jnp.exp(log_acc)  # transmittance of all nearer points (eq 7.8)
        # eq 7.14: quadrature over the point's own depth interval (static, small count)
        q = _quadrature(g, kappa, b, c, config.depth_samples)
        a = t_before * q
        vis_lam = t_before * lam
        mix = a if config.label_mix == "opacity" else vis_lam
        carry = (
            log_acc - kappa * g,
            alpha + a,
            num + mix * zs[:, None, None],
            lam_z + vis_lam,
        )
        return carry, None

    zero = jnp.zeros((n_tiles, T, T), dtype)
    per_slot = (used.astype(dtype), tx_, ty_, tz, tw)  # each (n_tiles, C)
    carry = (zero, zero, zero, zero)
    start = 0
    for level, (c_k, n_k) in enumerate(_levels(config, n_tiles)):
        # the n_k busiest tiles continue with slots [start, c_k) (level 0: all tiles)
        if level == 0 and n_k == n_tiles:
            sel = None
            sub, kcols, krows = carry, cols, rows
            slots = tuple(jnp.swapaxes(a[:, start:c_k], 0, 1) for a in per_slot)
        else:
            sel = order[:n_k]
            sub, kcols, krows = tuple(c[sel] for c in carry), cols[sel], rows[sel]
            slots = tuple(jnp.swapaxes(a[sel, start:c_k], 0, 1) for a in per_slot)
        body = jax.checkpoint(lambda c, s, kc=kcols, kr=krows: step(c, s, kc, kr))
        sub, _ = lax.scan(body, sub, slots)
        if sel is None:
            carry = sub
        else:
            carry = tuple(c.at[sel].set(v) for c, v in zip(carry, sub, strict=True))
        start = c_k
    _, alpha, num, lam = carry

    def assemble(t):  # (n_tiles, T, T) → (H, W)
        t = t.reshape(n_ty, n_tx, T, T).transpose(0, 2, 1, 3).reshape(n_ty * T, n_tx * T)
        return t[:H, :W]

    num, alpha, lam = assemble(num), assemble(alpha), assemble(lam)
    den = alpha if config.label_mix == "opacity" else lam
    has = den > _tiny(den.dtype)
    lab = jnp.where(has, num / jnp.where(has, den, 1.0), 0.0)
    return RenderResult(label=lab, weight=lam, alpha=alpha, overflow=overflow)
