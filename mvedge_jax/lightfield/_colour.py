"""Colour conversion in JAX (sRGB D65 → CIELAB)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

# sRGB (linear) → XYZ, D65 white.
_RGB_TO_XYZ = jnp.array(
    [
        [0.412453, 0.357580, 0.180423],
        [0.212671, 0.715160, 0.072169],
        [0.019334, 0.119193, 0.950227],
    ],
    dtype=jnp.float32,
)
_WHITE_D65 = jnp.array([0.950456, 1.0, 1.088754], dtype=jnp.float32)


def rgb_to_lab(rgb: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Convert sRGB in [0, 1] to CIELAB (D65), differentiably.

    Matches OpenCV's ``cv2.COLOR_RGB2LAB`` on float input: L* in [0, 100], a* and b* roughly
    in [-128, 127].

    Args:
        rgb: ``(..., 3)`` sRGB values in [0, 1] (any float dtype).

    Returns:
        ``(..., 3)`` array of ``(L*, a*, b*)``, same dtype as the input.
    """
    rgb = jnp.asarray(rgb)
    lin = jnp.where(
        rgb > 0.04045, ((jnp.maximum(rgb, 0.04045) + 0.055) / 1.055) ** 2.4, rgb / 12.92
    )
    xyz = lin @ _RGB_TO_XYZ.T.astype(lin.dtype)
    t = xyz / _WHITE_D65.astype(lin.dtype)
    eps = (6.0 / 29.0) ** 3
    f = jnp.where(t > eps, jnp.cbrt(jnp.maximum(t, eps)), t / (3 * (6.0 / 29.0) ** 2) + 4.0 / 29.0)
    L = jnp.where(t[..., 1] > eps, 116.0 * f[..., 1] - 16.0, 903.3 * t[..., 1])
    a = 500.0 * (f[..., 0] - f[..., 1])
    b = 200.0 * (f[..., 1] - f[..., 2])
    return jnp.stack([L, a, b], axis=-1)
