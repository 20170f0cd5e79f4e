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


def _propagate_view(
    lab_img, labels, disp, offset, cmp_lab, cmp_off, w_colour, w_spatial, w_photo, radius
):
    """One pass of eq 5.1 on one view: every unlabelled pixel takes the cheapest labelled
    candidate within the chessboard ``radius``."""
    H, W = labels.shape
    y, x = jnp.meshgrid(jnp.arange(H), jnp.arange(W), indexing="ij")
    side = 2 * radius + 1

    def body(k, carry):
        best_c, best_l, best_d = carry
        sy = k // side - radius
        sx = k % side - radius
        cy, cx = y + sy, x + sx
        inside = (cy >= 0) & (cy < H) & (cx >= 0) & (cx < W)
        cy, cx = jnp.clip(cy, 0, H - 1), jnp.clip(cx, 0, W - 1)
        cl = jnp.where(inside, labels[cy, cx], -1)
        cd = disp[cy, cx]
        cost = w_colour * jnp.sum((lab_img - lab_img[cy, cx]) ** 2, -1)
        cost = cost + w_spatial * (sy * sy + sx * sx).astype(cost.dtype)

        def photo(m, acc):
            ddr = offset[0] - cmp_off[m, 0]
            ddc = offset[1] - cmp_off[m, 1]
            py = jnp.clip(jnp.rint(y + ddr * cd).astype(jnp.int32), 0, H - 1)
            px = jnp.clip(jnp.rint(x + ddc * cd).astype(jnp.int32), 0, W - 1)
            return acc + jnp.sum(jnp.abs(lab_img - cmp_lab[m][py, px]), -1)

        pc = jax.lax.fori_loop(0, cmp_lab.shape[0], photo, jnp.zeros_like(cost))
        cost = cost + w_photo * pc
        better = (cl >= 0) & (cost < best_c)
        return (
            jnp.where(better, cost, best_c),
            jnp.where(better, cl, best_l),
            jnp.where(better, cd, best_d),
        )

    init = (jnp.full((H, W), jnp.inf, lab_img.dtype), jnp.full((H, W), -1, jnp.int32), disp)
    _, bl, bd = jax.lax.fori_loop(0, side * side, body, init)
    free = labels < 0
    return jnp.where(free, bl, labels), jnp.where(free & (bl >= 0), bd, disp)


@functools.partial(jax.jit, static_argnames=("radius", "passes"))
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
    pixel). The pixel takes the cheapest candidate's label and disparity. ``passes`` passes
    reach pixels up to ``passes · radius`` from a label.

    Args:
        lab_views: ``(N, H, W, 3)`` CIELAB of the views to label.
        labels: ``(N, H, W)`` int32, -1 = unlabelled.
        disparity: ``(N, H, W)`` float32 of the labelled pixels.
        offsets: ``(N, 2)`` ``(dr, dc)`` of each view from the centre view.
        compare_lab: ``(M, H, W, 3)`` CIELAB of the comparison views.
        compare_offsets: ``(M, 2)`` their offsets.
        w_colour, w_spatial, w_photo: ω_c, ω_s, ω_d of eq 5.1.
        radius: search radius in pixels (static).
        passes: number of passes (static).

    Returns:
        ``(labels, disparity)``, shapes as the inputs.

    References:
        Thesis Sec. 5.1.1 ("Label Propagation", eq 5.1).
    """
    one = lambda li, lb, d, o: _propagate_view(  # noqa: E731
        li, lb, d, o, compare_lab, compare_offsets, w_colour, w_spatial, w_photo, radius
    )
    for _ in range(passes):
        labels, disparity = jax.vmap(one)(lab_views, labels, disparity, offsets)
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
