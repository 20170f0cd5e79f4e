"""Files of the main job: disparity maps, figures, EPIs, field formats and ``metrics.json``."""

from __future__ import annotations

import dataclasses
import json
import math
import platform
import time
from collections.abc import Callable

import cv2
import jax
import jax.numpy as jnp
import numpy as np

from .. import viz
from ..edges import HORIZONTAL, VERTICAL, EdgeSet, render_sparse_disparity
from ..io import HciCamera, OutputWriter, depth_to_points, disparity_to_depth, write_ply
from ..lightfield import LightField
from ..metrics import depth_metrics, view_consistency
from ._driver import Result

#: Files of `write_outputs` that a run always writes (with ground truth also ``error_map.png``
#: and ``badpix_0.07.png``).
FIGURES = (
    "centre_disparity.png",
    "mosaic.png",
    "edges_overlay.png",
    "epi_horizontal.png",
    "epi_vertical.png",
)

_EPI_ROW_SCALE = 8


def _epi_lines(views: np.ndarray, edges: EdgeSet, direction: str, index: int):
    if direction not in ("horizontal", "vertical"):
        raise ValueError(f"direction must be 'horizontal' or 'vertical'; got {direction!r}")
    views = np.asarray(views)
    U, V, H, W = views.shape[:4]
    limit = H if direction == "horizontal" else W
    if not 0 <= index < limit:
        raise ValueError(f"{direction} EPI index {index} outside [0, {limit})")
    rc, cc = U // 2, V // 2
    if direction == "horizontal":
        epi = views[rc, :, index]  # (V, W, 3)
        sel = np.asarray(edges.valid) & (np.asarray(edges.direction) == HORIZONTAL)
        sel &= np.round(np.asarray(edges.y)).astype(int) == index
    else:
        epi = views[:, cc, :, index]  # (U, H, 3)
        sel = np.asarray(edges.valid) & (np.asarray(edges.direction) == VERTICAL)
        sel &= np.round(np.asarray(edges.x)).astype(int) == index
    inter = np.asarray(edges.intercepts)[sel]
    return epi, inter, np.asarray(edges.disparity)[sel]


def epi_overlay(
    views: np.ndarray,
    edges: EdgeSet,
    direction: str,
    index: int,
    *,
    vmin: float | None = None,
    vmax: float | None = None,
) -> np.ndarray:
    """An EPI of the cross-hair with the detected multi-view edge lines drawn over it.

    Args:
        views: ``(U, V, H, W, 3)`` light field in [0, 1].
        edges: the edge set (lines drawn from their intercepts, coloured by disparity in
            `viz.DISPARITY_CMAP`).
        direction: ``"horizontal"`` (EPI of pixel row ``index`` in the centre row of views)
            or ``"vertical"`` (pixel column ``index`` in the centre column).
        index: the pixel row or column.
        vmin, vmax: disparity range of the line colours (default: 2nd/98th percentile of
            the lines drawn).

    Returns:
        ``(A * 8, S, 3)`` uint8 RGB (angular axis stretched 8×).

    Raises:
        ValueError: on an unknown direction or an index outside the image.

    References:
        Thesis Ch. 4.1 (EPI lines of multi-view edges).
    """
    epi, inter, d = _epi_lines(views, edges, direction, index)
    if vmin is None or vmax is None:
        lo, hi = (np.percentile(d, 2), np.percentile(d, 98)) if d.size else (0.0, 1.0)
        vmin = lo if vmin is None else vmin
        vmax = hi if vmax is None else vmax
    colours = viz.colorize_disparity(d[None, :], vmin=vmin, vmax=vmax)[0]
    # intercepts are the positions on the first and last angular rows
    return viz.epi_with_lines(epi, inter[:, 0], inter[:, 1], colours, row_scale=_EPI_ROW_SCALE)


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


