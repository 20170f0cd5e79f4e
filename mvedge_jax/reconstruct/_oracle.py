"""An edge model built from ground truth, for ablations and tests of the reconstruction.

`oracle_edges` plays the role of the edge detector (Ch. 4.1) and of the surface-vector stage
(Sec. 4.2–4.3) when the ground-truth disparity of the centre view is known: it answers "how
good is the reconstruction if the edge model is right?".
"""

from __future__ import annotations

import cv2
import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..edges import HORIZONTAL, VERTICAL, EdgeSet
from ..lightfield import rgb_to_lab


class OracleSurface(eqx.Module):
    """Duck-typed stand-in of ``mvedge_jax.surface.SurfaceResult`` (the fields the
    reconstruction reads)."""

    offset: Float[Array, "N 2"]
    step_response: Float[Array, " N"]
    depth_edge_confidence: Float[Array, "H W"]


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    H, W = img.shape
    x = np.clip(x, 0, W - 1)
    y = np.clip(y, 0, H - 1)
    x0 = np.clip(np.floor(x).astype(int), 0, max(W - 2, 0))
    y0 = np.clip(np.floor(y).astype(int), 0, max(H - 2, 0))
    fx, fy = x - x0, y - y0
    x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
    return (
        img[y0, x0] * (1 - fx) * (1 - fy)
        + img[y0, x1] * fx * (1 - fy)
        + img[y1, x0] * (1 - fx) * fy
        + img[y1, x1] * fx * fy
    )


