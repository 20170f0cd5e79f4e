"""EPI edge detection with the oriented filter bank (thesis Alg. 1, Sec. 4.1.1).

Responses are computed on the centre row of each EPI only (the row of the centre view), which
is all the centre-view points need and ~h times cheaper than the full EPI.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int

from .._pad import edge_pad

_EPS = 1e-12


def _check_epis(epis, bank):
    if epis.ndim != 4:
        raise ValueError(f"epis must have shape (N, h, W, C); got {tuple(epis.shape)}")
    if epis.shape[-1] == 0:
        raise ValueError(f"epis have no channel: shape {tuple(epis.shape)}")
    if bank.ndim != 3 or bank.shape[2] % 2 == 0:
        raise ValueError(f"bank must have shape (n, rows, odd width); got {tuple(bank.shape)}")
    h = epis.shape[1]
    if h < 3:
        raise ValueError(f"an EPI needs at least 3 views (rows); got shape {tuple(epis.shape)}")
    if bank.shape[1] < h or bank.shape[1] % 2 == 0:
        raise ValueError(f"bank height {bank.shape[1]} must be odd and >= the EPI height {h}")


def centre_bank(bank: Float[Array, "n R Fw"], h: int) -> Float[Array, "n h Fw"]:
    """The rows of ``bank`` that meet an ``h``-row EPI when centred on its centre row, each side
    (positive / negative weights) renormalised to unit sum."""
    R = bank.shape[1]
    sub = bank[:, R // 2 - h // 2 : R // 2 - h // 2 + h]
    pos = jnp.maximum(sub, 0.0)
    neg = jnp.maximum(-sub, 0.0)
    return pos / jnp.sum(pos, axis=(1, 2), keepdims=True) - neg / jnp.sum(
        neg, axis=(1, 2), keepdims=True
    )


def _centre_conv(epis: Array, bank: Array) -> Array:
    """Signed responses of every filter on the centre row of every EPI, per channel:
    ``(N, C, W, n)`` (edge-replicated borders; see `centre_response_magnitude`)."""
    _check_epis(epis, bank)
    N, h, W, C = epis.shape
    n, _, Fw = bank.shape
    sub = centre_bank(bank, h)
    pad = Fw // 2
    lhs = jnp.transpose(epis, (0, 3, 2, 1)).reshape(N * C, W, h)  # rows become in-channels
    lhs = edge_pad(lhs, ((0, 0), (pad, pad), (0, 0)))
    rhs = jnp.transpose(sub, (2, 1, 0)).astype(epis.dtype)  # (Fw, h, n)
    # Full float32 precision: a GPU would otherwise round the inputs to TensorFloat-32
    # (10-bit mantissa) by default.
    out = lax.conv_general_dilated(
        lhs,
        rhs,
        (1,),
        "VALID",
        dimension_numbers=("NWC", "WIO", "NWC"),
        precision=lax.Precision.HIGHEST,
    )  # (N*C, W, n)
    return out.reshape(N, C, W, n)


def centre_response_magnitude(
    epis: Float[Array, "N h W C"], bank: Float[Array, "n R Fw"]
) -> Float[Array, "N W n"]:
    """Magnitude of the oriented filters' responses on the centre row of every EPI.

    Each filter of ``bank`` (centred on the EPI's centre row, `centre_bank`) is applied to
    every channel; the magnitude is the Euclidean norm of the signed per-channel responses.
    The channels are summed as separate planes straight from the convolution's output: on
    XLA's CPU backend a reduction over a short channel axis needs the responses transposed
    into memory first, which costs more than the sum.

    Args:
        epis: ``(N, h, W, C)`` EPIs (rows = views, ``h`` odd).
        bank: ``(n, R, Fw)`` filter bank (`prewitt_bank`), ``R >= h`` odd.

    Returns:
        ``(N, W, n)`` magnitudes (Euclidean norm over the channels), the dtype of ``epis``.

    Raises:
        ValueError: if ``epis`` is not 4-D with at least 3 rows and a channel, or ``bank`` is
            not ``(n, R, Fw)`` with ``R >= h`` odd and ``Fw`` odd.

    References:
        Thesis Alg. 1 (the filter responses of the oriented bank, Sec. 4.1.1).
    """
    out = _centre_conv(epis, bank)
    squares = [out[:, c] * out[:, c] for c in range(out.shape[1])]
    return jnp.sqrt(sum(squares) + _EPS)


def detect_centre_row(
    epis: Float[Array, "N h W C"], bank: Float[Array, "n R Fw"], *, chunk: int = 64
) -> dict[str, Array]:
    """Hard detection on the centre row of every EPI (Alg. 1 without NMS / modulation).

    The full response stack is never materialised: EPIs are processed ``chunk`` at a time and
    reduced to the maximum over filters.

    Args:
        epis: ``(N, h, W, C)`` EPIs.
        bank: ``(n, R, Fw)`` filter bank.
        chunk: EPIs per chunk.

    Returns:
        dict with ``(N, W)`` arrays: ``conf`` (max response), ``label`` (int32 argmax),
        ``r_prev`` / ``r_next`` (responses of filters ``label - 1`` / ``label + 1``, clamped).
    """
    _check_epis(epis, bank)
    n = bank.shape[0]

    def one(e):
        mag = centre_response_magnitude(e[None], bank)[0]  # (W, n)
        lab = jnp.argmax(mag, axis=-1).astype(jnp.int32)
        take = lambda i: jnp.take_along_axis(mag, jnp.clip(i, 0, n - 1)[:, None], axis=-1)[:, 0]
        return {"conf": take(lab), "label": lab, "r_prev": take(lab - 1), "r_next": take(lab + 1)}

    # lax.map with batch_size vmaps `one` over chunks of EPIs: one conv per chunk.
    return lax.map(one, epis, batch_size=min(chunk, epis.shape[0]))


def local_std(epis: Float[Array, "N h W C"]) -> Float[Array, "N W"]:
    """Colour standard deviation of the 3x3 window around each centre-row EPI pixel
    (Euclidean norm of the per-channel standard deviations; edge-replicated borders)."""
    h, W = epis.shape[1], epis.shape[2]
    # Each channel as (N, W) planes of the nine window samples: a variance over stacked
    # samples and a sum over the short channel axis run ~8x slower on XLA's CPU backend.
    variances = []
    for c in range(epis.shape[-1]):
        rows = edge_pad(epis[:, h // 2 - 1 : h // 2 + 2, :, c], ((0, 0), (0, 0), (1, 1)))
        samples = [rows[:, a, i : i + W] for a in range(3) for i in range(3)]
        mean = sum(samples) / 9.0
        variances.append(sum((x - mean) ** 2 for x in samples) / 9.0)
    return jnp.sqrt(sum(variances) + _EPS)


def non_max_suppress(conf: Float[Array, "N W"]) -> Float[Array, "N W"]:
    """Keep local maxima across the line direction (along x); others become 0."""
    left = jnp.pad(conf[:, :-1], ((0, 0), (1, 0)), constant_values=-jnp.inf)
    right = jnp.pad(conf[:, 1:], ((0, 0), (0, 1)), constant_values=-jnp.inf)
    keep = (conf > left) & (conf >= right)
    return jnp.where(keep, conf, 0.0)


def parabola_offset(ym: ArrayLike, y0: ArrayLike, yp: ArrayLike) -> Array:
    """Vertex offset in [-0.5, 0.5] of the parabola through (-1, ym), (0, y0), (1, yp)."""
    den = ym - 2.0 * y0 + yp
    off = jnp.where(jnp.abs(den) > 1e-12, 0.5 * (ym - yp) / jnp.where(den == 0, 1.0, den), 0.0)
    return jnp.clip(off, -0.5, 0.5)


def soft_detect(
    epis: Float[Array, "N h W C"],
    bank: Float[Array, "n R Fw"],
    disparities: Float[Array, " n"],
    temperature: Float[ArrayLike, ""],
) -> tuple[Float[Array, "N W"], Float[Array, "N W"]]:
    """Differentiable detection on the centre row: softmax over the filter responses.

    ``p_i = softmax(r_i / temperature)``; expected disparity ``Σ p_i d_i`` and soft confidence
    ``Σ p_i r_i`` (→ the hard max as the temperature → 0). Gradients flow to the EPIs, the bank
    (hence its disparities / shift) and the temperature.

    Args:
        epis: ``(N, h, W, C)`` EPIs.
        bank: ``(n, R, Fw)`` filter bank.
        disparities: ``(n,)`` the bank's disparities.
        temperature: softmax temperature, response units (> 0).

    Returns:
        ``(disparity, confidence)``, each ``(N, W)``.

    References:
        Thesis Alg. 1 (hard argmax/max), relaxed.
    """
    return soft_select(centre_response_magnitude(epis, bank), disparities, temperature)


def soft_select(
    magnitude: Float[Array, "... n"],
    disparities: Float[Array, " n"],
    temperature: Float[ArrayLike, ...],
) -> tuple[Float[Array, ...], Float[Array, ...]]:
    """Softmax over filter-response magnitudes (the relaxed argmax / max of Alg. 1).

    ``p_i = softmax(r_i / temperature)`` over the last axis; returns the expected disparity
    ``Σ p_i d_i`` and the soft confidence ``Σ p_i r_i``. ``temperature`` broadcasts against
    ``magnitude[..., :1]`` (a scalar, or per pixel for a relative temperature).
    """
    p = jax.nn.softmax(magnitude / temperature, axis=-1)
    return jnp.sum(p * disparities, axis=-1), jnp.sum(p * magnitude, axis=-1)


def top_candidates(
    conf: Float[Array, "N W"], k: int, min_conf: Float[ArrayLike, ""]
) -> tuple[Int[Array, "N k"], Array, Array]:
    """The ``k`` strongest candidates per EPI (decreasing confidence).

    Returns:
        ``(index (N, k) int32, valid (N, k) bool, n_overflow (N,) int32)`` where ``n_overflow``
        counts candidates above ``min_conf`` that did not fit.
    """
    k = min(k, conf.shape[1])
    vals, idx = lax.top_k(conf, k)
    valid = vals > min_conf
    total = jnp.sum(conf > min_conf, axis=1)
    return idx.astype(jnp.int32), valid, (total - jnp.sum(valid, axis=1)).astype(jnp.int32)
