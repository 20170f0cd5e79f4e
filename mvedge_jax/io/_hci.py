"""HCI 4D light field benchmark folders (``input_CamNNN.png``, ``parameters.cfg``, PFM GT)."""

from __future__ import annotations

import os

from ..lightfield import LightField
from ._layout import HCI4D, detect_layout


def read_hci4d(
    folder: str | os.PathLike,
    *,
    views: int | tuple[int, int] | None = None,
    scale: float | None = None,
) -> LightField:
    """Read an HCI 4D benchmark scene.

    Views ``input_Cam{k:03d}.png`` with ``k = num_cams_x * row + col`` (9×9 unless
    ``parameters.cfg`` says otherwise); missing views (partial grids such as ``dino_star33``)
    are zero and ``False`` in ``view_mask``. Ground truth: ``gt_disp_lowres.pfm`` (centre
    view) and any ``gt_disp_lowres_Cam{k:03d}.pfm`` (PFM rows are bottom-to-top; flipped on
    reading); its sign follows SPEC §0 as is. ``disparity_range`` = ``[meta] disp_min,
    disp_max`` of ``parameters.cfg``.

    Args:
        folder: scene folder.
        views: optional central angular crop ``(U', V')`` (an int means square).
        scale: optional spatial scale in (0, 1] (``cv2.INTER_AREA``; GT scaled by it too).

    Returns:
        A `LightField` with ``views`` ``(U, V, H, W, 3)`` float32.

    Raises:
        FileNotFoundError: if the folder or its centre view is missing.
        ValueError: not an HCI 4D folder; views of different sizes; an incomplete cross-hair;
            corrupt PFM; NaN/Inf in the ground truth.

    References:
        Honauer, Johannsen, Kondermann, Goldluecke, "A dataset and evaluation methodology
        for depth estimation on 4D light fields", ACCV 2016.
    """
    from ._load import assemble

    info = detect_layout(folder)
    if info.layout != HCI4D:
        raise ValueError(f"{info.folder} is not an HCI 4D folder (detected {info.layout})")
    return assemble(info, views=views, scale=scale)[0]
