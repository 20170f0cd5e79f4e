"""Shared small scenes for the reconstruction tests."""

from __future__ import annotations

import pytest

from mvedge_jax.reconstruct import oracle_edges
from mvedge_jax.synthetic import make_scene


@pytest.fixture(scope="session")
def small_scene():
    """A 5x5x64x64 synthetic light field (GT in every view) and its GT-derived edge model."""
    lf = make_scene(3, grid=(5, 5), size=(64, 64), disparity_range=(-1.0, 1.0), n_objects=3)
    edges, surface = oracle_edges(lf.centre_view, lf.centre_gt, grid=(5, 5))
    return lf, edges, surface
