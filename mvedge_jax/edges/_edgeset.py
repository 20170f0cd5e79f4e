"""The `EdgeSet` pytree: a fixed-capacity set of multi-view edge points (thesis Ch. 4.1)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

HORIZONTAL = 0  # point came from a horizontal EPI (centre row of views)
VERTICAL = 1  # point came from a vertical EPI (centre column of views)


class EdgeSet(eqx.Module):
    """Multi-view edge points, fixed capacity ``N`` with a validity mask.

    Every field has leading dimension ``N``; entries with ``valid == False`` are padding and
    carry no meaning. Positions are centre-view pixel coordinates (x = column, y = row, pixel
    centres at integers); disparity is in pixels per view step (SPEC §0 sign: larger = nearer).

    Attributes:
        x: ``(N,)`` float32 centre-view column of the point (sub-pixel).
        y: ``(N,)`` float32 centre-view row of the point (sub-pixel).
        disparity: ``(N,)`` float32, pixels per view step.
        confidence: ``(N,)`` float32, >= 0.
        visible: ``(N,)`` bool, the line is visible in the centre view (eq 4.4).
        lab: ``(N, 3)`` float32 CIELAB colour of the point in the centre view.
        direction: ``(N,)`` int32, `HORIZONTAL` (0) or `VERTICAL` (1) EPI of origin.
        intercepts: ``(N, 2)`` float32, the line's position along the EPI's spatial axis on
            its first and last angular row (x for horizontal EPIs, y for vertical ones).
        valid: ``(N,)`` bool.
        n_dropped: ``()`` int32, points lost to capacity overflow (0 when nothing was lost).
    """

    x: Float[Array, " N"]
    y: Float[Array, " N"]
    disparity: Float[Array, " N"]
    confidence: Float[Array, " N"]
    visible: Bool[Array, " N"]
    lab: Float[Array, "N 3"]
    direction: Int[Array, " N"]
    intercepts: Float[Array, "N 2"]
    valid: Bool[Array, " N"]
    n_dropped: Int[Array, ""]

    @property
    def capacity(self) -> int:
        """``N``, the fixed capacity."""
        return int(self.x.shape[0])

    @property
    def n_valid(self) -> Int[Array, ""]:
        """Number of valid points (a traced scalar under jit)."""
        return jnp.sum(self.valid.astype(jnp.int32))

    @staticmethod
    def empty(capacity: int) -> EdgeSet:
        """An all-invalid set of the given capacity."""
        z = jnp.zeros((capacity,), jnp.float32)
        return EdgeSet(
            x=z,
            y=z,
            disparity=z,
            confidence=z,
            visible=jnp.zeros((capacity,), bool),
            lab=jnp.zeros((capacity, 3), jnp.float32),
            direction=jnp.zeros((capacity,), jnp.int32),
            intercepts=jnp.zeros((capacity, 2), jnp.float32),
            valid=jnp.zeros((capacity,), bool),
            n_dropped=jnp.zeros((), jnp.int32),
        )


def concatenate(a: EdgeSet, b: EdgeSet) -> EdgeSet:
    """Concatenate two edge sets (capacity ``Na + Nb``); ``n_dropped`` adds up."""
    return jax.tree.map(lambda u, v: jnp.concatenate([u, v]) if u.ndim else u + v, a, b)
