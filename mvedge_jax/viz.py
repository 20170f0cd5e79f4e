"""Visualisations as uint8 RGB arrays (disparity colour maps, error maps, mosaics, EPIs).

Nothing here touches files: `mvedge_jax.io.write_png` writes the arrays.
"""

from __future__ import annotations

import cv2
import matplotlib
import numpy as np


def colorize_disparity(
    disparity: np.ndarray,
    *,
    vmin: float | None = None,
    vmax: float | None = None,
    cmap: str = "viridis",
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Colour-map a disparity image.

    Args:
        disparity: ``(H, W)`` disparity in pixels per view step.
        vmin, vmax: colour range; default the 1st/99th percentiles of the valid pixels.
        cmap: a Matplotlib colour-map name.
        mask: optional ``(H, W)`` bool; pixels outside it (and non-finite ones) are black.

    Returns:
        ``(H, W, 3)`` uint8 RGB.

    Raises:
        ValueError: if ``disparity`` is not 2-D.
    """
    d = np.asarray(disparity, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f"colorize_disparity expects (H, W); got shape {d.shape}")
    ok = np.isfinite(d) if mask is None else (np.isfinite(d) & np.asarray(mask, bool))
    vals = d[ok]
    if vmin is None:
        vmin = float(np.percentile(vals, 1)) if vals.size else 0.0
    if vmax is None:
        vmax = float(np.percentile(vals, 99)) if vals.size else 1.0
    if vmax <= vmin:
        vmax = vmin + 1e-6
    t = np.clip((np.where(ok, d, vmin) - vmin) / (vmax - vmin), 0.0, 1.0)
    rgb = matplotlib.colormaps[cmap](t)[..., :3]
    rgb[~ok] = 0.0
    return (rgb * 255.0 + 0.5).astype(np.uint8)


def error_map(
    disparity: np.ndarray, gt: np.ndarray, *, limit: float = 0.2, mask: np.ndarray | None = None
) -> np.ndarray:
    """Signed disparity error ``disparity - gt`` as a diverging colour map.

    Blue: estimate too far (too small), red: too near; saturates at ``±limit`` pixels.

    Args:
        disparity, gt: ``(H, W)``.
        limit: error (pixels per view step) at which the colour saturates.
        mask: optional ``(H, W)`` bool of valid GT pixels; others are black.

    Returns:
        ``(H, W, 3)`` uint8 RGB.
    """
    e = np.asarray(disparity, np.float64) - np.asarray(gt, np.float64)
    return colorize_disparity(e, vmin=-limit, vmax=limit, cmap="RdBu_r", mask=mask)


def badpix_map(
    disparity: np.ndarray,
    gt: np.ndarray,
    *,
    threshold: float = 0.07,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Pixels with ``|disparity - gt| > threshold`` in red over a grey version of the error.

    Returns:
        ``(H, W, 3)`` uint8 RGB.
    """
    e = np.abs(np.asarray(disparity, np.float64) - np.asarray(gt, np.float64))
    grey = (255 * (1.0 - np.clip(e / (4 * threshold), 0, 1))).astype(np.uint8)
    out = np.stack([grey] * 3, axis=-1)
    bad = e > threshold
    if mask is not None:
        bad &= np.asarray(mask, bool)
        out[~np.asarray(mask, bool)] = 0
    out[bad] = (220, 30, 30)
    return out


def mosaic(images: np.ndarray, *, gap: int = 2) -> np.ndarray:
    """Tile a ``(U, V, H, W[, 3])`` grid of images into one image with ``gap`` black pixels."""
    a = np.asarray(images)
    if a.ndim not in (4, 5):
        raise ValueError(f"mosaic expects (U, V, H, W[, 3]); got shape {a.shape}")
    U, V, H, W = a.shape[:4]
    out = np.zeros((U * H + (U - 1) * gap, V * W + (V - 1) * gap) + a.shape[4:], a.dtype)
    for r in range(U):
        for c in range(V):
            out[r * (H + gap) : r * (H + gap) + H, c * (W + gap) : c * (W + gap) + W] = a[r, c]
    return out


def epi_with_lines(
    epi: np.ndarray,
    top: np.ndarray,
    bottom: np.ndarray,
    colours: np.ndarray | None = None,
    *,
    row_scale: int = 8,
) -> np.ndarray:
    """Draw EPI lines over an EPI, stretched vertically so the angular axis is visible.

    Args:
        epi: ``(A, S, 3)`` float in [0, 1] (A angular rows, S spatial samples).
        top, bottom: ``(L,)`` line positions along S on angular row 0 and row A - 1.
        colours: optional ``(L, 3)`` uint8 RGB per line (default red).
        row_scale: vertical stretch factor.

    Returns:
        ``(A * row_scale, S, 3)`` uint8 RGB.
    """
    e = np.asarray(epi, np.float32)
    if e.ndim != 3 or e.shape[-1] != 3:
        raise ValueError(f"epi_with_lines expects (A, S, 3); got shape {e.shape}")
    A, S, _ = e.shape
    img = cv2.resize(
        (np.clip(e, 0, 1) * 255).astype(np.uint8),
        (S, A * row_scale),
        interpolation=cv2.INTER_NEAREST,
    )
    img = np.ascontiguousarray(img)
    top, bottom = np.asarray(top, np.float64), np.asarray(bottom, np.float64)
    y0, y1 = row_scale / 2 - 0.5, (A - 1) * row_scale + row_scale / 2 - 0.5
    shift = 4
    for i in range(top.shape[0]):
        col = (255, 0, 0) if colours is None else tuple(int(v) for v in colours[i])
        p0 = (int(round(top[i] * (1 << shift))), int(round(y0 * (1 << shift))))
        p1 = (int(round(bottom[i] * (1 << shift))), int(round(y1 * (1 << shift))))
        cv2.line(img, p0, p1, col, 1, cv2.LINE_AA, shift)
    return img
