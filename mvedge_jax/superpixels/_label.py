"""Label maps across views: z-buffered projection, label propagation (eq 5.1), nearest fill."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int


def forward_labels(
    labels: Int[Array, "H W"],
    disparity: Float[Array, "H W"],
    dr: Array,
    dc: Array,
) -> tuple[Int[Array, "H W"], Float[Array, "H W"]]:
    """Project a view's label map into another view (nearest pixel, z-buffered).

    A labelled source pixel ``(x, y)`` with disparity ``d`` lands on
    ``(round(x - dc d), round(y - dr d))`` (SPEC §0); where several land on one pixel the
    largest disparity (nearest) wins, ties by the larger label. Unlabelled sources (-1) and
    targets outside the image are skipped.

    Args:
        labels: ``(H, W)`` int32 labels of the source view, -1 = none.
        disparity: ``(H, W)`` float32 disparity of the source view (pixels per view step).
        dr, dc: ``()`` destination view offset from the source view (view steps).

    Returns:
        ``(labels (H, W) int32`` with -1 for holes, ``disparity (H, W) float32``, 0 at holes).
    """
    H, W = labels.shape
    y, x = jnp.meshgrid(jnp.arange(H), jnp.arange(W), indexing="ij")
    xt = jnp.rint(x - dc * disparity).astype(jnp.int32)
    yt = jnp.rint(y - dr * disparity).astype(jnp.int32)
    ok = (labels >= 0) & (xt >= 0) & (xt < W) & (yt >= 0) & (yt < H)
    flat = jnp.where(ok, yt * W + xt, H * W).ravel()
    z = jnp.full((H * W + 1,), -jnp.inf, disparity.dtype)
    z = z.at[flat].max(jnp.where(ok, disparity, -jnp.inf).ravel())
    win = ok.ravel() & (disparity.ravel() >= z[flat])
    lab = jnp.full((H * W + 1,), -1, jnp.int32)
    lab = lab.at[jnp.where(win, flat, H * W)].max(labels.ravel().astype(jnp.int32))
    lab = lab[: H * W].reshape(H, W)
    d = jnp.where(lab >= 0, z[: H * W].reshape(H, W), 0.0)
    return lab, d


def _capacity(n: int) -> int:
    """A static capacity >= ``n`` from a coarse ladder (powers of two and 1.5 times them, at
    least 256) so that changing hole counts compile few variants."""
    c = 256
    while c < n:
        c = c * 3 // 2 if c & (c - 1) == 0 else c * 4 // 3
    return c


@functools.partial(jax.jit, static_argnames=("radius", "capacity"))
def _propagate_pass(
    lab_views,
    labels,
    disp,
    offsets,
    cmp_lab,
    cmp_off,
    w_colour,
    w_spatial,
    w_photo,
    *,
    radius: int,
    capacity: int,
):
    """One pass of eq 5.1 over the unlabelled pixels (at most ``capacity``, gathered into a
    list): each takes the cheapest labelled candidate within the chessboard ``radius``, all
    against the labels at the start of the pass."""
    N, H, W = labels.shape
    M = cmp_lab.shape[0]
    flat_l = labels.reshape(-1)
    flat_d = disp.reshape(-1)
    flat_lab = lab_views.reshape(-1, 3)
    cmp_flat = cmp_lab.reshape(M, H * W, 3)
    (idx,) = jnp.nonzero(flat_l < 0, size=capacity, fill_value=N * H * W)
    ok = idx < N * H * W
    idx = jnp.minimum(idx, N * H * W - 1)
    n, rem = idx // (H * W), idx % (H * W)
    y, x = rem // W, rem % W
    me = flat_lab[idx]  # (C, 3)
    off = offsets[n]  # (C, 2)
    side = 2 * radius + 1

    def body(k, carry):
        best_c, best_l, best_d = carry
        sy = k // side - radius
        sx = k % side - radius
        cy, cx = y + sy, x + sx
        inside = (cy >= 0) & (cy < H) & (cx >= 0) & (cx < W)
        cy, cx = jnp.clip(cy, 0, H - 1), jnp.clip(cx, 0, W - 1)
        c_idx = n * (H * W) + cy * W + cx
        cl = jnp.where(inside, flat_l[c_idx], -1)
        cd = flat_d[c_idx]
        cost = w_colour * jnp.sum((me - flat_lab[c_idx]) ** 2, -1)
        cost = cost + w_spatial * (sy * sy + sx * sx).astype(cost.dtype)

        def photo(m, acc):
            ddr = off[:, 0] - cmp_off[m, 0]
            ddc = off[:, 1] - cmp_off[m, 1]
            py = jnp.clip(jnp.rint(y + ddr * cd).astype(jnp.int32), 0, H - 1)
            px = jnp.clip(jnp.rint(x + ddc * cd).astype(jnp.int32), 0, W - 1)
            return acc + jnp.sum(jnp.abs(me - cmp_flat[m][py * W + px]), -1)

        pc = jax.lax.fori_loop(0, M, photo, jnp.zeros_like(cost))
        cost = cost + w_photo * pc
        better = (cl >= 0) & (cost < best_c)
        return (
            jnp.where(better, cost, best_c),
            jnp.where(better, cl, best_l),
            jnp.where(better, cd, best_d),
        )

    init = (
        jnp.full((capacity,), jnp.inf, lab_views.dtype),
        jnp.full((capacity,), -1, jnp.int32),
        jnp.zeros((capacity,), disp.dtype),
    )
    _, bl, bd = jax.lax.fori_loop(0, side * side, body, init)
    hit = ok & (bl >= 0)
    tgt = jnp.where(hit, idx, N * H * W)  # out of range: dropped
    flat_l = flat_l.at[tgt].set(bl, mode="drop")
    flat_d = flat_d.at[tgt].set(bd, mode="drop")
    return flat_l.reshape(N, H, W), flat_d.reshape(N, H, W)


def propagate_labels(
    lab_views: Float[Array, "N H W 3"],
    labels: Int[Array, "N H W"],
    disparity: Float[Array, "N H W"],
    offsets: Float[Array, "N 2"],
    compare_lab: Float[Array, "M H W 3"],
    compare_offsets: Float[Array, "M 2"],
    w_colour: Array,
    w_spatial: Array,
    w_photo: Array,
    *,
    radius: int = 2,
    passes: int = 2,
) -> tuple[Int[Array, "N H W"], Float[Array, "N H W"]]:
    """Label propagation (thesis eq 5.1) for the unlabelled pixels of ``N`` views.

    For an unlabelled pixel ``(x, y)`` of view ``(u, v)`` and a labelled candidate ``(p, q)``
    within the chessboard ``radius`` (label ``ℓ``, disparity ``d``) the cost is
    ``ω_c |I(x, y) - I(p, q)|² + ω_s ((x - p)² + (y - q)²)
    + ω_d Σ_m |I(x, y) - I_m(x + Δc_m d, y + Δr_m d)|₁`` with ``I`` in CIELAB and the sum over
    the ``M`` comparison views (``Δ``: view offset minus the comparison view's offset; nearest
    pixel). The pixel takes the cheapest candidate's label and disparity (the first in
    row-major candidate order on ties). Every pass labels against the labels at its start;
    ``passes`` passes reach pixels up to ``passes · radius`` from a label.

    Each pass gathers the unlabelled pixels into a list (its length is read on the host and
    rounded up to a coarse ladder of static capacities) and runs a jitted ``lax.fori_loop``
    over the ``(2 radius + 1)²`` candidates, so the cost is proportional to the number of
    holes, not of pixels. Passes stop early when no hole is left.

    Args:
        lab_views: ``(N, H, W, 3)`` CIELAB of the views to label.
        labels: ``(N, H, W)`` int32, -1 = unlabelled.
        disparity: ``(N, H, W)`` float32 of the labelled pixels.
        offsets: ``(N, 2)`` ``(dr, dc)`` of each view from the centre view.
        compare_lab: ``(M, H, W, 3)`` CIELAB of the comparison views.
        compare_offsets: ``(M, 2)`` their offsets.
        w_colour, w_spatial, w_photo: ω_c, ω_s, ω_d of eq 5.1.
        radius: search radius in pixels.
        passes: number of passes.

    Returns:
        ``(labels, disparity)``, shapes as the inputs.

    References:
        Thesis Sec. 5.1.1 ("Label Propagation", eq 5.1).
    """
    labels = jnp.asarray(labels, jnp.int32)
    disparity = jnp.asarray(disparity, jnp.float32)
    args = (
        jnp.asarray(lab_views, jnp.float32),
        jnp.asarray(offsets, jnp.float32),
        jnp.asarray(compare_lab, jnp.float32),
        jnp.asarray(compare_offsets, jnp.float32),
        jnp.asarray(w_colour, jnp.float32),
        jnp.asarray(w_spatial, jnp.float32),
        jnp.asarray(w_photo, jnp.float32),
    )
    lv, off, cl, co, wc, ws, wp = args
    for _ in range(passes):
        holes = int(jnp.sum(labels < 0))
        if holes == 0:
            break
        labels, disparity = _propagate_pass(
            lv,
            labels,
            disparity,
            off,
            cl,
            co,
            wc,
            ws,
            wp,
            radius=int(radius),
            capacity=_capacity(holes),
        )
    return labels, disparity


@jax.jit
def nearest_fill(
    labels: Int[Array, "N H W"], disparity: Float[Array, "N H W"]
) -> tuple[Int[Array, "N H W"], Float[Array, "N H W"]]:
    """Give every unlabelled pixel the label and disparity of a nearest labelled pixel.

    Repeated 4-neighbour dilation (left, right, up, down neighbour in that order of
    preference) until no unlabelled pixel has a labelled neighbour: the label comes from a
    labelled pixel at the smallest city-block distance. Views without any label stay -1.

    Args:
        labels: ``(N, H, W)`` int32, -1 = unlabelled.
        disparity: ``(N, H, W)`` float32.

    Returns:
        ``(labels, disparity)`` of the same shapes.
    """

    def shifted(a, fill, dy, dx):
        p = jnp.pad(a, ((0, 0), (1, 1), (1, 1)), constant_values=fill)
        H, W = a.shape[1:]
        return p[:, 1 + dy : 1 + dy + H, 1 + dx : 1 + dx + W]

    def body(state):
        lab, d, _ = state
        new_l, new_d = lab, d
        for dy, dx in ((0, -1), (0, 1), (-1, 0), (1, 0))[::-1]:
            nl = shifted(lab, -1, dy, dx)
            nd = shifted(d, 0.0, dy, dx)
            take = (lab < 0) & (nl >= 0)
            new_l = jnp.where(take, nl, new_l)
            new_d = jnp.where(take, nd, new_d)
        return new_l, new_d, jnp.any(new_l != lab)

    lab, d, _ = jax.lax.while_loop(lambda s: s[2], body, (labels, disparity, jnp.array(True)))
    return lab, d
