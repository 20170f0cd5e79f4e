"""Pictures of superpixel label maps: boundaries over the views, label colours, view sweeps."""

from __future__ import annotations

import numpy as np
from jaxtyping import ArrayLike

from ..metrics import boundary_mask


def draw_boundaries(
    image: ArrayLike, labels: ArrayLike, colour: tuple[float, float, float] = (1.0, 0.1, 0.1)
) -> np.ndarray:
    """A view with its superpixel boundaries painted.

    Args:
        image: ``(H, W, 3)`` float RGB in [0, 1].
        labels: ``(H, W)`` int superpixel labels.
        colour: RGB of the boundary pixels (`boundary_mask`: both sides of every boundary).

    Returns:
        ``(H, W, 3)`` float32 RGB.

    Raises:
        ValueError: if the shapes do not match.
    """
    img = np.asarray(image, np.float32)
    lab = np.asarray(labels)
    if img.ndim != 3 or img.shape[-1] != 3 or img.shape[:2] != lab.shape:
        raise ValueError(
            f"image must be (H, W, 3) and labels (H, W) of the same size; got {img.shape} "
            f"and {lab.shape}"
        )
    out = img.copy()
    out[boundary_mask(lab)] = colour
    return out


def label_colours(labels: ArrayLike, seed: int = 0) -> np.ndarray:
    """A random but fixed colour per label (same label, same colour in every view).

    Args:
        labels: ``(..., H, W)`` non-negative int labels.
        seed: colour table seed.

    Returns:
        ``labels.shape + (3,)`` float32 RGB in [0.15, 1].
    """
    lab = np.asarray(labels)
    table = np.random.default_rng(seed).uniform(0.15, 1.0, (int(lab.max(initial=0)) + 1, 3))
    return table[np.maximum(lab, 0)].astype(np.float32)


def view_sweep(views: ArrayLike, labels: ArrayLike, max_width: int = 256) -> np.ndarray:
    """Tiled view sweep: the centre row of views (top strip) and the centre column of views
    (bottom strip), each with its superpixel boundaries, to show boundary stability.

    Args:
        views: ``(U, V, H, W, 3)`` float RGB in [0, 1].
        labels: ``(U, V, H, W)`` int labels.
        max_width: tiles are downsampled by an integer factor to at most this width.

    Returns:
        ``(2 h + 4, max(U, V) (w + 4), 3)`` float32 RGB mosaic (white gaps).

    Raises:
        ValueError: on mismatched shapes.
    """
    v = np.asarray(views, np.float32)
    lab = np.asarray(labels)
    if v.ndim != 5 or v.shape[:4] != lab.shape:
        raise ValueError(
            f"views must be (U, V, H, W, 3) and labels (U, V, H, W); got {v.shape}, {lab.shape}"
        )
    U, V, H, W = lab.shape
    step = max(1, -(-W // max_width))
    row = [draw_boundaries(v[U // 2, c], lab[U // 2, c])[::step, ::step] for c in range(V)]
    col = [draw_boundaries(v[r, V // 2], lab[r, V // 2])[::step, ::step] for r in range(U)]
    h, w = row[0].shape[:2]
    n = max(U, V)
    out = np.ones((2 * h + 4, n * (w + 4), 3), np.float32)
    for i, t in enumerate(row):
        out[:h, i * (w + 4) : i * (w + 4) + w] = t
    for i, t in enumerate(col):
        out[h + 4 :, i * (w + 4) : i * (w + 4) + w] = t
    return out
