"""Helpers shared by the reconstruction tests."""

from __future__ import annotations

import numpy as np


def two_region_view(H: int = 24, W: int = 32, split: int = 15, seed: int = 0) -> np.ndarray:
    """Red left of column ``split`` (inclusive), blue right of it, mild noise."""
    rng = np.random.default_rng(seed)
    xs = np.arange(W)[None, :, None]
    img = np.where(xs <= split, [0.8, 0.25, 0.2], [0.15, 0.3, 0.85]) * np.ones((H, 1, 1))
    return (img + rng.normal(0, 0.01, img.shape)).clip(0, 1).astype(np.float32)
