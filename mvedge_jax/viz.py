"""Visualisations: colour-mapped arrays and Matplotlib figures with colour bars.

One colour map per quantity, shared by every output: `DISPARITY_CMAP` for disparity (maps,
mosaics, edge points, EPI lines), `ERROR_CMAP` for the signed error and `BADPIX_CMAP` for bad
pixels, following the HCI 4D benchmark toolkit (``CMAP_DISP``, ``CMAP_ERROR`` and
``CMAP_ABS_ERROR``, signed error ``GT - estimate`` clipped at ``±0.2``).

The array functions return uint8 RGB; the figure functions return a Matplotlib `Figure`
(Agg canvas, no pyplot state) and the PNG metadata that `png_bytes` writes into the file's
tEXt chunks (value range, units, colour map, colour-bar box). Nothing here touches files.

References:
    Honauer, Johannsen, Kondermann, Goldluecke, "A dataset and evaluation methodology for
    depth estimation on 4D light fields", ACCV 2016 (the benchmark's error visualisations).
"""

from __future__ import annotations

import io
import math
import textwrap

import cv2
import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.colors import BoundaryNorm, ListedColormap, Normalize
from matplotlib.figure import Figure

DISPARITY_CMAP = "viridis"
"""Colour map of disparity in every output (the HCI toolkit's ``CMAP_DISP``)."""
ERROR_CMAP = "seismic"
"""Diverging colour map of the signed error ``GT - estimate`` (toolkit ``CMAP_ERROR``)."""
BADPIX_CMAP = "RdYlGn_r"
"""Good/bad pixel colour map (toolkit ``CMAP_ABS_ERROR``: good 0.2 → green, bad 1.0 → red)."""
ERROR_LIMIT = 0.2
"""Signed error (pixels per view step) at which the error map saturates (toolkit DMIN/DMAX)."""
DISPARITY_LABEL = "disparity [px per view step]"
ERROR_LABEL = "GT − estimate [px per view step]"
NO_DATA_RGB = (0, 0, 0)
"""Colour of pixels without a value (outside a mask, NaN)."""

_DPI = 100
_MIN_SIDE = 320  # small images are magnified (nearest) to this many pixels on the long side
MAX_SIDE = 2048
"""Large images (mosaics) are shown at most this many pixels on the long side."""


