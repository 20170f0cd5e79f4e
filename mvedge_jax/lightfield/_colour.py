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


def srgb_to_linear(rgb: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Decode sRGB in [0, 1] to linear light (IEC 61966-2-1 transfer curve), differentiably.

    Light mixes linearly in this space: a pixel that sees two surfaces (an anti-aliased
    render, a camera pixel on an occlusion edge) is their area-weighted mean here, not in
    the encoded values.

    Args:
        rgb: ``(..., 3)`` (or any shape) sRGB values in [0, 1] (any float dtype).

    Returns:
        Linear-light values in [0, 1], same shape and dtype as the input.
    """
    rgb = jnp.asarray(rgb)
    # x ** 2.4 as exp/log: XLA's CPU pow is about 4x slower.
    x = jnp.maximum(rgb, 0.04045)
    return jnp.where(rgb > 0.04045, jnp.exp(2.4 * jnp.log((x + 0.055) / 1.055)), rgb / 12.92)


def linear_to_srgb(linear: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Encode linear light in [0, 1] as sRGB (the inverse of `srgb_to_linear`).

    Args:
        linear: linear-light values in [0, 1] (any shape, any float dtype).

    Returns:
        sRGB values in [0, 1], same shape and dtype as the input.
    """
    linear = jnp.asarray(linear)
    x = jnp.maximum(linear, 0.0031308)
    return jnp.where(linear > 0.0031308, 1.055 * jnp.exp(jnp.log(x) / 2.4) - 0.055, 12.92 * linear)


def rgb_to_lab(rgb: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Convert sRGB in [0, 1] to CIELAB (D65), differentiably.

    Matches OpenCV's ``cv2.COLOR_RGB2LAB`` on float input: L* in [0, 100], a* and b* roughly
    in [-128, 127].

    Args:
        rgb: ``(..., 3)`` sRGB values in [0, 1] (any float dtype).

    Returns:
        ``(..., 3)`` array of ``(L*, a*, b*)``, same dtype as the input.
    """
    # x ** 2.4 and cbrt as exp/log: XLA's CPU pow and cbrt are about 4x slower (42.8 ms
    # against 10.9 ms on a 512² image, 2-core CPU); the results agree to 1e-4 in L*a*b*.
    lin = srgb_to_linear(rgb)
    m = (_RGB_TO_XYZ / _WHITE_D65[:, None]).astype(lin.dtype)
    r, g, b = lin[..., 0], lin[..., 1], lin[..., 2]
    eps = (6.0 / 29.0) ** 3

    def f(t):
        cube_root = jnp.exp(jnp.log(jnp.maximum(t, eps)) / 3.0)
        return jnp.where(t > eps, cube_root, t / (3 * (6.0 / 29.0) ** 2) + 4.0 / 29.0)

    tx, ty, tz = (m[k, 0] * r + m[k, 1] * g + m[k, 2] * b for k in range(3))
    fx, fy, fz = f(tx), f(ty), f(tz)
    L = jnp.where(ty > eps, 116.0 * fy - 16.0, 903.3 * ty)
    return jnp.stack([L, 500.0 * (fx - fy), 200.0 * (fy - fz)], axis=-1)