def config_to_json(config) -> object:
    """A config (nested `eqx.Module`s / dataclasses) as plain JSON values (for
    ``metrics.json``; `config_to_dict` gives the TOML form).

    Walks the dataclass fields generically: modules become dicts (with ``"_type"``, the class
    name), arrays become floats or lists, tuples lists, non-finite floats the strings
    ``"inf"``, ``"-inf"``, ``"nan"``, and anything else its ``repr``.

    Args:
        config: e.g. a `PipelineConfig`.

    Returns:
        A JSON-serialisable value (``json.dumps(..., allow_nan=False)`` accepts it).
    """
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        out: dict = {"_type": type(config).__name__}
        for f in dataclasses.fields(config):
            out[f.name] = config_to_json(getattr(config, f.name))
        return out
    if isinstance(config, dict):
        return {str(k): config_to_json(v) for k, v in config.items()}
    if isinstance(config, (list, tuple)):
        return [config_to_json(v) for v in config]
    if isinstance(config, (bool, np.bool_)) or config is None or isinstance(config, str):
        return bool(config) if isinstance(config, np.bool_) else config
    if isinstance(config, (int, np.integer)):
        return int(config)
    if isinstance(config, (float, np.floating)):
        return _finite(float(str(config)))
    if isinstance(config, (jax.Array, np.ndarray)):
        a = np.asarray(config)
        if a.dtype.kind == "f":  # shortest decimal of each value (0.15, not 0.15000000596)
            a = np.array([float(str(v)) for v in a.ravel()]).reshape(a.shape)
        if a.dtype.kind in "biuf":
            return config_to_json(a.item() if a.ndim == 0 else a.tolist())
    return repr(config)


def _finite(x: float):
    if math.isfinite(x):
        return x
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")


