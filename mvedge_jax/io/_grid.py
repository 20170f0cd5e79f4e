"""Generic view grids: ``RR_CC.png``, ``view_RR_CC.png``, ``<name>_RR_CC.png``,
``<name>_NNN_RR_CC.png`` (0- or 1-based, or a sub-grid such as rows 09–11)."""

from __future__ import annotations

import os

from ..lightfield import LightField
from ._layout import VIEW_GRID, detect_layout


def read_view_grid(
    folder: str | os.PathLike,
    *,
    views: int | tuple[int, int] | None = None,
    scale: float | None = None,
    transpose: bool | None = None,
) -> LightField:
    """Read a folder of views named ``[prefix_][NNN_]RR_CC.<ext>``.

    The grid spans the smallest to the largest index found in each direction (so 0-based,
    1-based and offset sub-grids all work); absent views inside it are ``False`` in
    ``view_mask``. A running index ``NNN`` (one per file) is ignored. Since exporters do not
    agree on which index comes first, the parallax between the centre view and views along
    each file index is measured (`check_parallax_axes`) and the indices are swapped when the
    first one clearly moves the camera horizontally; ``transpose`` forces either choice.
    No ground truth is read; ``disparity_range`` is None.

    Args:
        folder: the folder with the views.
        views: optional central angular crop ``(U', V')`` (an int means square).
        scale: optional spatial scale in (0, 1] (``cv2.INTER_AREA``).
        transpose: None = decide from the parallax; True/False = swap/keep the file indices.

    Returns:
        A `LightField` (no ground truth).

    Raises:
        FileNotFoundError: folder or centre view missing.
        ValueError: no ``RR_CC`` views, several file families, duplicate views, views of
            different sizes, an incomplete cross-hair or fewer than 3 views in a direction.
    """
    from ._load import assemble, orient

    info = detect_layout(folder)
    if info.layout != VIEW_GRID:
        raise ValueError(f"{info.folder} is not a generic view grid (detected {info.layout})")
    return assemble(orient(info, transpose), views=views, scale=scale)[0]
