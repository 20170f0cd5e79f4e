"""Fixtures: a small synthetic light field with object IDs and its exact EPI lines."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.edges import HORIZONTAL, VERTICAL, EdgeSet
from mvedge_jax.synthetic import make_scene_with_objects


def oracle_edges(ids: np.ndarray, gt: np.ndarray, grid: tuple[int, int]):
    """Edge set of the exact object boundaries of the centre view and their surface vectors.

    A boundary between pixels ``k`` and ``k + 1`` of a row (column) is a horizontal (vertical)
    EPI line at ``k + 0.5`` with the nearer side's disparity; its surface vector points to the
    nearer side.
    """
    U, V = grid
    pts = []
    for direction, (a, g) in ((HORIZONTAL, (ids, gt)), (VERTICAL, (ids.T, gt.T))):
        i, k = np.nonzero(a[:, 1:] != a[:, :-1])
        near_right = g[i, k + 1] > g[i, k]
        d = np.maximum(g[i, k], g[i, k + 1])
        side = np.where(near_right, 1.0, -1.0)
        pos = k + 0.5
        n = V if direction == HORIZONTAL else U
        for e, p, dd, s in zip(i, pos, d, side, strict=True):
            x, y = (p, e) if direction == HORIZONTAL else (e, p)
            off = (s, 0.0) if direction == HORIZONTAL else (0.0, s)
            pts.append((x, y, dd, direction, p + (n // 2) * dd, p - (n - 1 - n // 2) * dd, *off))
    a = np.asarray(pts, np.float32)
    N = a.shape[0]
    edges = EdgeSet(
        x=jnp.asarray(a[:, 0]),
        y=jnp.asarray(a[:, 1]),
        disparity=jnp.asarray(a[:, 2]),
        confidence=jnp.ones((N,), jnp.float32),
        visible=jnp.ones((N,), bool),
        lab=jnp.zeros((N, 3), jnp.float32),
        direction=jnp.asarray(a[:, 3].astype(np.int32)),
        intercepts=jnp.asarray(a[:, 4:6]),
        valid=jnp.ones((N,), bool),
        n_dropped=jnp.zeros((), jnp.int32),
    )
    return edges, jnp.asarray(a[:, 6:8])


@pytest.fixture(scope="session")
def scene():
    """5x5 views of 64x64 px, 4 objects in front of a floor and a wall, with object IDs."""
    lf, ids = make_scene_with_objects(0, grid=(5, 5), size=(64, 64), n_objects=4)
    ids = np.asarray(ids)
    edges, offset = oracle_edges(ids[2, 2], np.asarray(lf.gt_disparity[2, 2]), lf.grid)
    return lf, ids, edges, offset
