"""Rasterising and visualising an `EdgeSet`; per-point errors against ground truth."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ._edgeset import EdgeSet


def _pixels(edges: EdgeSet, H: int, W: int):
    xi = jnp.round(edges.x).astype(jnp.int32)
    yi = jnp.round(edges.y).astype(jnp.int32)
    inside = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
    return xi, yi, inside


def render_sparse_disparity(
    edges: EdgeSet, shape: tuple[int, int], *, visible_only: bool = True
) -> tuple[Float[Array, "H W"], Bool[Array, "H W"]]:
    """Rasterise the edge points into a sparse centre-view disparity map.

    Each valid point lands on its nearest pixel; where several land on one pixel the most
    confident wins. Jittable (``shape`` and ``visible_only`` static).

    Args:
        edges: the edge set.
        shape: ``(H, W)`` of the centre view.
        visible_only: use only points visible in the centre view (``edges.visible``).

    Returns:
        ``(disparity (H, W) float32, mask (H, W) bool)``; disparity is 0 where ``mask`` is False.

    Raises:
        ValueError: if ``shape`` is not two positive ints.
    """
    if len(shape) != 2 or min(shape) < 1:
        raise ValueError(f"shape must be (H, W) with positive sizes; got {shape}")
    H, W = int(shape[0]), int(shape[1])
    xi, yi, inside = _pixels(edges, H, W)
    use = edges.valid & inside
    if visible_only:
        use = use & edges.visible
    ys = jnp.where(use, yi, H)  # out of bounds → dropped
    cmax = jnp.full((H, W), -jnp.inf, jnp.float32).at[ys, xi].max(edges.confidence, mode="drop")
    win = use & (edges.confidence >= cmax[jnp.clip(yi, 0, H - 1), jnp.clip(xi, 0, W - 1)])
    ys = jnp.where(win, yi, H)
    disp = jnp.zeros((H, W), jnp.float32).at[ys, xi].set(edges.disparity, mode="drop")
    mask = jnp.zeros((H, W), bool).at[ys, xi].set(True, mode="drop")
    return disp, mask


def point_errors(
    edges: EdgeSet, gt: Float[ArrayLike, "H W"], gt_mask: Bool[ArrayLike, "H W"] | None = None
) -> Float[Array, " N"]:
    """Absolute disparity error of every point: the minimum ``|d - gt|`` over the 3x3
    ground-truth neighbourhood of its nearest pixel (NaN for invalid or off-image points and
    where no neighbour has valid ground truth).

    Args:
        edges: the edge set.
        gt: ``(H, W)`` centre-view ground-truth disparity.
        gt_mask: ``(H, W)`` bool validity of ``gt`` (all valid when ``None``).

    Returns:
        ``(N,)`` float32.
    """
    gt = jnp.asarray(gt, jnp.float32)
    if gt.ndim != 2:
        raise ValueError(f"gt must have shape (H, W); got {tuple(gt.shape)}")
    H, W = gt.shape
    m = jnp.ones((H, W), bool) if gt_mask is None else jnp.asarray(gt_mask, bool)
    xi, yi, inside = _pixels(edges, H, W)
    best = jnp.full(edges.x.shape, jnp.inf, jnp.float32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            y, x = jnp.clip(yi + dy, 0, H - 1), jnp.clip(xi + dx, 0, W - 1)
            e = jnp.where(m[y, x], jnp.abs(edges.disparity - gt[y, x]), jnp.inf)
            best = jnp.minimum(best, e)
    return jnp.where(edges.valid & inside & jnp.isfinite(best), best, jnp.nan)


def render_overlay(
    edges: EdgeSet,
    image: Float[ArrayLike, "H W 3"],
    *,
    d_range: tuple[float, float] | None = None,
    visible_only: bool = True,
) -> np.ndarray:
    """Edge points coloured by disparity over a dimmed greyscale copy of the centre view.

    Args:
        edges: the edge set.
        image: ``(H, W, 3)`` RGB in [0, 1] (the centre view).
        d_range: disparity range mapped to the colour map (default: 2nd–98th percentile of the
            points).
        visible_only: draw only points visible in the centre view.

    Returns:
        ``(H, W, 3)`` uint8 RGB array (write it with e.g. ``cv2.imwrite`` after RGB→BGR).

    Raises:
        ValueError: if ``image`` is not ``(H, W, 3)``.
    """
    import matplotlib

    img = np.asarray(image, np.float32)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image must have shape (H, W, 3); got {img.shape}")
    H, W = img.shape[:2]
    disp, mask = render_sparse_disparity(edges, (H, W), visible_only=visible_only)
    disp, mask = np.asarray(disp), np.asarray(mask)
    grey = 0.35 * img.mean(axis=2, keepdims=True).repeat(3, axis=2)
    if d_range is None:
        vals = disp[mask]
        d_range = (
            (float(np.percentile(vals, 2)), float(np.percentile(vals, 98))) if vals.size else (0, 1)
        )
    lo, hi = d_range
    t = np.clip((disp - lo) / max(hi - lo, 1e-6), 0.0, 1.0)
    colours = matplotlib.colormaps["turbo"](t)[..., :3]
    out = np.where(mask[..., None], colours, grey)
    return (np.clip(out, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
