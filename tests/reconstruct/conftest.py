"""Shared small scenes for the reconstruction tests."""

from __future__ import annotations

import numpy as np
import pytest

from mvedge_jax.reconstruct import oracle_edges
from mvedge_jax.synthetic import make_scene


@pytest.fixture(scope="session")
def small_scene():
    """A 5x5x64x64 synthetic light field (GT in every view) and its GT-derived edge model."""
    lf = make_scene(3, grid=(5, 5), size=(64, 64), disparity_range=(-1.0, 1.0), n_objects=3)
    edges, surface = oracle_edges(lf.centre_view, lf.centre_gt, grid=(5, 5))
    return lf, edges, surface


def two_region_view(H: int = 24, W: int = 32, split: int = 15, seed: int = 0) -> np.ndarray:
    """Red left of column ``split`` (inclusive), blue right of it, mild noise."""
    rng = np.random.default_rng(seed)
    xs = np.arange(W)[None, :, None]
    img = np.where(xs <= split, [0.8, 0.25, 0.2], [0.15, 0.3, 0.85]) * np.ones((H, 1, 1))
    return (img + rng.normal(0, 0.01, img.shape)).clip(0, 1).astype(np.float32)
