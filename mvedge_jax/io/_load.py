"""One entry point for every layout: detect, orient, crop, read in parallel, scale, check."""

from __future__ import annotations

import os
import warnings

import cv2
import jax
import jax.numpy as jnp
import numpy as np

from ..lightfield import LightField
from ._hci_old import depth_to_disparity, read_hci_old_depth
from ._images import _read_views, aligned_zeros, resize_area
from ._layout import VIEW_GRID, LayoutInfo, Position, detect_layout
from ._orient import check_parallax_axes, transpose_layout
from ._pfm import read_pfm

#: Smallest view size, in pixels in each direction after ``scale``, that the loader accepts.
#: Edge detection blurs with a 7-pixel kernel and the reconstruction diffuses over
#: neighbourhoods of about that size; views smaller than 16x16 px leave too few pixels
#: for a meaningful disparity map (3x3-px views gave an all-zero map).
MIN_VIEW_SIZE = 16


#: Ground truth may exceed the metadata disparity range by this much (px/view) unwarned: the
#: filter bank extends the range by ``EdgeConfig.filter.d_margin`` (0.25) anyway.
_RANGE_SLACK = 0.25


class DisparityRangeWarning(UserWarning):
    """The disparity range in a scene's metadata looks wrong (the message says which range
    is used instead)."""


def _normalise_views(views) -> tuple[int, int] | None:
    if views is None:
        return None
    if isinstance(views, (int, np.integer)) and not isinstance(views, bool):
        views = (int(views), int(views))
    try:
        u, v = views
        u, v = int(u), int(v)
        ok = (u, v) == tuple(views)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"views must be an int or a pair (U, V) of ints; got {views!r}")
    if u < 3 or v < 3:
        raise ValueError(f"views={(u, v)}: a light field needs at least 3 views in each direction")
    return u, v


def _normalise_scale(scale) -> float | None:
    if scale is None:
        return None
    try:
        s = float(scale)
    except (TypeError, ValueError):
        raise ValueError(f"scale must be a number in (0, 1]; got {scale!r}") from None
    if not (0.0 < s <= 1.0):
        raise ValueError(f"scale must be in (0, 1] (spatial downscale factor); got {s}")
    return None if s == 1.0 else s


def crop_window(grid: tuple[int, int], views: tuple[int, int] | None) -> tuple[int, int, int, int]:
    """The central ``views = (U', V')`` block of a ``(U, V)`` grid that keeps the centre view.

    The block starts at ``U // 2 - U' // 2`` (likewise for columns), so the old centre
    ``(U // 2, V // 2)`` becomes the new centre ``(U' // 2, V' // 2)``.

    Returns:
        ``(row0, col0, U', V')``.

    Raises:
        ValueError: if the crop is larger than the grid or smaller than 3.
    """
    U, V = grid
    if views is None:
        return 0, 0, U, V
    u, v = views
    if u > U or v > V:
        raise ValueError(f"views={u}x{v} is larger than the {U}x{V} grid of this light field")
    if u < 3 or v < 3:
        raise ValueError(f"views={u}x{v}: a light field needs at least 3 views in each direction")
    return U // 2 - u // 2, V // 2 - v // 2, u, v


def _check_grid(info: LayoutInfo, window: tuple[int, int, int, int]) -> None:
    U, V = info.grid
    if U < 3 or V < 3:
        raise ValueError(
            f"{info.folder}: a {U}x{V} grid of views ({info.pattern}); a light field needs at "
            "least 3 views in each direction"
        )
    r0, c0, u, v = window
    rc, cc = info.centre
    if (rc, cc) not in info.files:
        raise FileNotFoundError(
            f"centre view missing in {info.folder}: {info.describe_position((rc, cc))} of the "
            f"{U}x{V} grid"
        )
    gaps = [(rc, c) for c in range(c0, c0 + v) if (rc, c) not in info.files]
    gaps += [(r, cc) for r in range(r0, r0 + u) if (r, cc) not in info.files]
    if gaps:
        desc = "; ".join(info.describe_position(p) for p in gaps[:6])
        more = f" and {len(gaps) - 6} more" if len(gaps) > 6 else ""
        raise ValueError(
            f"gap in the central cross-hair of {info.folder} ({U}x{V} grid, {info.pattern}): "
            f"missing {desc}{more}"
        )


