"""Files of the main job: disparity maps, figures, EPIs and ``metrics.json``."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .. import viz
from ..edges import HORIZONTAL, VERTICAL, EdgeSet, render_overlay
from ..io import OutputWriter
from ..lightfield import LightField
from ..metrics import depth_metrics, view_consistency
from ._driver import Result


def epi_overlay(views: np.ndarray, edges: EdgeSet, direction: str, index: int) -> np.ndarray:
    """An EPI of the cross-hair with the detected multi-view edge lines drawn over it.

    Args:
        views: ``(U, V, H, W, 3)`` light field in [0, 1].
        edges: the edge set (lines drawn from their intercepts, coloured by disparity).
        direction: ``"horizontal"`` (EPI of pixel row ``index`` in the centre row of views)
            or ``"vertical"`` (pixel column ``index`` in the centre column).
        index: the pixel row or column.

    Returns:
        ``(A * 8, S, 3)`` uint8 RGB (angular axis stretched 8×).

    Raises:
        ValueError: on an unknown direction.
    """
    if direction not in ("horizontal", "vertical"):
        raise ValueError(f"direction must be 'horizontal' or 'vertical'; got {direction!r}")
    views = np.asarray(views)
    rc, cc = views.shape[0] // 2, views.shape[1] // 2
    if direction == "horizontal":
        epi = views[rc, :, index]  # (V, W, 3)
        sel = np.asarray(edges.valid) & (np.asarray(edges.direction) == HORIZONTAL)
        sel &= np.round(np.asarray(edges.y)).astype(int) == index
    else:
        epi = views[:, cc, :, index]  # (U, H, 3)
        sel = np.asarray(edges.valid) & (np.asarray(edges.direction) == VERTICAL)
        sel &= np.round(np.asarray(edges.x)).astype(int) == index
    inter = np.asarray(edges.intercepts)[sel]
    d = np.asarray(edges.disparity)[sel]
    lo, hi = (np.percentile(d, 2), np.percentile(d, 98)) if d.size else (0.0, 1.0)
    colours = viz.colorize_disparity(d[None, :], vmin=lo, vmax=hi, cmap="plasma")[0]
    # intercepts are the positions on the first and last angular rows
    return viz.epi_with_lines(epi, inter[:, 0], inter[:, 1], colours)


def quality_metrics(lf: LightField, disparity: np.ndarray) -> dict:
    """The quality metrics of ``metrics.json`` for a ``(U, V, H, W)`` disparity of ``lf``.

    Returns:
        ``view_consistency`` (eqs 6.9–6.10) always; with ground truth of the centre view
        ``mse_x100``, ``badpix_*``, ``q25_x100`` (`depth_metrics`), and with ground truth in
        more than one view ``all_views`` (their mean over those views, plus
        ``worst_view_mse_x100``).
    """
    disp = np.asarray(disparity, np.float32)
    mask = np.asarray(lf.view_mask)
    U, V = disp.shape[:2]
    rc, cc = lf.centre_index
    metrics: dict = {
        "view_consistency": float(view_consistency(jnp.asarray(disp), view_mask=jnp.asarray(mask)))
    }
    if lf.gt_disparity is not None:
        gt = np.asarray(lf.gt_disparity)
        gtm = np.asarray(lf.gt_mask)
        if gtm[rc, cc].any():
            metrics.update(depth_metrics(disp[rc, cc], gt[rc, cc], gtm[rc, cc]))
        with_gt = [(r, c) for r in range(U) for c in range(V) if gtm[r, c].any() and mask[r, c]]
        if len(with_gt) > 1:
            per_view = [depth_metrics(disp[r, c], gt[r, c], gtm[r, c]) for r, c in with_gt]
            metrics["all_views"] = {
                k: float(np.mean([m[k] for m in per_view])) for k in per_view[0]
            }
            metrics["all_views"]["worst_view_mse_x100"] = float(
                max(m["mse_x100"] for m in per_view)
            )
    return metrics


def result_diagnostics(result: Result) -> dict:
    """``warnings`` (always a list) and ``solver`` (status per stage) of a `Result`."""
    diag = dict(result.diagnostics)
    diag["warnings"] = list(diag.get("warnings", []))
    return diag


def write_outputs(
    writer: OutputWriter,
    lf: LightField,
    result: Result,
    *,
    seconds_total: float,
    initial: Result | None = None,
    optimize_info: dict | None = None,
) -> dict:
    """Write the main job's files into ``writer`` and return the metrics it wrote.

    Files: ``disparity/view_RR_CC.pfm`` per view, ``disparity.npz`` (all views + edge set),
    ``centre_disparity.png``, ``mosaic.png``, ``edges_overlay.png``, ``epi_horizontal.png``,
    ``epi_vertical.png``, and with ground truth ``error_map.png``, ``badpix_0.07.png``;
    ``metrics.json`` always. After `optimize_disparity` (``initial`` given) also
    ``centre_disparity_initial.png`` (the Ch. 6 centre map, same colour scale) and
    ``centre_disparity_initial`` in ``disparity.npz``.

    Args:
        writer: the `OutputWriter` of the output folder.
        lf: the light field.
        result: the final `Result` (optimised when ``initial`` is given).
        seconds_total: wall seconds of the whole run.
        initial: the Ch. 6 `Result` before `optimize_disparity`, or ``None``.
        optimize_info: the ``info`` of `optimize_disparity`, or ``None``.

    Returns:
        The metrics: ``seconds_total``, ``compile_seconds``, ``seconds_per_stage``,
        ``view_consistency``, ``n_views``, ``n_edge_points``, ``n_dropped_points``,
        ``warnings`` and ``solver`` (`result_diagnostics`), and with
        ground truth of the centre view ``mse_x100``, ``badpix_0.01/0.03/0.07``,
        ``q25_x100`` (+ ``all_views``: the mean over every view with ground truth). With
        ``initial``: ``initial``, the same quality metrics (`quality_metrics`) of the Ch. 6
        result. With ``optimize_info``: ``optimize_seconds``, ``propagate_seconds``,
        ``loss_history``, ``optimize_points``, ``optimize_steps``, ``optimize_overflow``,
        ``optimize_selected_fraction`` and ``optimize_solver_iterations_max``.
    """
    disp = np.asarray(result.disparity, np.float32)
    views = np.asarray(lf.views)
    mask = np.asarray(lf.view_mask)
    U, V, H, W = disp.shape
    rc, cc = lf.centre_index
    for r in range(U):
        for c in range(V):
            if mask[r, c]:
                writer.pfm(f"disparity/view_{r:02d}_{c:02d}.pfm", disp[r, c])
    e = result.edges
    extra = {}
    if initial is not None:
        extra["centre_disparity_initial"] = np.asarray(initial.disparity[rc, cc], np.float32)
    writer.npz(
        "disparity.npz",
        disparity=disp,
        view_mask=mask,
        edge_x=np.asarray(e.x),
        edge_y=np.asarray(e.y),
        edge_disparity=np.asarray(e.disparity),
        edge_confidence=np.asarray(e.confidence),
        edge_direction=np.asarray(e.direction),
        edge_valid=np.asarray(e.valid),
        **extra,
    )
    present = disp[mask]
    lo, hi = np.percentile(present, 1), np.percentile(present, 99)
    writer.png("centre_disparity.png", viz.colorize_disparity(disp[rc, cc], vmin=lo, vmax=hi))
    if initial is not None:
        writer.png(
            "centre_disparity_initial.png",
            viz.colorize_disparity(extra["centre_disparity_initial"], vmin=lo, vmax=hi),
        )
    tiles = np.stack(
        [
            np.stack([viz.colorize_disparity(disp[r, c], vmin=lo, vmax=hi) for c in range(V)])
            for r in range(U)
        ]
    )
    tiles[~mask] = 0
    writer.png("mosaic.png", viz.mosaic(tiles))
    writer.png("edges_overlay.png", render_overlay(e, views[rc, cc]))
    writer.png("epi_horizontal.png", epi_overlay(views, e, "horizontal", H // 2))
    writer.png("epi_vertical.png", epi_overlay(views, e, "vertical", W // 2))

    metrics: dict = {
        "scene": lf.name,
        "seconds_total": float(seconds_total),
        "compile_seconds": float(result.compile_seconds),
        "seconds_per_stage": {k: float(v) for k, v in result.seconds_per_stage.items()},
        "n_views": int(mask.sum()),
        "n_edge_points": int(np.asarray(e.valid).sum()),
        "n_dropped_points": int(np.asarray(e.n_dropped)),
    }
    metrics.update(quality_metrics(lf, disp))
    metrics.update(result_diagnostics(result))
    if lf.gt_disparity is not None:
        gt = np.asarray(lf.gt_disparity)
        gtm = np.asarray(lf.gt_mask)
        if gtm[rc, cc].any():
            writer.png("error_map.png", viz.error_map(disp[rc, cc], gt[rc, cc], mask=gtm[rc, cc]))
            writer.png(
                "badpix_0.07.png", viz.badpix_map(disp[rc, cc], gt[rc, cc], mask=gtm[rc, cc])
            )
    if initial is not None:
        metrics["initial"] = quality_metrics(lf, np.asarray(initial.disparity, np.float32))
    if optimize_info is not None:
        info = optimize_info
        metrics["optimize_seconds"] = float(info["optimize_seconds"])
        metrics["propagate_seconds"] = float(info.get("propagate_seconds", 0.0))
        metrics["loss_history"] = [float(v) for v in info["loss_history"]]
        metrics["optimize_points"] = int(info.get("n_points", 0))
        metrics["optimize_steps"] = len(metrics["loss_history"])
        metrics["optimize_overflow"] = int(info.get("overflow", 0))
        if "selected_fraction" in info:
            metrics["optimize_selected_fraction"] = float(info["selected_fraction"])
        its = info.get("solver_iterations") or [0]
        metrics["optimize_solver_iterations_max"] = int(max(its))
    writer.json("metrics.json", metrics)
    return metrics
