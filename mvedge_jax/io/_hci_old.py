"""Old HCI light-field benchmark (Wanner et al. 2013) as re-packaged with ``lf/RR_CC.png``,
``attributes.dat``, ``depth.bin`` and ``mask.png``."""

from __future__ import annotations

import os

import numpy as np

from ..lightfield import LightField
from ._layout import HCI_OLD, detect_layout


def depth_to_disparity(
    depth: np.ndarray, *, dH: float, focal_length: float, shift: float
) -> np.ndarray:
    """Convert old-HCI depth to disparity in pixels per view step.

    ``disparity = dH * focal_length / depth - shift`` (the constants of ``attributes.dat``;
    for stillLife ``614.4 * 9.375 / depth - 288``). With ``focal_length == 0`` the values
    already are disparities and are returned unchanged. The sign matches SPEC §0 (checked
    by warping the views of stillLife with it: larger disparity = nearer).

    Args:
        depth: depth map (any shape), in the benchmark's depth units.
        dH, focal_length, shift: ``dH``, ``focalLength`` and ``shift`` from ``attributes.dat``.

    Returns:
        float32 disparity, same shape; non-positive depths give ``inf``/negative-infinite
        values, which callers must reject or mask.
    """
    depth = np.asarray(depth, dtype=np.float64)
    if focal_length == 0:
        return depth.astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        disp = dH * focal_length / np.where(depth > 0, depth, np.nan) - shift
    disp[depth == 0] = np.inf
    return disp.astype(np.float32)


def read_hci_old_depth(path: str | os.PathLike, size: tuple[int, int]) -> np.ndarray:
    """Read an old-HCI ``depth.bin``: raw little-endian float32 in raster order.

    Args:
        path: the ``depth.bin`` file.
        size: ``(H, W)`` = ``(yRes, xRes)`` from ``attributes.dat``.

    Returns:
        ``(H, W)`` float32 depth (or disparity when ``focalLength`` is 0).

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if the file size is not ``4 * H * W`` bytes.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"depth file not found: {path}")
    H, W = size
    nbytes = os.path.getsize(path)
    if nbytes != 4 * H * W:
        raise ValueError(
            f"{path} has {nbytes} bytes; expected {4 * H * W} (float32 {H}x{W} from "
            "attributes.dat): truncated or wrong resolution"
        )
    return np.fromfile(path, dtype="<f4").reshape(H, W)


def read_hci_old(
    folder: str | os.PathLike,
    *,
    views: int | tuple[int, int] | None = None,
    scale: float | None = None,
) -> LightField:
    """Read an old HCI benchmark scene (``lf/RR_CC.png`` + ``attributes.dat``).

    Views ``lf/RR_CC.png`` (row top→bottom, column left→right). Ground truth ``depth.bin``
    (centre view) is converted with `depth_to_disparity` using the constants of
    ``attributes.dat``; ``mask.png`` (non-zero = valid), if present, gives ``gt_mask``.
    ``disparity_range`` is ``(min_disp, max_disp)`` of ``attributes.dat``.

    Args:
        folder: the scene folder (or its ``lf`` sub-folder).
        views: optional central angular crop ``(U', V')`` (an int means square).
        scale: optional spatial scale in (0, 1] (``cv2.INTER_AREA``; GT scaled by it too).

    Returns:
        A `LightField` with GT for the centre view.

    Raises:
        FileNotFoundError: folder, centre view or files missing.
        ValueError: not an old-HCI folder, or inconsistent/corrupt/non-finite data.

    References:
        Wanner, Meister, Goldluecke, "Datasets and benchmarks for densely sampled 4D light
        fields", VMV 2013.
    """
    from ._load import assemble

    info = detect_layout(folder)
    if info.layout != HCI_OLD:
        raise ValueError(f"{info.folder} is not an old HCI folder (detected {info.layout})")
    return assemble(info, views=views, scale=scale)[0]