def strict_json(obj) -> object:
    """``obj`` with every non-finite float replaced by ``None`` (JSON ``null``).

    Returns:
        A value that ``json.dumps(..., allow_nan=False)`` accepts.
    """
    if isinstance(obj, dict):
        return {str(k): strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def device_info() -> dict:
    """The JAX back end and device a run uses (for ``metrics.json`` and the CLI).

    Returns:
        ``backend`` (e.g. ``"cpu"``, ``"gpu"``), ``device`` (its kind, e.g. ``"cpu"`` or
        ``"NVIDIA H100 80GB HBM3"``), ``device_count``, ``jax_version``, ``python``, and
        ``deterministic``: whether repeated runs give the same bits (always on the CPU; on a
        GPU only with `mvedge_jax.request_deterministic_gpu`).
    """
    from .._determinism import deterministic_gpu_requested

    devs = jax.devices()
    backend = jax.default_backend()
    return {
        "backend": backend,
        "device": str(getattr(devs[0], "device_kind", devs[0].platform)),
        "device_count": len(devs),
        "jax_version": jax.__version__,
        "python": platform.python_version(),
        "deterministic": backend == "cpu" or deterministic_gpu_requested(),
    }


def provenance(
    lf: LightField,
    config,
    *,
    seed: int,
    scale: float | None = None,
    views: tuple[int, int] | None = None,
    window: tuple[int, int, int, int] | None = None,
) -> dict:
    """What a reader of ``metrics.json`` needs to reproduce a run.

    Args:
        lf: the light field as loaded.
        config: the resolved configuration (`PipelineConfig`).
        seed: seed of the PRNG key of the randomised refinement.
        scale: spatial scale applied on loading (``None``: full resolution).
        views: the ``--views`` request ``(U, V)``, if any.
        window: the angular crop ``(row0, col0, U, V)`` of the file's grid, if any.

    Returns:
        ``input`` (folder or ``"synthetic"``), ``scene``, ``views`` (grid, number present,
        the mask as rows of ``#``/``.``, request and crop), ``scale`` and ``units`` (errors
        are in pixels of the scaled views), ``config`` (`config_to_json`), ``seed``,
        ``mvedge_jax_version`` and `device_info`.
    """
    from .. import __version__

    mask = np.asarray(lf.view_mask)
    U, V = lf.grid
    H, W = lf.size
    s = 1.0 if scale is None else float(scale)
    out = {
        "input": lf.source if lf.source is not None else "synthetic (mvedge_jax.synthetic)",
        "scene": lf.name,
        "views": {
            "grid": [U, V],
            "present": int(mask.sum()),
            "mask": ["".join("#" if m else "." for m in row) for row in mask],
            "requested": list(views) if views is not None else None,
            "window_of_file_grid": list(window) if window is not None else None,
            "centre": list(lf.centre_index),
        },
        "size": [H, W],
        "scale": s,
        "units": (
            "disparity and its errors in pixels per view step of the loaded views"
            + (
                f" (scaled by {s:g}: multiply by {1 / s:g} for full-resolution pixels)"
                if s != 1.0
                else ""
            )
        ),
        "config": config_to_json(config),
        "seed": int(seed),
        "mvedge_jax_version": __version__,
    }
    out.update(device_info())
    return out


def _mosaic_tiles(disp: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, int]:
    """The views of the mosaic, reduced by an integer factor (area average) so that the
    mosaic fits `viz.MAX_SIDE`; missing views are NaN."""
    U, V, H, W = disp.shape
    k = max(1, math.ceil(max(U * H, V * W) / (viz.MAX_SIDE - 2 * (max(U, V) - 1))))
    h, w = max(1, H // k), max(1, W // k)
    tiles = np.full((U, V, h, w), np.nan, np.float32)
    for r in range(U):
        for c in range(V):
            if mask[r, c]:
                tiles[r, c] = cv2.resize(disp[r, c], (w, h), interpolation=cv2.INTER_AREA)
    return tiles, k


def _save(writer: OutputWriter, name: str, fig_md) -> None:
    fig, md = fig_md
    writer.path(name).write_bytes(viz.png_bytes(fig, md))


def _edges_overlay(edges: EdgeSet, centre: np.ndarray, lo: float, hi: float) -> np.ndarray:
    H, W = centre.shape[:2]
    disp, mask = render_sparse_disparity(edges, (H, W))
    disp, mask = np.asarray(disp), np.asarray(mask)
    grey = (0.35 * centre.mean(axis=2, keepdims=True).repeat(3, axis=2) * 255 + 0.5).astype(
        np.uint8
    )
    return np.where(mask[..., None], viz.colorize_disparity(disp, vmin=lo, vmax=hi), grey)


def edge_epi_figure(
    views: np.ndarray,
    edges: EdgeSet,
    direction: str,
    index: int,
    *,
    vmin: float,
    vmax: float,
):
    """The figure of `epi_overlay`: the EPI with its edge lines as vectors, a title naming
    the pixel row/column and the views, axes in pixels and views, and a disparity colour bar.

    Args:
        views: ``(U, V, H, W, 3)`` light field in [0, 1].
        edges: the edge set.
        direction: ``"horizontal"`` or ``"vertical"`` (as `epi_overlay`).
        index: the pixel row (horizontal) or column (vertical).
        vmin, vmax: disparity range of the line colours.

    Returns:
        ``(figure, metadata)`` of `viz.epi_figure` (write it with `viz.png_bytes`).

    Raises:
        ValueError: on an unknown direction or an index outside the image.

    References:
        Thesis Ch. 4.1 (EPI lines of multi-view edges).
    """
    views = np.asarray(views)
    lo, hi = vmin, vmax
    epi, inter, d = _epi_lines(views, edges, direction, index)
    U, V = views.shape[:2]
    if direction == "horizontal":
        title = (
            f"horizontal EPI of pixel row y = {index} through the centre row of views "
            f"(u = {U // 2}); lines: detected edges, coloured by disparity"
        )
        labels = ("x [px]", "view column v")
    else:
        title = (
            f"vertical EPI of pixel column x = {index} through the centre column of views "
            f"(v = {V // 2}); lines: detected edges, coloured by disparity"
        )
        labels = ("y [px]", "view row u")
    return viz.epi_figure(
        epi, inter[:, 0], inter[:, 1], d, title=title, vmin=lo, vmax=hi, axis_labels=labels
    )


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
    provenance: dict | None = None,
    hci: bool = False,
    camera: HciCamera | None = None,
    depth: bool = False,
    ply: bool = False,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Write the main job's files into ``writer`` and return the metrics it wrote.

    Files: ``disparity/view_RR_CC.pfm`` per view, ``disparity.npz`` (all views + edge set),
    figures with colour bars (`viz.image_figure`; value range and units also in each PNG's
    metadata): ``centre_disparity.png``, ``mosaic.png`` (all views), ``edges_overlay.png``
    (edge points by disparity over the centre view), ``epi_horizontal.png`` and
    ``epi_vertical.png`` (EPIs of the centre row/column with the detected lines), and with
    ground truth ``error_map.png`` (GT − estimate) and ``badpix_0.07.png``; ``metrics.json``
    always (strict JSON). After `optimize_disparity` (``initial`` given) also
    ``centre_disparity_initial.png`` (the Ch. 6 centre map, same colour range) and
    ``centre_disparity_initial`` in ``disparity.npz``. Every disparity figure shares one
    colour range: the 1st–99th percentile of all views.

    Field formats: ``hci`` writes the HCI 4D benchmark submission layout
    ``disp_maps/<scene>.pfm`` (centre view) and ``runtimes/<scene>.txt`` (seconds after
    compilation); ``depth`` writes ``depth/view_RR_CC.pfm`` (metres, `disparity_to_depth`)
    and ``centre_depth.png``; ``ply`` writes ``centre_view.ply``, the centre view's coloured
    point cloud (millimetres, `depth_to_points`). ``depth`` and ``ply`` need ``camera``.

    Args:
        writer: the `OutputWriter` of the output folder.
        lf: the light field.
        result: the final `Result` (optimised when ``initial`` is given).
        seconds_total: wall seconds of the whole run.
        initial: the Ch. 6 `Result` before `optimize_disparity`, or ``None``.
        optimize_info: the ``info`` of `optimize_disparity`, or ``None``.
        provenance: `provenance` of the run, stored as ``metrics["provenance"]``.
        hci: write the HCI benchmark layout.
        camera: the scene's `HciCamera` (``io.read_hci_camera``), for ``depth`` and ``ply``.
        depth: write metric depth.
        ply: write the centre view's point cloud.
        progress: optional callback with the name of each file group as it is written.

    Returns:
        The metrics: ``scene``, ``seconds_total``, ``compile_seconds``,
        ``seconds_per_stage``, ``seconds_write``, ``view_consistency``, ``n_views``,
        ``n_edge_points``, ``n_dropped_points``, and with ground truth of the centre view
        ``mse_x100``, ``badpix_0.01/0.03/0.07``, ``q25_x100`` (+ ``all_views``: the mean over
        every view with ground truth). With ``initial``: ``initial``, the same quality
        metrics (`quality_metrics`) of the Ch. 6 result. With ``optimize_info``:
        ``optimize_seconds``, ``propagate_seconds``, ``loss_history``, ``optimize_points``,
        ``optimize_steps``, ``optimize_overflow``, ``optimize_selected_fraction`` and
        ``optimize_solver_iterations_max``. With ``provenance``: ``provenance``. With
        ``ply``: ``ply_points``. Non-finite values are written as ``null``.

    Raises:
        ValueError: if ``depth`` or ``ply`` is asked for without ``camera``.
    """
    if (depth or ply) and camera is None:
        raise ValueError(
            f"{lf.name}: --depth/--ply need the camera of an HCI 4D scene (parameters.cfg); "
            "none is known for this input"
        )
    t_write = time.perf_counter()
    step = progress or (lambda name: None)
    disp = np.asarray(result.disparity, np.float32)
    views = np.asarray(lf.views)
    mask = np.asarray(lf.view_mask)
    U, V, H, W = disp.shape
    rc, cc = lf.centre_index
    step("disparity maps")
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
    step("figures")
    present = disp[mask]
    lo, hi = viz.colour_range(present[np.isfinite(present)], None, None)
    name = lf.name
    _save(
        writer,
        "centre_disparity.png",
        viz.disparity_figure(
            disp[rc, cc], title=f"{name}: disparity, centre view ({rc}, {cc})", vmin=lo, vmax=hi
        ),
    )
    if initial is not None:
        _save(
            writer,
            "centre_disparity_initial.png",
            viz.disparity_figure(
                extra["centre_disparity_initial"],
                title=f"{name}: disparity before optimisation (Ch. 6), centre view",
                vmin=lo,
                vmax=hi,
            ),
        )
    tiles, reduced = _mosaic_tiles(disp, mask)

    def disparity_coloured(image: np.ndarray, title: str):
        return viz.image_figure(
            image,
            title=title,
            cmap=viz.DISPARITY_CMAP,
            vmin=lo,
            vmax=hi,
            label=viz.DISPARITY_LABEL,
        )

    _save(
        writer,
        "mosaic.png",
        disparity_coloured(
            viz.mosaic(tiles, fill=np.nan),
            f"{name}: disparity of all {U}x{V} views (row u down, column v across)"
            + (f", each reduced {reduced}x" if reduced > 1 else ""),
        ),
    )
    _save(
        writer,
        "edges_overlay.png",
        disparity_coloured(
            _edges_overlay(e, views[rc, cc], lo, hi),
            f"{name}: {int(np.asarray(e.valid).sum())} edge points by disparity",
        ),
    )
    _save(
        writer,
        "epi_horizontal.png",
        edge_epi_figure(views, e, "horizontal", H // 2, vmin=lo, vmax=hi),
    )
    _save(
        writer, "epi_vertical.png", edge_epi_figure(views, e, "vertical", W // 2, vmin=lo, vmax=hi)
    )

    metrics: dict = {
        "scene": name,
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
            _save(
                writer,
                "error_map.png",
                viz.error_figure(
                    disp[rc, cc],
                    gt[rc, cc],
                    mask=gtm[rc, cc],
                    title=f"{name}: error, centre view (white correct, red too far, blue too near)",
                ),
            )
            _save(
                writer,
                "badpix_0.07.png",
                viz.badpix_figure(
                    disp[rc, cc],
                    gt[rc, cc],
                    mask=gtm[rc, cc],
                    title=f"{name}: BadPix(0.07) {metrics['badpix_0.07']:.2f}% (red), centre view",
                ),
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
    if hci:
        step("HCI layout")
        runtime = sum(metrics["seconds_per_stage"].values())
        runtime += metrics.get("optimize_seconds", 0.0) + metrics.get("propagate_seconds", 0.0)
        writer.pfm(f"disp_maps/{name}.pfm", disp[rc, cc])
        writer.path(f"runtimes/{name}.txt").write_text(f"{runtime:.6f}\n")
        metrics["hci_runtime_seconds"] = runtime
    if depth:
        step("depth")
        for r in range(U):
            for c in range(V):
                if mask[r, c]:
                    writer.pfm(
                        f"depth/view_{r:02d}_{c:02d}.pfm", disparity_to_depth(disp[r, c], camera)
                    )
        z = disparity_to_depth(disp[rc, cc], camera)
        finite = z[np.isfinite(z)]
        zlo, zhi = viz.colour_range(finite, None, None)
        _save(
            writer,
            "centre_depth.png",
            viz.image_figure(
                z,
                title=f"{name}: depth, centre view ({rc}, {cc})",
                cmap=viz.DISPARITY_CMAP + "_r",
                vmin=zlo,
                vmax=zhi,
                label="depth [m]",
            ),
        )
    if ply:
        step("point cloud")
        pts = depth_to_points(disparity_to_depth(disp[rc, cc], camera), camera)
        metrics["ply_points"] = write_ply(writer.path("centre_view.ply"), pts, views[rc, cc])
    metrics["seconds_write"] = time.perf_counter() - t_write
    if provenance is not None:
        metrics["provenance"] = provenance
    metrics = strict_json(metrics)
    json.dumps(metrics, allow_nan=False)  # raises on anything a strict reader would refuse
    step("metrics.json")
    writer.json("metrics.json", metrics)
    return metrics
