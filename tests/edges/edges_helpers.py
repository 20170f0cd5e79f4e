"""Synthetic EPIs and light fields with known disparities for the edge tests (helpers)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from mvedge_jax.lightfield import LightField


def step_epi(
    positions, signs, d: float, h: int, W: int, colour=(0.6, 0.3, 0.2), sigma: float = 1.0
) -> np.ndarray:
    """``(h, W, 3)`` EPI of step edges blurred by a Gaussian of ``sigma`` px (box-antialiased
    when ``sigma == 0``): edge ``k`` is at centre-row column ``positions[k]`` and traces
    ``x(u) = p_k - (u - h//2) d``; ``signs[k]`` = ±1 step direction."""
    from scipy.special import erf

    x = np.arange(W, dtype=np.float64)[None, :]
    a = (np.arange(h) - h // 2)[:, None]
    v = np.full((h, W), 0.2)
    for p, s in zip(positions, signs, strict=True):
        t = x - (p - a * d)
        prof = np.clip(t + 0.5, 0.0, 1.0) if sigma == 0 else 0.5 * (1 + erf(t / (sigma * 2**0.5)))
        v = v + s * prof * 0.5
    return (v[..., None] * np.asarray(colour)[None, None]).astype(np.float32)


def texture_1d(seed: int, n: int = 12, fmax: float = 0.2):
    """A band-limited random 1-D texture ``t(x) -> (..., 3)`` in about [0.1, 0.9]."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.02, fmax, (n, 3))
    ph = rng.uniform(0, 2 * np.pi, (n, 3))
    amp = rng.uniform(0.5, 1.0, (n, 3)) / n

    def t(x):
        x = np.asarray(x, np.float64)[..., None, None]
        return 0.5 + np.sum(amp * np.sin(2 * np.pi * f * x + ph), axis=-2)

    return t


def plane_light_field(d: float, *, U=9, H=48, W=64, seed=0) -> LightField:
    """Views of a fronto-parallel plane at disparity ``d`` textured with ``A(x) + B(y)`` (two
    band-limited 1-D textures): ``view[r, c](x', y') = centre(x' + dc d, y' + dr d)``."""
    A, B = texture_1d(seed), texture_1d(seed + 1)
    views = np.zeros((U, U, H, W, 3), np.float32)
    xs, ys = np.arange(W), np.arange(H)
    for r in range(U):
        for c in range(U):
            dr, dc = r - U // 2, c - U // 2
            views[r, c] = 0.5 * (A(xs + dc * d)[None, :] + B(ys + dr * d)[:, None])
    views = np.clip(views, 0, 1)
    gt = np.full((U, U, H, W), d, np.float32)
    return LightField(
        views=jnp.asarray(views),
        view_mask=jnp.ones((U, U), bool),
        gt_disparity=jnp.asarray(gt),
        gt_mask=jnp.ones((U, U, H, W), bool),
        name="plane",
        disparity_range=(d - 0.5, d + 0.5),
    )
