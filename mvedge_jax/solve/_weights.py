"""Edge weights of the smoothness term from a guide image (thesis eq 4.11: 1/(|∇I| + ε))."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._image import as_float_image


def _safe_norm(parts: list[Array]) -> Array:
    """Euclidean norm of the arrays ``parts`` (one per channel), element by element, with a
    finite gradient at zero."""
    s = sum(d * d for d in parts)
    pos = s > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, s, 1.0)), 0.0)


def guide_differences(
    guide: Float[ArrayLike, "H W *C"],
) -> tuple[Float[Array, "H W-1"], Float[Array, "H-1 W"]]:
    """``|∇guide|`` on the 4-neighbour edges of a grid: the Euclidean norm over the channels
    of the forward difference between the two pixels each edge joins.

    Args:
        guide: ``(H, W)`` or ``(H, W, C)`` image (an integer one is taken as float32).

    Returns:
        ``(dx (H, W-1), dy (H-1, W))`` in the guide's units and float dtype; differentiable,
        with a finite gradient where a difference is 0.

    Raises:
        ValueError: if ``guide`` is not 2-D or 3-D, or 3-D with no channel.

    References:
        The ``|∇I|`` of thesis eq 4.11 and eq 6.4.
    """
    guide = as_float_image(guide, "guide")
    # The channels as separate (H, W) planes: a reduction over a short channel axis makes
    # XLA's CPU backend write both shifted slices to memory first.
    planes = [guide] if guide.ndim == 2 else [guide[..., c] for c in range(guide.shape[-1])]
    return (
        _safe_norm([p[:, 1:] - p[:, :-1] for p in planes]),
        _safe_norm([p[1:, :] - p[:-1, :] for p in planes]),
    )


def guide_edge_weights(
    guide: Float[ArrayLike, "H W *C"],
    *,
    scale: Float[ArrayLike, ""] = 1.0,
    eps: Float[ArrayLike, ""] = 1e-2,
) -> tuple[Float[Array, "H W-1"], Float[Array, "H-1 W"]]:
    """Smoothness weights ``scale / (|∇guide| + eps)`` on the 4-neighbour edges of a grid.

    ``|∇guide|`` across an edge is the Euclidean norm over channels of the forward
    difference between the two pixels it joins (in the guide's units, e.g. [0, 1] RGB).

    Args:
        guide: ``(H, W)`` or ``(H, W, C)`` float image.
        scale: scalar numerator ``c`` (differentiable).
        eps: scalar ``ε > 0`` in the guide's units (differentiable); bounds the weight by
            ``scale / eps``.

    Returns:
        ``(weight_x (H, W-1), weight_y (H-1, W))`` in the guide's float dtype, ready for
        `solve_poisson`.

    Raises:
        ValueError: if ``guide`` is not 2-D or 3-D (with a channel), or a concrete ``eps`` is
            not positive.

    References:
        Thesis eq 4.11 and eq 6.4 (smoothness ``c / (|∇I| + ε)``).
    """
    try:
        eps_value = float(eps)
    except Exception:  # a tracer: cannot check
        eps_value = None
    if eps_value is not None and not eps_value > 0:
        raise ValueError(f"eps must be > 0; got {eps_value}")
    gx, gy = guide_differences(guide)
    scale = jnp.asarray(scale, gx.dtype)
    eps = jnp.asarray(eps, gx.dtype)
    return scale / (gx + eps), scale / (gy + eps)
