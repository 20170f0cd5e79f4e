"""Helpers shared by the reconstruction tests."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from scipy.ndimage import grey_dilation


def two_region_view(H: int = 24, W: int = 32, split: int = 15, seed: int = 0) -> np.ndarray:
    """Red left of column ``split`` (inclusive), blue right of it, mild noise."""
    rng = np.random.default_rng(seed)
    xs = np.arange(W)[None, :, None]
    img = np.where(xs <= split, [0.8, 0.25, 0.2], [0.15, 0.3, 0.85]) * np.ones((H, 1, 1))
    return (img + rng.normal(0, 0.01, img.shape)).clip(0, 1).astype(np.float32)


def cross_hair(lf):
    """The cross-hair views of ``lf`` without the centre ``(K, H, W, 3)`` and their
    ``(dr, dc)`` offsets from the centre ``(K, 2)``."""
    U, V = lf.grid
    rc, cc = U // 2, V // 2
    pos = [(rc, c) for c in range(V) if c != cc] + [(r, cc) for r in range(U) if r != rc]
    views = jnp.stack([lf.views[r, c] for r, c in pos])
    offsets = jnp.asarray([(r - rc, c - cc) for r, c in pos], jnp.float32)
    return views, offsets


def interior(gt, size: int = 9, jump: float = 0.05) -> np.ndarray:
    """Pixels whose ``size²`` window spans less than ``jump`` of GT disparity."""
    g = np.asarray(gt)
    return grey_dilation(g, size=(size, size)) + grey_dilation(-g, size=(size, size)) < jump
