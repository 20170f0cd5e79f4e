"""Depth error up to scale: the least-squares scale-fit protocol of thesis Sec. 7.2.2."""

from __future__ import annotations

import numpy as np
from jaxtyping import ArrayLike, Bool, Float


def scale_fit_metrics(
    depth: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
    *,
    samples: int = 500,
    fits: int = 10,
    seed: int = 0,
) -> dict:
    """MSE and Q25 of a depth map whose scale is unknown (thesis Sec. 7.2.2, Table 7.1).

    Protocol: pixels where the ground truth is finite and positive (and ``mask`` holds) are
    valid; an invalid estimate there (not finite or ``<= 0``) is replaced by the mean ground
    truth depth. Each of ``fits`` fits draws ``samples`` valid pixels at random (without
    replacement; all of them when fewer are valid) and takes the least-squares scale
    ``s = Σ d g / Σ d²`` (no offset) of the estimate ``d`` to the ground truth ``g`` there;
    ``s d`` is then scored on every valid pixel: ``MSE = mean((s d - g)²)`` and ``Q25`` the
    25th percentile of ``|s d - g|`` (linear interpolation). The reported result is the fit
    with the smallest MSE ("the minimum of ten different fits").

    Args:
        depth: estimated depth, any shape (e.g. ``(H, W)``), any positive scale.
        gt: ground-truth depth, same shape (world units).
        mask: optional bool, same shape; ``True`` pixels are evaluated.
        samples: pixels per fit (thesis: 500).
        fits: number of fits (thesis: 10).
        seed: seed of the pixel draws.

    Returns:
        ``{"mse", "q25", "scale"}`` of the best fit (MSE in squared ground-truth units, Q25
        in ground-truth units; the thesis' Table 7.1 appears to list Q25 ×100), and
        ``"fits_mse"``, ``"fits_q25"``, ``"fits_scale"`` (lists over the fits),
        ``"valid_pixels"`` and ``"replaced_pixels"`` (invalid estimates set to the mean
        ground truth). All plain Python numbers.

    Raises:
        ValueError: on mismatched shapes, a non-boolean mask, ``samples``/``fits`` < 1 or no
            valid pixel.

    References:
        Thesis Sec. 7.2.2 ("least squares fit to the ground truth at 500 randomly sampled
        valid depth pixels", "the minimum of ten different fits", invalid pixels assigned
        the mean GT depth).
    """
    d = np.asarray(depth, np.float64)
    g = np.asarray(gt, np.float64)
    if d.shape != g.shape:
        raise ValueError(f"depth and ground truth shapes differ: {d.shape} vs {g.shape}")
    if samples < 1 or fits < 1:
        raise ValueError(f"samples and fits must be >= 1; got {samples} and {fits}")
    valid = np.isfinite(g) & (g > 0)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != d.shape:
            raise ValueError(f"mask shape {m.shape} differs from the depth shape {d.shape}")
        if m.dtype != np.bool_:
            raise ValueError(f"mask must be boolean; got dtype {m.dtype}")
        valid &= m
    n = int(valid.sum())
    if n == 0:
        raise ValueError("no valid ground-truth pixel to evaluate")
    dv, gv = d[valid], g[valid]
    bad = ~(np.isfinite(dv) & (dv > 0))
    dv = np.where(bad, gv.mean(), dv)
    rng = np.random.default_rng(seed)
    k = min(samples, n)
    out_mse, out_q25, out_s = [], [], []
    for _ in range(fits):
        idx = rng.choice(n, size=k, replace=False)
        s = float(np.dot(dv[idx], gv[idx])) / float(np.dot(dv[idx], dv[idx]))  # dv > 0
        err = s * dv - gv
        out_mse.append(float(np.mean(err**2)))
        out_q25.append(float(np.quantile(np.abs(err), 0.25)))
        out_s.append(s)
    best = int(np.argmin(out_mse))
    return {
        "mse": out_mse[best],
        "q25": out_q25[best],
        "scale": out_s[best],
        "fits_mse": out_mse,
        "fits_q25": out_q25,
        "fits_scale": out_s,
        "valid_pixels": n,
        "replaced_pixels": int(bad.sum()),
    }
