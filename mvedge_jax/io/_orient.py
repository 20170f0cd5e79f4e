"""Which file index of a view grid moves the camera horizontally? (measured from parallax)

File names ``RR_CC`` do not always mean (row, column): some exporters write the horizontal
aperture index first. SPEC §0 needs rows = vertical camera motion, so for generic view grids
the loader measures the parallax between the centre view and views along the centre file row
and file column (dense optical flow) and swaps the two indices when the evidence is clear.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from ._images import read_rgb, resize_area
from ._layout import LayoutInfo

#: Longest image side used for the flow estimate (speed; the ratio test is scale-free).
_MAX_SIDE = 320
#: Swap only when the swapped axes explain this many times more motion, in both directions.
_RATIO = 3.0
#: The file order counts as confirmed when it explains this many times more motion.
_KEEP_RATIO = 1.5
#: ... and the motion is at least this large (pixels per view step at the analysis scale).
_MIN_FLOW = 0.05


@dataclasses.dataclass(frozen=True)
class ParallaxCheck:
    """Mean absolute parallax (pixels per view step, full resolution) along each image axis.

    Attributes:
        along_rows: for views in the centre file row: (mean |flow x|, mean |flow y|).
        along_cols: for views in the centre file column: (mean |flow x|, mean |flow y|).
        swap: True when the file's first index clearly moves the camera horizontally.
        decided: False when the parallax is too small or inconsistent to tell.
    """

    along_rows: tuple[float, float]
    along_cols: tuple[float, float]
    swap: bool
    decided: bool

    def describe(self) -> str:
        (rx, ry), (cx, cy) = self.along_rows, self.along_cols
        verdict = (
            "file indices are (col, row): swapped"
            if self.swap
            else ("file indices are (row, col)" if self.decided else "undecided: file order kept")
        )
        return (
            f"parallax check: along file rows |dx|={rx:.3f} |dy|={ry:.3f}, along file cols "
            f"|dx|={cx:.3f} |dy|={cy:.3f} px/view -> {verdict}"
        )


def _grey(path: str) -> tuple[np.ndarray, float]:
    rgb = read_rgb(path)
    s = min(1.0, _MAX_SIDE / max(rgb.shape[:2]))
    if s < 1.0:
        rgb = resize_area(rgb, (max(8, round(rgb.shape[0] * s)), max(8, round(rgb.shape[1] * s))))
    g = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    return np.round(g * 255.0).astype(np.uint8), s


def _mean_abs_flow(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    flow = cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 3, 15, 3, 5, 1.2, 0)
    return float(np.abs(flow[..., 0]).mean()), float(np.abs(flow[..., 1]).mean())


def check_parallax_axes(info: LayoutInfo, *, max_step: int = 3) -> ParallaxCheck:
    """Measure which file index moves the camera horizontally.

    Compares the centre view with the views ``±k`` steps along the centre file row and file
    column (``k = min(max_step, half the grid)``), using Farnebäck optical flow on grey images
    downscaled to at most 320 px. In a correctly ordered grid, moving along a row gives
    horizontal flow and moving along a column vertical flow.

    Args:
        info: a layout from `detect_layout` (file order, not yet swapped).
        max_step: largest angular distance (views) used; far Lytro views are dark and distorted.

    Returns:
        A `ParallaxCheck`; ``swap`` is True only if both directions agree by a factor of 3.

    Raises:
        FileNotFoundError, ValueError: if a view cannot be read.
    """
    U, V = info.grid
    rc, cc = info.centre
    centre, s = _grey(info.files[(rc, cc)])
    sums = {"row": np.zeros(2), "col": np.zeros(2)}
    counts = {"row": 0, "col": 0}
    for axis, n in (("row", V), ("col", U)):
        k = max(1, min(max_step, n // 2))
        for sign in (1, -1):
            pos = (rc, cc + sign * k) if axis == "row" else (rc + sign * k, cc)
            if pos not in info.files:
                continue
            other, _ = _grey(info.files[pos])
            if other.shape != centre.shape:
                continue  # reported properly when the views are read
            try:
                fx, fy = _mean_abs_flow(centre, other)
            except cv2.error:  # e.g. images too small for the flow pyramid: stay undecided
                continue
            sums[axis] += np.array([fx, fy]) / (k * s)
            counts[axis] += 1
    along_rows = tuple(float(v) for v in sums["row"] / max(counts["row"], 1))
    along_cols = tuple(float(v) for v in sums["col"] / max(counts["col"], 1))
    (rx, ry), (cx, cy) = along_rows, along_cols
    if not counts["row"] or not counts["col"]:
        return ParallaxCheck(along_rows, along_cols, swap=False, decided=False)
    swap = ry > _RATIO * rx and cx > _RATIO * cy and min(ry, cx) * s > _MIN_FLOW
    keep = rx > _KEEP_RATIO * ry and cy > _KEEP_RATIO * cx and min(rx, cy) * s > _MIN_FLOW
    return ParallaxCheck(along_rows, along_cols, swap=swap, decided=swap or keep)


def transpose_layout(info: LayoutInfo) -> LayoutInfo:
    """Swap the roles of the two file indices (grid rows become columns)."""
    return info.with_(
        grid=(info.grid[1], info.grid[0]),
        files={(c, r): p for (r, c), p in info.files.items()},
        gt_files={(c, r): p for (r, c), p in info.gt_files.items()},
        gt_mask_files={(c, r): p for (r, c), p in info.gt_mask_files.items()},
        row_labels=info.col_labels,
        col_labels=info.row_labels,
        transposed=not info.transposed,
    )