def _read_gt(
    info: LayoutInfo, pos: Position, size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth of one view at full resolution: ``(disparity (H, W), valid (H, W))``."""
    path = info.gt_files[pos]
    if info.gt_format == "pfm":
        d = read_pfm(path)
        if d.ndim != 2:
            raise ValueError(f"ground truth {path} has 3 channels; expected a 1-channel PFM (Pf)")
    elif info.gt_format == "hci_old_depth":
        if info.gt_size != tuple(size):
            raise ValueError(
                f"attributes.dat of {info.folder} gives {info.gt_size[0]}x{info.gt_size[1]} "
                f"(yRes x xRes) but the views are {size[0]}x{size[1]}"
            )
        dH, f, shift = info.depth_to_disparity
        d = depth_to_disparity(read_hci_old_depth(path, size), dH=dH, focal_length=f, shift=shift)
    else:  # pragma: no cover - scanners only set the formats above
        raise ValueError(f"unknown ground-truth format {info.gt_format!r}")
    if d.shape != tuple(size):
        raise ValueError(
            f"ground truth {path} is {d.shape[0]}x{d.shape[1]}, the views are "
            f"{size[0]}x{size[1]} (HxW)"
        )
    valid = np.ones(size, bool)
    mpath = info.gt_mask_files.get(pos)
    if mpath is not None:
        m = cv2.imread(mpath, cv2.IMREAD_UNCHANGED)
        if m is None:
            raise ValueError(f"cannot decode ground-truth mask {mpath}")
        if m.ndim == 3:
            m = m.max(axis=2)
        if m.shape != tuple(size):
            raise ValueError(
                f"ground-truth mask {mpath} is {m.shape[0]}x{m.shape[1]}, the views are "
                f"{size[0]}x{size[1]} (HxW)"
            )
        valid = m > 0
    bad = ~np.isfinite(d) & valid
    if bad.any():
        ys, xs = np.nonzero(bad)
        raise ValueError(
            f"ground truth {path} has {int(bad.sum())} NaN/Inf values at valid pixels "
            f"(first at y={ys[0]}, x={xs[0]})"
        )
    d = np.where(valid, d, 0.0).astype(np.float32)
    return d, valid


def _scale_gt(
    d: np.ndarray, valid: np.ndarray, size: tuple[int, int], scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Area-average the valid GT pixels; a pixel stays valid when its whole footprint is."""
    m = valid.astype(np.float32)
    num = resize_area(d * m, size)
    den = resize_area(m, size)
    out = np.where(den > 0, num / np.maximum(den, 1e-12), 0.0) * scale
    return out.astype(np.float32), den >= 1.0 - 1e-4


def orient(info: LayoutInfo, transpose: bool | None = None) -> LayoutInfo:
    """Decide the row/column order of a generic view grid (see `check_parallax_axes`).

    Args:
        info: a layout from `detect_layout`.
        transpose: True/False forces swapping/keeping the file indices; None measures the
            parallax (view grids only; HCI layouts define their order and are left alone).

    Returns:
        The layout, transposed when needed, with a note saying how it was decided.

    Raises:
        ValueError: if ``transpose`` is True for an HCI layout (its naming fixes the order).
    """
    if transpose is None and info.layout != VIEW_GRID:
        return info
    if transpose and info.layout != VIEW_GRID:
        raise ValueError(
            f"transpose applies to view grids only: {info.folder} is {info.layout} "
            f"({info.pattern}), whose file naming fixes the row/column order"
        )
    if transpose is None:
        U, V = info.grid
        if U < 3 or V < 3 or info.centre not in info.files:
            return info  # the grid checks report this properly
        check = check_parallax_axes(info)
        out = transpose_layout(info) if check.swap else info
        return out.with_(notes=(*info.notes, check.describe()))
    if transpose:
        out = transpose_layout(info)
        return out.with_(notes=(*info.notes, "file indices swapped on request (transpose=True)"))
    return info.with_(notes=(*info.notes, "file order kept on request (transpose=False)"))


def assemble(
    info: LayoutInfo,
    *,
    views: int | tuple[int, int] | None = None,
    scale: float | None = None,
) -> tuple[LightField, LayoutInfo]:
    """Read the files a layout names into a `LightField` (crop, parallel read, scale, checks).

    Args:
        info: from `detect_layout` (and `orient`).
        views: optional central angular crop.
        scale: optional spatial scale factor in (0, 1].

    Returns:
        ``(light_field, info)`` with ``info.window``/``info.scale`` filled in.

    Raises:
        FileNotFoundError, ValueError: see `load_light_field`.
    """
    crop = _normalise_views(views)
    s = _normalise_scale(scale)
    U, V = info.grid
    if U < 3 or V < 3:
        _check_grid(info, (0, 0, U, V))
    try:
        window = crop_window(info.grid, crop)
    except ValueError as e:
        raise ValueError(f"{e} ({info.folder})") from None
    _check_grid(info, window)
    r0, c0, u, v = window
    positions = [
        (r, c) for r in range(r0, r0 + u) for c in range(c0, c0 + v) if (r, c) in info.files
    ]
    centre = info.centre
    # Centre first, so that size mismatches are reported against the centre view.
    positions.sort(key=lambda p: p != centre)
    flat, size = _read_views(
        [info.files[p] for p in positions],
        scale=s,
        slots=[(r - r0) * v + (c - c0) for r, c in positions],
        n_slots=u * v,
        min_size=MIN_VIEW_SIZE,
    )
    H, W = flat.shape[1:3]
    arr = flat.reshape(u, v, H, W, 3)
    mask = np.zeros((u, v), bool)
    for r, c in positions:
        mask[r - r0, c - c0] = True
    gt_pos = [p for p in info.gt_files if r0 <= p[0] < r0 + u and c0 <= p[1] < c0 + v]
    gt = gt_mask = None
    if gt_pos:
        gt = aligned_zeros((u, v, H, W), np.float32)
        gt_mask = np.zeros((u, v, H, W), bool)
        for r, c in gt_pos:
            d, ok = _read_gt(info, (r, c), size)
            if s is not None:
                d, ok = _scale_gt(d, ok, (H, W), s)
            gt[r - r0, c - c0], gt_mask[r - r0, c - c0] = d, ok
    drange, range_notes = _checked_range(info, size, (u, v), gt, gt_mask, s or 1.0)
    if drange is not None and s is not None:
        drange = (drange[0] * s, drange[1] * s)
    # device_put wraps the aligned host buffers without a copy on CPU (they are not touched
    # again here); jnp.asarray would copy 255 MB for a 9x9x512x512 light field.
    lf = LightField(
        views=jax.device_put(arr),
        view_mask=jnp.asarray(mask),
        gt_disparity=None if gt is None else jax.device_put(gt),
        gt_mask=None if gt_mask is None else jnp.asarray(gt_mask),
        name=os.path.basename(info.folder.rstrip(os.sep)) or info.folder,
        source=info.folder,
        disparity_range=drange,
    )
    if crop is not None and (u, v) != (U, V):
        info = info.with_(window=window)
    if range_notes:
        info = info.with_(notes=(*info.notes, *range_notes))
    return lf, info.with_(scale=s, image_size=size)


def _checked_range(
    info: LayoutInfo,
    size: tuple[int, int],
    grid: tuple[int, int],
    gt: np.ndarray | None,
    gt_mask: np.ndarray | None,
    gt_scale: float,
) -> tuple[tuple[float, float] | None, list[str]]:
    """The metadata disparity range (full resolution) if plausible, and warnings.

    Implausible: a point at the range's largest ``|d|`` would move by more than the whole
    view between the outermost views of the grid (``|d| (max(U, V) - 1) > max(H, W)``);
    such a range is ignored (the pipeline then uses its configured fallback). A range that
    the ground truth (where present) exceeds by more than `_RANGE_SLACK` (0.25 px/view, the
    default ``EdgeConfig.filter.d_margin``) is kept but warned about. Each warning is issued as a
    `DisparityRangeWarning` and returned.
    """
    drange = info.disparity_range
    if drange is None:
        return None, []
    lo, hi = drange
    notes = []
    bound = max(size) / max(max(grid) - 1, 1)
    if max(abs(lo), abs(hi)) > bound:
        notes.append(
            f"the metadata disparity range [{lo:g}, {hi:g}] px/view of {info.folder} is "
            f"implausible for {grid[0]}x{grid[1]} views of {size[0]}x{size[1]} px (beyond "
            f"±{bound:.3g}: points would leave the views); ignored, the disparity range used "
            "is unknown (the pipeline's EdgeConfig.filter.d_max or d_max_fallback applies)"
        )
        drange = None
    elif gt is not None and gt_mask is not None and gt_mask.any():
        vals = gt[gt_mask] / gt_scale
        g_lo, g_hi = float(vals.min()), float(vals.max())
        if g_lo < lo - _RANGE_SLACK or g_hi > hi + _RANGE_SLACK:
            notes.append(
                f"the metadata disparity range [{lo:g}, {hi:g}] px/view of {info.folder} is "
                f"narrower than its ground truth [{g_lo:.3g}, {g_hi:.3g}]; the range used is "
                f"still [{lo:g}, {hi:g}] (set EdgeConfig.filter.d_max to cover the scene)"
            )
    for note in notes:
        warnings.warn(note, DisparityRangeWarning, stacklevel=3)
    return drange, notes


def load_light_field_with_info(
    path: str | os.PathLike,
    *,
    views: int | tuple[int, int] | None = None,
    scale: float | None = None,
    transpose: bool | None = None,
) -> tuple[LightField, LayoutInfo]:
    """`load_light_field`, also returning the `LayoutInfo` (layout, files, crop, notes)."""
    info = orient(detect_layout(path), transpose)
    return assemble(info, views=views, scale=scale)


def load_light_field(
    path: str | os.PathLike,
    *,
    views: int | tuple[int, int] | None = None,
    scale: float | None = None,
    transpose: bool | None = None,
) -> LightField:
    """Load a light field from a folder of any supported layout (auto-detected).

    Layouts (see `detect_layout`): HCI 4D (``input_CamNNN.png``, ``parameters.cfg``,
    ``gt_disp_lowres[_CamNNN].pfm``; partial grids get a ``view_mask``), old HCI
    (``lf/RR_CC.png``, ``attributes.dat``, ``depth.bin`` → disparity, ``mask.png``), and view
    grids ``[prefix_][NNN_]RR_CC.png`` with any first index. For view grids the parallax
    decides which file index is the row (some exporters write the column first); pass
    ``transpose`` to override. The result follows SPEC §0 (``centre(x, y) ≈
    view[r, c](x - dc d, y - dr d)``, larger disparity nearer).

    Args:
        path: the scene folder. Nothing is ever written into it.
        views: optional central angular crop ``(U', V')`` (an int means square), e.g. ``7``
            for the central 7×7 of a Lytro grid. The centre view stays the centre view.
        scale: optional spatial downscale factor in (0, 1]: views are resized with
            ``cv2.INTER_AREA`` to ``round(H * scale) × round(W * scale)``; ground-truth
            disparity (pixels) and ``disparity_range`` are multiplied by ``scale``; a GT
            pixel stays valid only when every source pixel under it was valid. The result
            must be at least `MIN_VIEW_SIZE` (16) pixels in each direction.
        transpose: view grids only: None = decide from the parallax, True/False = force
            (True on an HCI layout is an error).

    Only regular files are read (a named pipe among the views is an error, not a hang).
    A metadata disparity range that cannot be right (points would leave the views) is
    ignored, and one narrower than the ground truth is kept; both issue a
    `DisparityRangeWarning` and a note in the `LayoutInfo`.

    Returns:
        A `LightField`: ``views (U, V, H, W, 3)`` float32 RGB in [0, 1], ``view_mask (U, V)``,
        ``gt_disparity``/``gt_mask`` ``(U, V, H, W)`` where GT exists (else None), ``name`` =
        folder name, ``source`` = absolute folder, ``disparity_range`` from the metadata.

    Raises:
        FileNotFoundError: the folder, the centre view or a named file is missing.
        NotADirectoryError: ``path`` is a file.
        ValueError: no recognised layout; two files for one view (``input_Cam40.png`` and
            ``input_Cam040.png``); views of different sizes; grey views among colour views;
            views (after ``scale``) smaller than `MIN_VIEW_SIZE`; a view that is not a
            regular file; a gap in the central cross-hair; fewer than 3 views in a
            direction; a crop larger than the grid; a bad ``scale``; ``transpose=True`` on an
            HCI layout; corrupt/truncated images, PFM or ``depth.bin``; NaN/Inf ground
            truth; metadata that contradicts the files.
    """
    return load_light_field_with_info(path, views=views, scale=scale, transpose=transpose)[0]
