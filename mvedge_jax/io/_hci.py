"""HCI 4D light field benchmark folders (``input_CamNNN.png``, ``parameters.cfg``, PFM GT)."""

from __future__ import annotations

import configparser
import os

import cv2
import jax.numpy as jnp
import numpy as np

from ..lightfield import LightField
from ._pfm import read_pfm


def _read_rgb(path: str) -> np.ndarray:
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"cannot decode image: {path}")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = img[..., :3][..., ::-1]  # BGR(A) → RGB
    scale = 65535.0 if img.dtype == np.uint16 else 255.0
    return np.ascontiguousarray(img, dtype=np.float32) / scale


def read_hci4d(folder: str | os.PathLike, grid: int = 9) -> LightField:
    """Read an HCI 4D benchmark scene.

    Views ``input_Cam{k:03d}.png`` with ``k = grid * row + col``; missing views (partial
    grids such as ``dino_star33``) are zero and flagged in ``view_mask``. Ground truth:
    ``gt_disp_lowres.pfm`` (centre view) and any ``gt_disp_lowres_Cam{k:03d}.pfm``.

    Args:
        folder: scene folder.
        grid: angular grid size (9 for the benchmark).

    Returns:
        A `LightField` with ``views`` ``(grid, grid, H, W, 3)`` float32.

    Raises:
        FileNotFoundError: if the folder or its centre view is missing.
        ValueError: on views of different sizes, non-finite data or an incomplete cross-hair.
    """
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"light field folder not found: {folder}")
    centre = (grid // 2) * grid + grid // 2
    centre_path = os.path.join(folder, f"input_Cam{centre:03d}.png")
    if not os.path.isfile(centre_path):
        raise FileNotFoundError(f"centre view missing: {centre_path}")
    first = _read_rgb(centre_path)
    H, W, _ = first.shape
    views = np.zeros((grid, grid, H, W, 3), np.float32)
    mask = np.zeros((grid, grid), bool)
    for r in range(grid):
        for c in range(grid):
            p = os.path.join(folder, f"input_Cam{grid * r + c:03d}.png")
            if not os.path.isfile(p):
                continue
            img = _read_rgb(p)
            if img.shape != first.shape:
                raise ValueError(f"view {p} has shape {img.shape}, expected {first.shape}")
            views[r, c] = img
            mask[r, c] = True
    gt = np.zeros((grid, grid, H, W), np.float32)
    gt_mask = np.zeros((grid, grid, H, W), bool)
    have_gt = False
    for r in range(grid):
        for c in range(grid):
            k = grid * r + c
            names = [f"gt_disp_lowres_Cam{k:03d}.pfm"] + (["gt_disp_lowres.pfm"] if k == centre else [])
            for n in names:
                p = os.path.join(folder, n)
                if os.path.isfile(p):
                    d = read_pfm(p)
                    if d.shape != (H, W):
                        raise ValueError(f"ground truth {p} has shape {d.shape}, expected {(H, W)}")
                    if not np.isfinite(d).all():
                        raise ValueError(f"ground truth {p} contains NaN or Inf")
                    gt[r, c], gt_mask[r, c], have_gt = d, True, True
                    break
    drange = None
    cfg_path = os.path.join(folder, "parameters.cfg")
    if os.path.isfile(cfg_path):
        cfg = configparser.ConfigParser()
        cfg.read(cfg_path)
        if cfg.has_option("meta", "disp_min") and cfg.has_option("meta", "disp_max"):
            drange = (cfg.getfloat("meta", "disp_min"), cfg.getfloat("meta", "disp_max"))
    return LightField(
        views=jnp.asarray(views),
        view_mask=jnp.asarray(mask),
        gt_disparity=jnp.asarray(gt) if have_gt else None,
        gt_mask=jnp.asarray(gt_mask) if have_gt else None,
        name=os.path.basename(os.path.normpath(folder)),
        source=os.path.abspath(folder),
        disparity_range=drange,
    )
