"""Input check shared by the functions that take one image: ``(H, W)`` or ``(H, W, C)``, float."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


def as_float_image(image: ArrayLike, name: str) -> Float[Array, "H W *C"]:
    """``image`` as a JAX array of 2 or 3 dimensions, in float32 if it was not float.

    Raises:
        ValueError: naming ``name``, if ``image`` is not 2-D or 3-D, or 3-D with no channel.
    """
    image = jnp.asarray(image)
    if image.ndim not in (2, 3):
        raise ValueError(f"{name} must have shape (H, W) or (H, W, C); got {tuple(image.shape)}")
    if image.ndim == 3 and image.shape[-1] == 0:
        raise ValueError(f"{name} has no channel: shape {tuple(image.shape)}")
    if not jnp.issubdtype(image.dtype, jnp.floating):
        image = image.astype(jnp.float32)
    return image
