"""The matrix-free weighted screened-Poisson operator ``A = Λ_d + L_w`` (SPEC §5).

The energy ``Σ λ_d (D − S)² + Σ_{horizontal} w_x (D[y, x+1] − D[y, x])²
+ Σ_{vertical} w_y (D[y+1, x] − D[y, x])²`` has the normal equations ``(Λ_d + L_w) D = Λ_d S``
where ``L_w`` is the weighted graph Laplacian of the 4-neighbour grid. Pixels on the border
simply have fewer neighbours (natural / Neumann boundary).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


def laplacian(
    x: Float[Array, "H W"], weight_x: Float[Array, "H W-1"], weight_y: Float[Array, "H-1 W"]
) -> Float[Array, "H W"]:
    """``L_w x``: ``(L_w x)_p = Σ_q w_pq (x_p − x_q)`` over the 4-neighbours ``q`` of ``p``."""
    fx = weight_x * (x[:, 1:] - x[:, :-1])  # flux across each horizontal edge
    fy = weight_y * (x[1:, :] - x[:-1, :])
    out = jnp.pad(fx, ((0, 0), (1, 0))) - jnp.pad(fx, ((0, 0), (0, 1)))
    out = out + jnp.pad(fy, ((1, 0), (0, 0))) - jnp.pad(fy, ((0, 1), (0, 0)))
    return out


def matvec(
    x: Float[Array, "H W"],
    data_weight: Float[Array, "H W"],
    weight_x: Float[Array, "H W-1"],
    weight_y: Float[Array, "H-1 W"],
) -> Float[Array, "H W"]:
    """``A x = λ_d ⊙ x + L_w x``."""
    return data_weight * x + laplacian(x, weight_x, weight_y)


def diagonal(
    data_weight: Float[Array, "H W"],
    weight_x: Float[Array, "H W-1"],
    weight_y: Float[Array, "H-1 W"],
) -> Float[Array, "H W"]:
    """The diagonal of ``A``: ``λ_d + Σ_q w_pq``."""
    d = data_weight
    d = d + jnp.pad(weight_x, ((0, 0), (1, 0))) + jnp.pad(weight_x, ((0, 0), (0, 1)))
    d = d + jnp.pad(weight_y, ((1, 0), (0, 0))) + jnp.pad(weight_y, ((0, 1), (0, 0)))
    return d


def dense_matrix(
    data_weight: Float[Array, "H W"],
    weight_x: Float[Array, "H W-1"],
    weight_y: Float[Array, "H-1 W"],
) -> Float[Array, "HW HW"]:
    """The dense ``(H·W, H·W)`` matrix of ``A`` in row-major pixel order (tiny grids only)."""
    H, W = data_weight.shape
    n = H * W
    # Columns of A are A applied to the basis vectors (A is symmetric, rows == columns).
    eye = jnp.eye(n, dtype=data_weight.dtype).reshape(n, H, W)
    cols = jax.vmap(lambda e: matvec(e, data_weight, weight_x, weight_y))(eye)
    return cols.reshape(n, n).T


def stencil_matrix(
    data_weight: Float[Array, "H W"],
    weight_x: Float[Array, "H W-1"],
    weight_y: Float[Array, "H-1 W"],
) -> Float[Array, "HW HW"]:
    """Same as `dense_matrix`, assembled directly from the stencil by scattering (cheaper)."""
    H, W = data_weight.shape
    n = H * W
    idx = np.arange(n).reshape(H, W)
    ix, jx = idx[:, :-1].ravel(), idx[:, 1:].ravel()
    iy, jy = idx[:-1, :].ravel(), idx[1:, :].ravel()
    d = diagonal(data_weight, weight_x, weight_y).ravel()
    A = jnp.zeros((n, n), data_weight.dtype).at[idx.ravel(), idx.ravel()].set(d)
    A = A.at[ix, jx].add(-weight_x.ravel()).at[jx, ix].add(-weight_x.ravel())
    A = A.at[iy, jy].add(-weight_y.ravel()).at[jy, iy].add(-weight_y.ravel())
    return A