def colorize_disparity(
    disparity: np.ndarray,
    *,
    vmin: float | None = None,
    vmax: float | None = None,
    cmap: str = DISPARITY_CMAP,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Colour-map a disparity image.

    Args:
        disparity: ``(H, W)`` disparity in pixels per view step.
        vmin, vmax: colour range; default the 1st/99th percentiles of the valid pixels.
        cmap: a Matplotlib colour-map name (default `DISPARITY_CMAP`).
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
    vmin, vmax = colour_range(d[ok], vmin, vmax)
    t = np.clip((np.where(ok, d, vmin) - vmin) / (vmax - vmin), 0.0, 1.0)
    rgb = matplotlib.colormaps[cmap](t)[..., :3]
    rgb[~ok] = np.asarray(NO_DATA_RGB) / 255.0
    return (rgb * 255.0 + 0.5).astype(np.uint8)


def colour_range(
    values: np.ndarray, vmin: float | None = None, vmax: float | None = None
) -> tuple[float, float]:
    """A colour range: ``vmin``/``vmax`` where given, else the 1st/99th percentile of ``values``.

    Args:
        values: finite values (any shape); empty gives ``(0, 1)``.
        vmin, vmax: fixed ends, or ``None``.

    Returns:
        ``(vmin, vmax)`` with ``vmax > vmin``.
    """
    vals = np.asarray(values).ravel()
    if vmin is None:
        vmin = float(np.percentile(vals, 1)) if vals.size else 0.0
    if vmax is None:
        vmax = float(np.percentile(vals, 99)) if vals.size else 1.0
    vmin, vmax = float(vmin), float(vmax)
    if not vmax > vmin:
        vmax = vmin + 1e-6
    return vmin, vmax


def error_map(
    disparity: np.ndarray,
    gt: np.ndarray,
    *,
    limit: float = ERROR_LIMIT,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Signed error ``gt - disparity`` in `ERROR_CMAP`, saturating at ``±limit``.

    The HCI toolkit's convention: white = correct, red = estimate too far (too small a
    disparity), blue = too near.

    Args:
        disparity, gt: ``(H, W)`` in pixels per view step.
        limit: error at which the colour saturates (pixels per view step).
        mask: optional ``(H, W)`` bool of valid GT pixels; others are black.

    Returns:
        ``(H, W, 3)`` uint8 RGB.

    Raises:
        ValueError: if the shapes differ or are not 2-D.
    """
    e = _signed_error(disparity, gt)
    return colorize_disparity(e, vmin=-limit, vmax=limit, cmap=ERROR_CMAP, mask=mask)


def _signed_error(disparity, gt) -> np.ndarray:
    d = np.asarray(disparity, np.float64)
    g = np.asarray(gt, np.float64)
    if d.shape != g.shape or d.ndim != 2:
        raise ValueError(f"disparity and GT must both be (H, W); got {d.shape} and {g.shape}")
    return g - d


def _badpix_colours() -> np.ndarray:
    cm = matplotlib.colormaps[BADPIX_CMAP]
    return np.array([cm(0.2)[:3], cm(1.0)[:3]])  # good, bad (toolkit: 1.0 * bad + 0.2 * good)


def badpix_map(
    disparity: np.ndarray,
    gt: np.ndarray,
    *,
    threshold: float = 0.07,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Bad pixels ``|disparity - gt| > threshold`` in red, good ones in green (HCI toolkit).

    Args:
        disparity, gt: ``(H, W)`` in pixels per view step.
        threshold: BadPix threshold (pixels per view step).
        mask: optional ``(H, W)`` bool of evaluated pixels; others are black.

    Returns:
        ``(H, W, 3)`` uint8 RGB.

    Raises:
        ValueError: if the shapes differ or are not 2-D.
    """
    e = np.abs(_signed_error(disparity, gt))
    ok = np.isfinite(e) if mask is None else np.isfinite(e) & np.asarray(mask, bool)
    rgb = _badpix_colours()[(e > threshold).astype(int)]
    rgb[~ok] = np.asarray(NO_DATA_RGB) / 255.0
    return (rgb * 255.0 + 0.5).astype(np.uint8)


def mosaic(images: np.ndarray, *, gap: int = 2, fill=0) -> np.ndarray:
    """Tile a ``(U, V, H, W[, 3])`` grid of images into one image with ``gap``-pixel gaps.

    Args:
        images: ``(U, V, H, W)`` or ``(U, V, H, W, 3)``.
        gap: gap between tiles in pixels.
        fill: value of the gaps (e.g. NaN for float maps shown as no data).

    Returns:
        ``(U*H + (U-1)*gap, V*W + (V-1)*gap[, 3])``, the dtype of ``images``.

    Raises:
        ValueError: on other shapes.
    """
    a = np.asarray(images)
    if a.ndim not in (4, 5):
        raise ValueError(f"mosaic expects (U, V, H, W[, 3]); got shape {a.shape}")
    U, V, H, W = a.shape[:4]
    out = np.full((U * H + (U - 1) * gap, V * W + (V - 1) * gap) + a.shape[4:], fill, a.dtype)
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

    Raises:
        ValueError: if ``epi`` is not ``(A, S, 3)``.
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


def image_figure(
    image: np.ndarray,
    *,
    title: str,
    cmap: str | matplotlib.colors.Colormap,
    vmin: float,
    vmax: float,
    label: str,
    norm: Normalize | None = None,
    ticks: list[float] | None = None,
    tick_labels: list[str] | None = None,
    axis_labels: tuple[str, str] | None = None,
    extent: tuple[float, float, float, float] | None = None,
    min_height: int = 0,
    lines_xy: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[Figure, dict[str, str]]:
    """An image with a title and a vertical colour bar on its right.

    A 2-D ``image`` is colour-mapped with ``cmap`` over ``[vmin, vmax]`` (NaN shown black);
    an RGB ``image`` is drawn as it is and the colour bar explains its colours (e.g. the EPI
    lines). Small images are magnified (nearest neighbour) to 320 px on the long side, large
    ones reduced to 2048 px.

    Args:
        image: ``(H, W)`` values or ``(H, W, 3)`` uint8 RGB.
        title: figure title.
        cmap: colour map (name or object) of the colour bar (and of a 2-D ``image``).
        vmin, vmax: the colour bar's value range.
        label: colour-bar label with units, e.g. `DISPARITY_LABEL`.
        norm: optional normalisation (default linear ``[vmin, vmax]``).
        ticks, tick_labels: optional colour-bar ticks (default five from vmin to vmax).
        axis_labels: ``(x label, y label)`` to draw axes with ticks (default: no axes).
        extent: optional ``imshow`` extent (data coordinates of the axes).
        min_height: stretch the image to at least this many pixels high (EPIs).
        lines_xy: optional ``(segments (L, 2, 2), values (L,))``: line segments in data
            coordinates (``extent``) drawn over the image, coloured by value with ``cmap``.

    Returns:
        ``(figure, metadata)``: ``metadata`` holds ``vmin``, ``vmax``, ``units`` (the label),
        ``colormap``, ``Title`` and ``colorbar_bbox`` (``"x0 y0 x1 y1"``, pixels of the PNG,
        origin top left) for `png_bytes`.

    Raises:
        ValueError: if ``image`` is not ``(H, W)`` or ``(H, W, 3)``, or ``vmax <= vmin``.
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3) or 0 in img.shape:
        raise ValueError(f"image_figure expects (H, W) or (H, W, 3); got shape {img.shape}")
    if not (math.isfinite(vmin) and math.isfinite(vmax) and vmax > vmin):
        raise ValueError(f"colour range must be finite with vmax > vmin; got [{vmin}, {vmax}]")
    H, W = img.shape[:2]
    zoom = max(1.0, _MIN_SIDE / max(H, W))
    zoom = min(zoom, MAX_SIDE / max(H, W))
    w_px, h_px = max(1, round(W * zoom)), max(1, round(H * zoom), min_height)
    k = max(1.0, math.sqrt(min(w_px, h_px) / 400))  # text and margins grow with big images
    fs = 8 * k
    left, bottom = (round(60 * k), round(42 * k)) if axis_labels else (10, 10)
    cb_gap, cb_w, right = round(10 * k), round(16 * k), round(95 * k)
    char_px = 0.6 * fs * _DPI / 72  # mean width of a character of the title font
    lines = textwrap.wrap(title, max(20, int((w_px + cb_gap + cb_w + right - 10) / char_px)))
    top = round((10 + 13 * len(lines)) * k)
    fig_w = left + w_px + cb_gap + cb_w + right
    fig_h = bottom + h_px + top
    fig = Figure(figsize=(fig_w / _DPI, fig_h / _DPI), dpi=_DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((left / fig_w, bottom / fig_h, w_px / fig_w, h_px / fig_h))
    cax = fig.add_axes(((left + w_px + cb_gap) / fig_w, bottom / fig_h, cb_w / fig_w, h_px / fig_h))
    cm = matplotlib.colormaps[cmap] if isinstance(cmap, str) else cmap
    norm = Normalize(vmin=vmin, vmax=vmax) if norm is None else norm
    interp = "nearest" if zoom >= 1 else "antialiased"
    if img.ndim == 2:
        data = np.ma.masked_invalid(np.asarray(img, np.float64))
        shown = cm.with_extremes(bad=np.asarray(NO_DATA_RGB) / 255.0)
        ax.imshow(data, cmap=shown, norm=norm, interpolation=interp, aspect="auto", extent=extent)
    else:
        ax.imshow(img, interpolation=interp, aspect="auto", extent=extent)
    if lines_xy is not None:
        segs, vals = lines_xy
        ax.add_collection(
            LineCollection(segs, array=np.asarray(vals), cmap=cm, norm=norm, linewidths=1.2 * k)
        )
    if axis_labels:
        ax.set_xlabel(axis_labels[0], fontsize=fs)
        ax.set_ylabel(axis_labels[1], fontsize=fs)
        ax.tick_params(labelsize=fs - 1)
    else:
        ax.set_axis_off()
    fig.text(left / fig_w, 1 - 4 * k / fig_h, "\n".join(lines), fontsize=fs, va="top", ha="left")
    sm = matplotlib.cm.ScalarMappable(norm=norm, cmap=cm)
    cb = fig.colorbar(sm, cax=cax)
    cb.outline.set_linewidth(0)
    cb.set_ticks(_ticks_with_ends(vmin, vmax) if ticks is None else ticks)
    if tick_labels is not None:
        cb.set_ticklabels(tick_labels)
    else:
        cb.ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%.3g"))
    cb.ax.tick_params(labelsize=fs - 1)
    cb.set_label(label, fontsize=fs)
    x0 = left + w_px + cb_gap
    metadata = {
        "Title": title,
        "vmin": f"{vmin:.6g}",
        "vmax": f"{vmax:.6g}",
        "units": label,
        "colormap": cm.name,
        "colorbar_bbox": f"{x0} {top} {x0 + cb_w} {top + h_px}",
    }
    return fig, metadata


def _ticks_with_ends(vmin: float, vmax: float) -> list[float]:
    """Round ticks inside ``[vmin, vmax]`` plus both ends (the value range is always read)."""
    inner = matplotlib.ticker.MaxNLocator(nbins=4).tick_values(vmin, vmax)
    gap = 0.12 * (vmax - vmin)
    inner = [t for t in inner if vmin + gap < t < vmax - gap]
    return [vmin, *inner, vmax]


def png_bytes(fig: Figure, metadata: dict[str, str] | None = None) -> bytes:
    """Render a figure of `image_figure` to PNG bytes with ``metadata`` as tEXt chunks.

    Args:
        fig: the figure.
        metadata: ``{key: text}`` written into the PNG (read back with Pillow's
            ``Image.open(path).text``).

    Returns:
        The PNG file's bytes.
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI, metadata=dict(metadata or {}))
    return buf.getvalue()


def disparity_figure(
    disparity: np.ndarray,
    *,
    title: str,
    vmin: float | None = None,
    vmax: float | None = None,
    mask: np.ndarray | None = None,
) -> tuple[Figure, dict[str, str]]:
    """A disparity map in `DISPARITY_CMAP` with its colour bar (`image_figure`).

    Args:
        disparity: ``(H, W)`` in pixels per view step (NaN: no data, black).
        title: figure title.
        vmin, vmax: colour range (default 1st/99th percentile; values beyond are clipped).
        mask: optional ``(H, W)`` bool; pixels outside it are black.

    Returns:
        ``(figure, metadata)`` as `image_figure`.

    Raises:
        ValueError: if ``disparity`` is not 2-D.
    """
    d = np.array(disparity, np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity_figure expects (H, W); got shape {d.shape}")
    if mask is not None:
        d[~np.asarray(mask, bool)] = np.nan
    vmin, vmax = colour_range(d[np.isfinite(d)], vmin, vmax)
    return image_figure(
        d, title=title, cmap=DISPARITY_CMAP, vmin=vmin, vmax=vmax, label=DISPARITY_LABEL
    )


def error_figure(
    disparity: np.ndarray,
    gt: np.ndarray,
    *,
    title: str,
    limit: float = ERROR_LIMIT,
    mask: np.ndarray | None = None,
) -> tuple[Figure, dict[str, str]]:
    """The signed error ``gt - disparity`` in `ERROR_CMAP`, clipped to ``±limit``.

    HCI toolkit convention: white = correct, red = too far, blue = too near.

    Args:
        disparity, gt: ``(H, W)`` in pixels per view step.
        title: figure title.
        limit: symmetric colour range (pixels per view step).
        mask: optional ``(H, W)`` bool of valid GT pixels; others are black.

    Returns:
        ``(figure, metadata)`` as `image_figure`.

    Raises:
        ValueError: if the shapes differ or are not 2-D.
    """
    e = _signed_error(disparity, gt)
    if mask is not None:
        e[~np.asarray(mask, bool)] = np.nan
    return image_figure(e, title=title, cmap=ERROR_CMAP, vmin=-limit, vmax=limit, label=ERROR_LABEL)


def badpix_figure(
    disparity: np.ndarray,
    gt: np.ndarray,
    *,
    title: str,
    threshold: float = 0.07,
    mask: np.ndarray | None = None,
) -> tuple[Figure, dict[str, str]]:
    """Bad pixels (``|disparity - gt| > threshold``) red, good green, with a two-entry bar.

    Args:
        disparity, gt: ``(H, W)`` in pixels per view step.
        title: figure title.
        threshold: BadPix threshold (pixels per view step).
        mask: optional ``(H, W)`` bool of evaluated pixels; others are black.

    Returns:
        ``(figure, metadata)`` as `image_figure` (``vmin`` 0, ``vmax`` 2 × threshold, plus
        ``threshold``).

    Raises:
        ValueError: if the shapes differ or are not 2-D.
    """
    e = np.abs(_signed_error(disparity, gt))
    bad = np.where(e > threshold, 1.5 * threshold, 0.5 * threshold)
    bad[~np.isfinite(e)] = np.nan
    if mask is not None:
        bad[~np.asarray(mask, bool)] = np.nan
    cmap = ListedColormap(_badpix_colours(), name=BADPIX_CMAP)
    t = float(threshold)
    fig, md = image_figure(
        bad,
        title=title,
        cmap=cmap,
        vmin=0.0,
        vmax=2 * t,
        norm=BoundaryNorm([0.0, t, 2 * t], 2),
        ticks=[0.5 * t, 1.5 * t],
        tick_labels=[f"≤ {t:g}", f"> {t:g}"],
        label="|GT − estimate| [px per view step]",
    )
    md["threshold"] = f"{t:g}"
    return fig, md


def epi_figure(
    epi: np.ndarray,
    top: np.ndarray,
    bottom: np.ndarray,
    disparity: np.ndarray,
    *,
    title: str,
    vmin: float,
    vmax: float,
    axis_labels: tuple[str, str] = ("x [px]", "view"),
) -> tuple[Figure, dict[str, str]]:
    """An EPI with lines drawn over it, coloured by disparity in `DISPARITY_CMAP`.

    The angular axis is stretched (at least 240 px high) and labelled with the view index;
    lines are vector graphics from their position on the first angular row to the last.

    Args:
        epi: ``(A, S, 3)`` RGB in [0, 1] (A views, S pixels).
        top, bottom: ``(L,)`` line positions (pixels along S) on angular rows 0 and A - 1.
        disparity: ``(L,)`` disparity of each line (pixels per view step).
        title: figure title (say which row or column of which views).
        vmin, vmax: colour range of the lines.
        axis_labels: ``(spatial axis, angular axis)`` labels.

    Returns:
        ``(figure, metadata)`` as `image_figure`.

    Raises:
        ValueError: if ``epi`` is not ``(A, S, 3)`` or the line arrays differ in length.
    """
    e = np.asarray(epi, np.float32)
    if e.ndim != 3 or e.shape[-1] != 3:
        raise ValueError(f"epi_figure expects (A, S, 3); got shape {e.shape}")
    top, bottom = np.asarray(top, np.float64), np.asarray(bottom, np.float64)
    d = np.asarray(disparity, np.float64)
    if not top.shape == bottom.shape == d.shape or top.ndim != 1:
        raise ValueError(
            f"top, bottom, disparity must be (L,) each; got {top.shape}, {bottom.shape}, {d.shape}"
        )
    A, S, _ = e.shape
    segs = np.stack(
        [
            np.stack([top, np.zeros_like(top)], -1),
            np.stack([bottom, np.full_like(bottom, A - 1)], -1),
        ],
        axis=1,
    )
    rgb = (np.clip(e, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return image_figure(
        rgb,
        title=title,
        cmap=DISPARITY_CMAP,
        vmin=vmin,
        vmax=vmax,
        label=DISPARITY_LABEL,
        axis_labels=axis_labels,
        extent=(-0.5, S - 0.5, A - 0.5, -0.5),
        min_height=240,
        lines_xy=(segs, d),
    )
