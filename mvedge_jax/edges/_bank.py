"""The oriented Prewitt filter bank of Alg. 1 and the Gaussian pre-blur (thesis 4.1.1)."""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._pad import edge_pad


def filter_disparities(n_filters: int, d_max: float) -> Float[Array, " n"]:
    """Candidate disparities of the bank: ``n_filters`` values evenly spaced in ``[-d_max, d_max]``.

    Args:
        n_filters: number of filters (>= 3).
        d_max: half range, pixels per view step (> 0).

    Returns:
        ``(n_filters,)`` float32, increasing.

    Raises:
        ValueError: if ``n_filters < 3`` or ``d_max <= 0``.
    """
    if n_filters < 3 or not d_max > 0:
        raise ValueError(f"need n_filters >= 3 and d_max > 0; got {n_filters}, {d_max}")
    return jnp.linspace(-d_max, d_max, n_filters, dtype=jnp.float32)


def bank_width(height: int, d_max: float, shift: float = 1.0) -> int:
    """Odd filter width that holds the steepest line of a bank of the given height."""
    half = math.ceil((height // 2) * d_max + shift + 1.0)
    return 2 * half + 1


def prewitt_bank(
    disparities: Float[ArrayLike, " n"],
    height: int,
    width: int,
    *,
    shift: Float[ArrayLike, ""] = 1.0,
    aa_sigma: Float[ArrayLike, ""] = 0.0,
) -> Float[Array, "n height width"]:
    """Oriented derivative-across-a-line ("Prewitt") filters, one per candidate disparity.

    Filter ``i`` is a line through the centre pixel with the EPI slope of disparity ``d_i``
    (column offset ``-a * d_i`` on row offset ``a``, SPEC §0); weight ``+1`` on the line shifted
    ``shift`` pixels left and ``-1`` on the line shifted ``shift`` pixels right, each line drawn
    with linear (tent) anti-aliasing and each side normalised to unit sum. Applied by
    cross-correlation, the response at an EPI pixel is the colour difference across the line
    through that pixel. Pure and differentiable in ``disparities`` and ``shift``.

    Args:
        disparities: ``(n,)`` candidate disparities, pixels per view step.
        height: filter height (odd; rows are angular offsets ``-(height//2) .. height//2``).
            Alg. 1 uses about twice the EPI height; for responses on the centre row of an EPI
            of ``h`` views only the central ``h`` rows matter.
        width: filter width (odd), e.g. `bank_width`.
        shift: distance of each side from the line, pixels.
        aa_sigma: anti-aliasing: each line sample is spread over the columns of its row with a
            Gaussian of this standard deviation (pixels), normalised per row; ``0`` (default):
            linear "tent" interpolation. The tent attenuates lines at half-pixel positions
            slightly, biasing labels towards slopes that hit pixel centres; a Gaussian of
            about 0.3 px reduces that bias.

    Returns:
        ``(n, height, width)`` float32 bank (zero sum per filter).

    Raises:
        ValueError: if ``height`` or ``width`` is not odd and positive, or the steepest line
            does not fit in ``width``.

    References:
        Thesis Alg. 1 and Sec. 4.1.1; SPEC §1.3.
    """
    if height < 1 or height % 2 == 0 or width < 3 or width % 2 == 0:
        raise ValueError(f"filter height and width must be odd and positive; got {height}x{width}")
    disparities = jnp.asarray(disparities)
    dt = jnp.promote_types(jnp.result_type(disparities, shift, aa_sigma), jnp.float32)
    disparities = disparities.astype(dt)
    try:
        dmax = float(jnp.max(jnp.abs(disparities)))
        sh = float(shift)
    except Exception:  # traced: cannot check
        dmax, sh = None, None
    if dmax is not None and (height // 2) * dmax + sh + 1.0 > width // 2:
        raise ValueError(
            f"a {height}x{width} filter cannot hold a line of disparity {dmax:.3f} "
            f"(needs width >= {bank_width(height, dmax, sh)})"
        )
    a = jnp.arange(height, dtype=dt) - height // 2  # (height,)
    k = jnp.arange(width, dtype=dt) - width // 2  # (width,)
    centre = -a[None, :, None] * disparities[:, None, None]  # (n, height, 1)
    pos = _spread(k[None, None, :] - (centre - shift), aa_sigma)
    neg = _spread(k[None, None, :] - (centre + shift), aa_sigma)
    pos = pos / jnp.sum(pos, axis=(1, 2), keepdims=True)
    neg = neg / jnp.sum(neg, axis=(1, 2), keepdims=True)
    return pos - neg


def _spread(t, aa_sigma):
    """Row-normalised weights of a line sample at signed column distance ``t``."""
    aa_sigma = jnp.asarray(aa_sigma, t.dtype)
    tent = jnp.maximum(0.0, 1.0 - jnp.abs(t))
    safe = jnp.where(aa_sigma > 0, aa_sigma, 1.0)
    g = jnp.exp(-0.5 * (t / safe) ** 2)
    g = g / jnp.sum(g, axis=-1, keepdims=True)
    return jnp.where(aa_sigma > 0, g, tent)


def gaussian_kernel(sigma: Float[ArrayLike, ""], radius: int) -> Float[Array, " k"]:
    """Normalised 1-D Gaussian of standard deviation ``sigma`` pixels, ``2 * radius + 1`` taps.

    Differentiable in ``sigma``.
    """
    sigma = jnp.asarray(sigma)
    sigma = sigma.astype(jnp.promote_types(sigma.dtype, jnp.float32))
    t = jnp.arange(-radius, radius + 1, dtype=sigma.dtype)
    g = jnp.exp(-0.5 * (t / sigma) ** 2)
    return g / jnp.sum(g)


def blur_images(
    images: Float[Array, "N H W C"], sigma: Float[ArrayLike, ""], radius: int
) -> Float[Array, "N H W C"]:
    """Separable Gaussian blur of a batch of images (edge-replicated borders).

    Args:
        images: ``(N, H, W, C)``.
        sigma: standard deviation in pixels (differentiable).
        radius: kernel half-width in pixels.

    Returns:
        ``(N, H, W, C)`` blurred images, same dtype.
    """
    g = gaussian_kernel(sigma, radius).astype(images.dtype)
    p = edge_pad(images, ((0, 0), (radius, radius), (0, 0), (0, 0)))
    H = images.shape[1]
    out = sum(g[i] * p[:, i : i + H] for i in range(2 * radius + 1))
    p = edge_pad(out, ((0, 0), (0, 0), (radius, radius), (0, 0)))
    W = images.shape[2]
    return sum(g[i] * p[:, :, i : i + W] for i in range(2 * radius + 1))
