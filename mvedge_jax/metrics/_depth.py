"""Disparity accuracy metrics (SPEC §7; thesis Sec. 6.2.3 and 7.2, HCI 4D benchmark)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

BADPIX_THRESHOLDS = (0.01, 0.03, 0.07, 0.1, 0.3, 0.7)


def _prepare(d, gt, mask) -> tuple[Array, Array, Array]:
    d = jnp.asarray(d)
    gt = jnp.asarray(gt)
    if d.shape != gt.shape:
        raise ValueError(f"disparity and ground truth shapes differ: {d.shape} vs {gt.shape}")
    if d.size == 0:
        raise ValueError(f"empty disparity map of shape {d.shape}")
    if mask is None:
        m = jnp.ones(d.shape, bool)
    else:
        m = jnp.asarray(mask)
        if m.shape != d.shape:
            raise ValueError(f"mask shape {m.shape} differs from the disparity shape {d.shape}")
        if m.dtype != jnp.bool_:
            raise ValueError(f"mask must be boolean; got dtype {m.dtype}")
    dtype = jnp.result_type(d.dtype, gt.dtype, jnp.float32)
    return d.astype(dtype), gt.astype(dtype), m


def _masked_mean(x: Array, m: Array) -> Array:
    # NaN when the mask is empty (0/0), like numpy's mean of an empty selection.
    return jnp.sum(jnp.where(m, x, 0.0)) / jnp.sum(m)


def mse_x100(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> Float[Array, ""]:
    """Mean squared disparity error ×100 over the (masked) pixels.

    Args:
        d: estimated disparity, any shape (e.g. ``(H, W)``), pixels per view step.
        gt: ground truth, same shape.
        mask: optional bool, same shape; ``True`` pixels are evaluated.

    Returns:
        ``()`` float: ``100 · mean((d - gt)²)``; NaN for an empty mask.

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Thesis Sec. 6.2.3 (MSE×100); Honauer et al., ACCV 2016.
    """
    d, gt, m = _prepare(d, gt, mask)
    return _mse_x100(d, gt, m)


def badpix(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    t: float | Float[ArrayLike, ""],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> Float[Array, ""]:
    """Percentage of (masked) pixels whose absolute disparity error exceeds ``t``.

    Args:
        d: estimated disparity, any shape.
        gt: ground truth, same shape.
        t: threshold in pixels per view step (0.01, 0.03, 0.07 on HCI 4D); may be traced.
        mask: optional bool, same shape.

    Returns:
        ``()`` float in [0, 100]; NaN for an empty mask.

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Thesis Sec. 7.2 (BadPix); Honauer et al., ACCV 2016.
    """
    d, gt, m = _prepare(d, gt, mask)
    return _badpix(d, gt, jnp.asarray(t, d.dtype), m)


def _masked_quantile(x: Array, m: Array, q: float) -> Array:
    """``np.quantile(x[m], q)`` (linear interpolation) with static shapes."""
    v = jnp.sort(jnp.where(m, x, jnp.inf).ravel())
    n = jnp.sum(m)
    pos = q * (n - 1).astype(x.dtype)
    lo = jnp.clip(jnp.floor(pos).astype(jnp.int32), 0, v.size - 1)
    hi = jnp.clip(lo + 1, 0, jnp.maximum(n - 1, 0))
    frac = pos - lo.astype(x.dtype)
    out = v[lo] + frac * (v[hi] - v[lo])
    return jnp.where(n > 0, out, jnp.nan)


def q25_x100(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> Float[Array, ""]:
    """25th percentile of the absolute disparity error ×100 over the (masked) pixels.

    The percentile interpolates linearly between order statistics (numpy's default).

    Args:
        d: estimated disparity, any shape.
        gt: ground truth, same shape.
        mask: optional bool, same shape.

    Returns:
        ``()`` float; NaN for an empty mask.

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Thesis Sec. 6.2.3 (Q25, reported ×100 in Table 6.1).
    """
    d, gt, m = _prepare(d, gt, mask)
    return _q25_x100(d, gt, m)


@jax.jit
def _mse_x100(d, gt, m):
    return 100.0 * _masked_mean((d - gt) ** 2, m)


@jax.jit
def _badpix(d, gt, t, m):
    return 100.0 * _masked_mean((jnp.abs(d - gt) > t).astype(d.dtype), m)


@jax.jit
def _q25_x100(d, gt, m):
    return 100.0 * _masked_quantile(jnp.abs(d - gt), m, 0.25)


@jax.jit
def _all_metrics(d, gt, m):
    err = jnp.abs(d - gt)
    out = {"mse_x100": 100.0 * _masked_mean(err**2, m)}
    for t in BADPIX_THRESHOLDS:
        out[f"badpix_{t}"] = 100.0 * _masked_mean((err > t).astype(d.dtype), m)
    out["q25_x100"] = 100.0 * _masked_quantile(err, m, 0.25)
    return out


def depth_metrics(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> dict[str, float]:
    """All accuracy metrics of SPEC §7 as plain Python floats (for reports and tables).

    Args:
        d: estimated disparity, any shape (usually the centre view ``(H, W)``).
        gt: ground truth, same shape.
        mask: optional bool, same shape.

    Returns:
        ``{"mse_x100", "badpix_0.01", "badpix_0.03", "badpix_0.07", "badpix_0.1",
        "badpix_0.3", "badpix_0.7", "q25_x100"}`` → float (badpix in percent).

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Thesis Sec. 6.2.3, 7.2; Honauer et al., ACCV 2016.
    """
    d, gt, m = _prepare(d, gt, mask)
    values = _all_metrics(d, gt, m)  # (jit returns the dict with sorted keys)
    keys = ["mse_x100", *(f"badpix_{t}" for t in BADPIX_THRESHOLDS), "q25_x100"]
    return {k: float(values[k]) for k in keys}