def oracle_edges(
    centre_view: Float[ArrayLike, "H W 3"],
    gt: Float[ArrayLike, "H W"],
    *,
    grid: tuple[int, int] = (9, 9),
    threshold: float = 2.0,
    capacity: int | None = None,
    step_scale: float = 0.2,
    confidence_scale: float = 0.1,
    noise: float = 0.0,
    seed: int = 0,
) -> tuple[EdgeSet, OracleSurface]:
    """Edge points and surface vectors derived from the ground-truth centre disparity.

    Points: pixels whose CIELAB gradient magnitude (colour structure tensor of the Sobel
    derivatives after a Gaussian blur with σ = 1) exceeds ``threshold`` (CIELAB units per
    pixel) and is a local maximum along the gradient direction ``n``. Label: the ground truth
    at the pixel; the surface vector points to the side (``±n``)
    whose ground truth one pixel away is closer to the label (texture edges, with equal
    sides, point along ``+n``).
    ``step_response = tanh(|gt(p + 2n) − gt(p − 2n)| / step_scale)``; the depth-edge
    confidence map is ``tanh(|∇gt| / confidence_scale)`` (Sobel, blurred with σ = 1).
    Direction: horizontal EPI when ``|n_x| >= |n_y|``. Intercepts follow SPEC §0. Optional
    Gaussian label noise (``noise`` px). NumPy; not jittable.

    Args:
        centre_view: ``(H, W, 3)`` RGB in [0, 1].
        gt: ``(H, W)`` ground-truth disparity of the centre view.
        grid: ``(U, V)`` of the light field (for the intercepts).
        threshold: gradient threshold, CIELAB units per pixel.
        capacity: `EdgeSet` capacity (default: the number of points).
        step_scale, confidence_scale: disparity scales of the two tanh normalisations.
        noise: standard deviation of Gaussian noise added to the labels.
        seed: seed of that noise.

    Returns:
        ``(EdgeSet, OracleSurface)``.
    """
    img = np.asarray(centre_view, np.float32)
    gt = np.asarray(gt, np.float32)
    H, W = gt.shape
    lab = np.asarray(rgb_to_lab(jnp.asarray(img)))
    blur = cv2.GaussianBlur(lab, (0, 0), 1.0)
    # Colour structure tensor direction: the dominant gradient orientation.
    jxx = sum(cv2.Sobel(blur[..., c], cv2.CV_32F, 1, 0, ksize=3) ** 2 for c in range(3)) / 64
    jyy = sum(cv2.Sobel(blur[..., c], cv2.CV_32F, 0, 1, ksize=3) ** 2 for c in range(3)) / 64
    jxy = (
        sum(
            cv2.Sobel(blur[..., c], cv2.CV_32F, 1, 0, ksize=3)
            * cv2.Sobel(blur[..., c], cv2.CV_32F, 0, 1, ksize=3)
            for c in range(3)
        )
        / 64
    )
    mag = np.sqrt(np.maximum(0.5 * (jxx + jyy + np.sqrt((jxx - jyy) ** 2 + 4 * jxy**2)), 0))
    theta = 0.5 * np.arctan2(2 * jxy, jxx - jyy)
    nx, ny = np.cos(theta), np.sin(theta)
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    m1 = _bilinear(mag, xs + nx, ys + ny)
    m2 = _bilinear(mag, xs - nx, ys - ny)
    keep = (mag > threshold) & (mag >= m1) & (mag >= m2)
    keep[:1], keep[-1:], keep[:, :1], keep[:, -1:] = False, False, False, False
    py, px = np.nonzero(keep)
    nxp, nyp = nx[py, px], ny[py, px]
    x, y = px.astype(np.float32), py.astype(np.float32)
    fwd = _bilinear(gt, x + nxp, y + nyp)
    bwd = _bilinear(gt, x - nxp, y - nyp)
    label = gt[py, px]
    sign = np.where(np.abs(fwd - label) <= np.abs(bwd - label), 1.0, -1.0).astype(np.float32)
    if noise > 0:
        label = label + np.random.default_rng(seed).normal(0, noise, label.shape)
    step = np.abs(_bilinear(gt, x + 2 * nxp, y + 2 * nyp) - _bilinear(gt, x - 2 * nxp, y - 2 * nyp))
    step_resp = np.tanh(step / step_scale)
    gdx = cv2.Sobel(gt, cv2.CV_32F, 1, 0, ksize=3) / 8
    gdy = cv2.Sobel(gt, cv2.CV_32F, 0, 1, ksize=3) / 8
    conf = cv2.GaussianBlur(np.tanh(np.hypot(gdx, gdy) / confidence_scale), (0, 0), 1.0)
    n = len(x)
    N = n if capacity is None else int(capacity)
    n = min(n, N)
    U, V = grid
    direction = np.where(np.abs(nxp) >= np.abs(nyp), HORIZONTAL, VERTICAL).astype(np.int32)
    pos = np.where(direction == HORIZONTAL, x, y)
    half = np.where(direction == HORIZONTAL, V // 2, U // 2)
    last = np.where(direction == HORIZONTAL, V - 1, U - 1)
    icpt = np.stack([pos + half * label, pos - (last - half) * label], axis=1)

    def pad(a, fill=0):
        a = np.asarray(a)[:n]
        out = np.full((N,) + a.shape[1:], fill, a.dtype)
        out[:n] = a
        return jnp.asarray(out)

    edges = EdgeSet(
        x=pad(x.astype(np.float32)),
        y=pad(y.astype(np.float32)),
        disparity=pad(label.astype(np.float32)),
        confidence=pad(mag[py, px].astype(np.float32)),
        visible=pad(np.ones(len(x), bool), False),
        lab=pad(lab[py, px].astype(np.float32)),
        direction=pad(direction),
        intercepts=pad(icpt.astype(np.float32)),
        valid=pad(np.ones(len(x), bool), False),
        n_dropped=jnp.asarray(max(len(x) - N, 0), jnp.int32),
    )
    surface = OracleSurface(
        offset=pad(np.stack([sign * nxp, sign * nyp], 1).astype(np.float32)),
        step_response=pad(step_resp.astype(np.float32)),
        depth_edge_confidence=jnp.asarray(conf.astype(np.float32)),
    )
    return edges, surface
