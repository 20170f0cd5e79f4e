"""Structural similarity (SSIM) of two images with 3×3 box windows."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._pad import edge_pad


def _box3(a: Array, axes: tuple[int, int]) -> Array:
    """3×3 box mean with edge replication over the two spatial ``axes`` of a 3-D array.

    Two separable ``reduce_window`` sums: their backward pass is again a windowed sum. The
    sum of nine shifted slices it replaces made XLA's CPU backend recompute the SSIM
    expression in the backward pass of each slice (the self-supervised value_and_grad over
    16 views at 512²: 2.1–2.5 s against 0.85–1.0 s on the 2-core CPU).
    """
    pad = [(0, 0)] * a.ndim
    for ax in axes:
        pad[ax] = (1, 1)
    p = edge_pad(a, pad)
    zero = np.zeros((), a.dtype)  # concrete, so that JAX picks the differentiable window sum
    for ax in axes:
        window = tuple(3 if i == ax else 1 for i in range(a.ndim))
        p = jax.lax.reduce_window(p, zero, jax.lax.add, window, (1,) * a.ndim, "VALID")
    return p / 9.0


def ssim_map(
    a: Float[ArrayLike, "H W C"], b: Float[ArrayLike, "H W C"], *, channels_last: bool = True
) -> Array:
    """SSIM per pixel and channel with 3×3 box windows (C1 = 0.01², C2 = 0.03²).

    Args:
        a: ``(H, W, C)`` image in [0, 1] (``(C, H, W)`` with ``channels_last=False``).
        b: the other image, same shape.
        channels_last: the layout of ``a`` and ``b``.

    Returns:
        SSIM in [-1, 1], the shape of the inputs.

    Raises:
        ValueError: if the images are not 3-D or differ in shape.

    References:
        Wang et al., "Image quality assessment: from error visibility to structural
        similarity", IEEE TIP 2004 (thesis ref. [110]).
    """
    a, b = jnp.asarray(a), jnp.asarray(b)
    if a.ndim != 3 or a.shape != b.shape:
        raise ValueError(
            f"ssim_map needs two 3-D images of one shape; got {tuple(a.shape)} and {tuple(b.shape)}"
        )
    axes = (0, 1) if channels_last else (1, 2)
    c1, c2 = 0.01**2, 0.03**2
    mu_a, mu_b = _box3(a, axes), _box3(b, axes)
    va = _box3(a * a, axes) - mu_a**2
    vb = _box3(b * b, axes) - mu_b**2
    cov = _box3(a * b, axes) - mu_a * mu_b
    num = (2 * mu_a * mu_b + c1) * (2 * cov + c2)
    den = (mu_a**2 + mu_b**2 + c1) * (va + vb + c2)
    return num / den


def ssim_dissimilarity(
    a: Float[ArrayLike, "H W C"], b: Float[ArrayLike, "H W C"], *, channels_last: bool = True
) -> Array:
    """``clip((1 - SSIM) / 2, 0, 1)`` per pixel and channel (`ssim_map`): 0 for identical
    local structure, 1 for opposite; the SSIM term of eq 7.16 and of `photo_cost`.

    Args and errors: see `ssim_map`.

    Returns:
        Dissimilarity in [0, 1], the shape of the inputs.
    """
    return jnp.clip((1.0 - ssim_map(a, b, channels_last=channels_last)) / 2.0, 0.0, 1.0)
