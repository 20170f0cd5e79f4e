"""End-to-end entry points: light field → edges → surface vectors → disparity for every view.

The stages (thesis Ch. 4.1 → 4.2–4.3 → 6) are separately jitted pure functions of arrays. The
`estimate_disparity` driver compiles each stage ahead of time (so compile time is reported apart
from run time), runs it, and records the seconds per stage. `estimate_disparity_arrays` is the
same chain as one jittable function, for sweeps and gradients.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import viz
from .edges import HORIZONTAL, VERTICAL, EdgeConfig, EdgeSet, render_overlay
from .edges._pipeline import _detect_arrays, resolve_d_max
from .io import OutputWriter
from .lightfield import LightField
from .metrics import depth_metrics, view_consistency
from .reconstruct import ReconstructConfig, Reconstruction, reconstruct
from .surface import SurfaceConfig, SurfaceResult, surface_vectors

STAGES = ("edges", "surface", "reconstruct")


class PipelineConfig(eqx.Module):
    """Configuration of the whole Ch. 6 pipeline: one frozen config per stage."""

    edges: EdgeConfig = EdgeConfig()
    surface: SurfaceConfig = SurfaceConfig()
    reconstruct: ReconstructConfig = ReconstructConfig()


class Result(eqx.Module):
    """Output of `estimate_disparity`.

    Attributes:
        disparity: ``(U, V, H, W)`` float32 disparity for every view, pixels per view step.
        edges: the multi-view edge set (thesis Ch. 4.1).
        surface: surface vectors, λ_e and depth-edge confidence (Ch. 4.2–4.3).
        reconstruction: intermediate maps of the smooth 4D reconstruction (Ch. 6).
        seconds_per_stage: wall seconds per stage after compilation.
        compile_seconds: total ahead-of-time compilation seconds.
    """

    disparity: Float[Array, "U V H W"]
    edges: EdgeSet
    surface: SurfaceResult
    reconstruction: Reconstruction
    seconds_per_stage: dict[str, float] = eqx.field(static=True)
    compile_seconds: float = eqx.field(static=True)


def _stage_fns(config: PipelineConfig, disparity_range: tuple[float, float] | None):
    d_max = resolve_d_max(config.edges, disparity_range)

    def edges_fn(views, key):
        rc, cc = views.shape[0] // 2, views.shape[1] // 2
        return _detect_arrays(views[rc], views[:, cc], config.edges, d_max, key)

    def surface_fn(edges, centre):
        return surface_vectors(edges, centre, config.surface)

    def reconstruct_fn(views, edges, surface):
        return reconstruct(views, edges, surface, config.reconstruct)

    return edges_fn, surface_fn, reconstruct_fn


def estimate_disparity_arrays(
    views: Float[Array, "U V H W 3"],
    view_mask: Array,
    config: PipelineConfig,
    key: Array,
    disparity_range: tuple[float, float] | None = None,
) -> tuple[Float[Array, "U V H W"], EdgeSet, SurfaceResult, Reconstruction]:
    """The whole chain as one function of arrays (jit it with ``disparity_range`` static).

    Args:
        views: ``(U, V, H, W, 3)`` float32 RGB in [0, 1].
        view_mask: ``(U, V)`` bool, views present.
        config: the pipeline configuration.
        key: PRNG key for the randomised refinement (thesis eq 4.5).
        disparity_range: ``(d_min, d_max)`` of the scene if known (pixels per view step).

    Returns:
        ``(disparity (U, V, H, W), edges, surface, reconstruction)``.

    References:
        Thesis Ch. 4.1 (edges), 4.2–4.3 (surface vectors), 6.1 (reconstruction).
    """
    edges_fn, surface_fn, reconstruct_fn = _stage_fns(config, disparity_range)
    rc, cc = views.shape[0] // 2, views.shape[1] // 2
    del view_mask  # only the cross-hair is read; it is complete by construction
    edges = edges_fn(views, key)
    surface = surface_fn(edges, views[rc, cc])
    rec = reconstruct_fn(views, edges, surface)
    return rec.disparity, edges, surface, rec


def estimate_disparity(
    lf: LightField,
    config: PipelineConfig | None = None,
    *,
    key: Array | None = None,
    progress: Callable[[str, str], None] | None = None,
) -> Result:
    """Disparity for every view of a light field (the main job, thesis Ch. 6).

    Each stage is compiled ahead of time and then run, so that ``compile_seconds`` and
    ``seconds_per_stage`` separate compilation from work (the persistent compilation cache,
    when enabled, makes later compilations cheap).

    Args:
        lf: the light field; its cross-hair must be complete.
        config: pipeline configuration (defaults: thesis parameters).
        key: PRNG key for the randomised line refinement; default ``jax.random.key(0)``.
        progress: optional callback ``progress(stage, event)`` with event ``"compile"``,
            ``"run"`` or ``"done"``, for progress bars.

    Returns:
        A `Result` with ``disparity`` of shape ``(U, V, H, W)``.

    Raises:
        ValueError: if the views contain NaN/Inf.
    """
    config = PipelineConfig() if config is None else config
    key = jax.random.key(0) if key is None else key
    if not bool(jnp.isfinite(lf.views).all()):
        raise ValueError(f"light field {lf.name!r} contains NaN or Inf pixel values")
    edges_fn, surface_fn, reconstruct_fn = _stage_fns(config, lf.disparity_range)
    centre = lf.centre_view
    seconds: dict[str, float] = {}
    compile_total = 0.0

    def run(stage, fn, *args):
        nonlocal compile_total
        if progress:
            progress(stage, "compile")
        t0 = time.perf_counter()
        compiled = jax.jit(fn).lower(*args).compile()
        compile_total += time.perf_counter() - t0
        if progress:
            progress(stage, "run")
        t0 = time.perf_counter()
        out = jax.block_until_ready(compiled(*args))
        seconds[stage] = time.perf_counter() - t0
        if progress:
            progress(stage, "done")
        return out

    edges = run("edges", edges_fn, lf.views, key)
    surface = run("surface", surface_fn, edges, centre)
    rec = run("reconstruct", reconstruct_fn, lf.views, edges, surface)
    return Result(
        disparity=rec.disparity,
        edges=edges,
        surface=surface,
        reconstruction=rec,
        seconds_per_stage=seconds,
        compile_seconds=compile_total,
    )


def config_from_dict(data: dict) -> PipelineConfig:
    """Build a `PipelineConfig` from ``{"edges": {...}, "surface": {...}, "reconstruct": {...}}``
    (keyword arguments of the stage configs; missing tables keep the defaults).

    Raises:
        ValueError: on an unknown table name.
        TypeError: on an unknown parameter of a stage config.
    """
    unknown = set(data) - {"edges", "surface", "reconstruct"}
    if unknown:
        raise ValueError(
            f"unknown config tables {sorted(unknown)}; use edges, surface, reconstruct"
        )
    return PipelineConfig(
        edges=EdgeConfig(**data.get("edges", {})),
        surface=SurfaceConfig(**data.get("surface", {})),
        reconstruct=ReconstructConfig(**data.get("reconstruct", {})),
    )


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


def write_outputs(
    writer: OutputWriter, lf: LightField, result: Result, *, seconds_total: float
) -> dict:
    """Write the main job's files into ``writer`` and return the metrics it wrote.

    Files: ``disparity/view_RR_CC.pfm`` per view, ``disparity.npz`` (all views + edge set),
    ``centre_disparity.png``, ``mosaic.png``, ``edges_overlay.png``, ``epi_horizontal.png``,
    ``epi_vertical.png``, and with ground truth ``error_map.png``, ``badpix_0.07.png``;
    ``metrics.json`` always.

    Returns:
        The metrics: ``seconds_total``, ``compile_seconds``, ``seconds_per_stage``,
        ``view_consistency``, ``n_views``, ``n_edge_points``, ``n_dropped_points``, and with
        ground truth of the centre view ``mse_x100``, ``badpix_0.01/0.03/0.07``,
        ``q25_x100`` (+ ``all_views``: the mean over every view with ground truth).
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
    )
    present = disp[mask]
    lo, hi = np.percentile(present, 1), np.percentile(present, 99)
    writer.png("centre_disparity.png", viz.colorize_disparity(disp[rc, cc], vmin=lo, vmax=hi))
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

    consistency = float(view_consistency(jnp.asarray(disp), view_mask=jnp.asarray(mask)))
    metrics: dict = {
        "scene": lf.name,
        "seconds_total": float(seconds_total),
        "compile_seconds": float(result.compile_seconds),
        "seconds_per_stage": {k: float(v) for k, v in result.seconds_per_stage.items()},
        "view_consistency": consistency,
        "n_views": int(mask.sum()),
        "n_edge_points": int(np.asarray(e.valid).sum()),
        "n_dropped_points": int(np.asarray(e.n_dropped)),
    }
    if lf.gt_disparity is not None:
        gt = np.asarray(lf.gt_disparity)
        gtm = np.asarray(lf.gt_mask)
        if gtm[rc, cc].any():
            metrics.update(depth_metrics(disp[rc, cc], gt[rc, cc], gtm[rc, cc]))
            writer.png("error_map.png", viz.error_map(disp[rc, cc], gt[rc, cc], mask=gtm[rc, cc]))
            writer.png(
                "badpix_0.07.png", viz.badpix_map(disp[rc, cc], gt[rc, cc], mask=gtm[rc, cc])
            )
        with_gt = [(r, c) for r in range(U) for c in range(V) if gtm[r, c].any() and mask[r, c]]
        if len(with_gt) > 1:
            per_view = [depth_metrics(disp[r, c], gt[r, c], gtm[r, c]) for r, c in with_gt]
            metrics["all_views"] = {
                k: float(np.mean([m[k] for m in per_view])) for k in per_view[0]
            }
            metrics["all_views"]["worst_view_mse_x100"] = float(
                max(m["mse_x100"] for m in per_view)
            )
    writer.json("metrics.json", metrics)
    return metrics
