"""End-to-end entry points: light field → edges → surface vectors → disparity for every view.

The stages (thesis Ch. 4.1 → 4.2–4.3 → 6) are separately jitted pure functions of arrays. The
`estimate_disparity` driver compiles each stage ahead of time (so compile time is reported apart
from run time), runs it, and records the seconds per stage. `estimate_disparity_arrays` is the
same chain as one jittable function, for sweeps and gradients. `optimize_disparity` refines a
result with the differentiable edge model (thesis Ch. 7) and propagates the refined centre map
to every view.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import viz
from .diff import ModelConfig, OptimizeConfig, RenderConfig, optimize, params_from_edges
from .edges import HORIZONTAL, VERTICAL, EdgeConfig, EdgeSet, render_overlay
from .edges._pipeline import _detect_arrays, resolve_d_max
from .io import OutputWriter
from .lightfield import LightField
from .metrics import depth_metrics, view_consistency
from .reconstruct import (
    ReconstructConfig,
    Reconstruction,
    propagate,
    reconstruct,
    select_centre,
    sharpen,
)
from .surface import SurfaceConfig, SurfaceResult, surface_vectors

STAGES = ("edges", "surface", "reconstruct")


#: The default of ``PipelineConfig.optimize``: the thesis schedule and losses (Sec. 7.1.5) with
#: settings measured to suit a start from the Ch. 6 result (dense, accurate labels): a narrower
#: splat (σ_S = 0.8, σ_λ = 0.5 instead of 1.3, 0.71) and stronger image-edge stops
#: (``q_scale`` 30) encode the Ch. 6 map far more faithfully; a low density ρ = 0.1 keeps
#: visible neighbours from hiding each other; larger tile capacities avoid overflow with
#: dense points; one pass at a third of the authors' learning rates (Adam moves every label
#: by about the learning rate per step, and more passes did not help on HCI crops).
#: Measured at full resolution (centre view, Ch. 6 → optimised and sharpened, before the
#: merge of `optimize_disparity`'s ``select_initial``): backgammon MSE×100 1.31 → 1.33,
#: BadPix(0.07) 1.76 → 1.45, BadPix(0.01) 13.9 → 24.5; antinous 8.10 → 7.88, 16.4 → 12.7,
#: 74.6 → 62.3 (session 3). With the merge: backgammon 1.31, 1.29, 12.1; antinous 7.81,
#: 12.8, 68.5 (session 4). With the merge and the residual diffusion of
#: `optimize_disparity`'s ``diffuse_residual`` (the default since session 5): backgammon
#: 1.29, 1.24, 12.3; antinous 6.50, 12.8, 69.9. ``OptimizeConfig()`` (one pass) instead:
#: backgammon 3.64, 4.99 (session 2). Twice the label rate (0.01) instead: antinous 7.98,
#: 12.96, 62.1 before the merge (session 4; worse than 0.005). Session 6 (after the Ch. 6
#: disocclusion and matting changes), on an H100 (whose scatter order varies, so the Ch. 6
#: start varies by ±0.1 BadPix(0.07) from run to run): the session-5 rates (0.005, 0.03)
#: gave antinous BadPix(0.07) −23.0 to −24.5% in five runs; label rate 0.008 and position
#: rate 0.05 with ``select_min_change = 0`` (every pixel may take the optimised value)
#: −25.2 to −26.0% in three runs, and backgammon −26.8% (against −27.5%). Session 8 (2-core
#: CPU, these rates): with the departures splatted per point (`predict`'s ``prior``; the
#: start is now the Ch. 6 map exactly) and the SSIM term in the merge's cost
#: (``ReconstructConfig.select_ssim``), antinous 8.02, 12.06 (−26.1%), 64.4 and backgammon
#: 1.22, 1.19 (−31.6%), 16.5; the optimised map alone (before sharpening and merge) went
#: from 11.07, 18.31 to 7.94, 15.66 on antinous.
OPTIMIZE_DEFAULT = OptimizeConfig(
    model=ModelConfig(
        render=RenderConfig(
            sigma_label=0.8,
            sigma_weight=0.5,
            density=0.1,
            tile_levels=((128, 1.0), (200, 0.5)),
        ),
        q_scale=30.0,
    ),
    passes=1,
    learning_rate=(0.008, 0.05, 0.005, 0.005),
)


class PipelineConfig(eqx.Module):
    """Configuration of the whole pipeline: one frozen config per stage.

    Attributes:
        edges: multi-view edge detection (Ch. 4.1).
        surface: surface vectors and depth-edge confidence (Ch. 4.2–4.3).
        reconstruct: smooth 4D reconstruction (Ch. 6); its cross-hair/off-cross-hair part
            also propagates an optimised centre map (`optimize_disparity`).
        optimize: the optional Ch. 7 refinement (`optimize_disparity`, ``mvedge depth
            --optimize``); default `OPTIMIZE_DEFAULT` (``OptimizeConfig()`` is the thesis
            configuration).
    """

    edges: EdgeConfig = EdgeConfig()
    surface: SurfaceConfig = SurfaceConfig()
    reconstruct: ReconstructConfig = ReconstructConfig()
    optimize: OptimizeConfig = OPTIMIZE_DEFAULT


class Result(eqx.Module):
    """Output of `estimate_disparity` (and of `optimize_disparity`).

    Attributes:
        disparity: ``(U, V, H, W)`` float32 disparity for every view, pixels per view step.
        edges: the multi-view edge set (thesis Ch. 4.1).
        surface: surface vectors, λ_e and depth-edge confidence (Ch. 4.2–4.3).
        reconstruction: intermediate maps of the smooth 4D reconstruction (Ch. 6).
        seconds_per_stage: wall seconds per stage after compilation (``edges``, ``surface``,
            ``reconstruct``; ``optimize`` after `optimize_disparity`).
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


def cross_hair_others(
    views: Float[Array, "U V H W 3"],
) -> tuple[Float[Array, "K H W 3"], Float[Array, "K 2"]]:
    """The ``K = U + V - 2`` cross-hair views other than the centre and their ``(dr, dc)``.

    Args:
        views: ``(U, V, H, W, 3)`` light field.

    Returns:
        ``(others (K, H, W, 3), offsets (K, 2))``: the centre row of views left to right,
        then the centre column top to bottom, without the centre view; ``offsets`` are
        ``(row - U//2, col - V//2)`` in view steps (float32).
    """
    U, V = views.shape[:2]
    rc, cc = U // 2, V // 2
    pos = [(rc, c) for c in range(V) if c != cc] + [(r, cc) for r in range(U) if r != rc]
    idx = np.asarray(pos)
    offsets = jnp.asarray(idx - np.array([rc, cc]), jnp.float32)
    return jnp.asarray(views)[idx[:, 0], idx[:, 1]], offsets


def _one_per_pixel(edges: EdgeSet, valid: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``valid`` restricted to the most confident point of each pixel (ties: lowest index)."""
    H, W = shape
    xi = np.clip(np.round(np.asarray(edges.x)), 0, W - 1).astype(np.int64)
    yi = np.clip(np.round(np.asarray(edges.y)), 0, H - 1).astype(np.int64)
    pix = yi * W + xi
    order = np.lexsort((-np.asarray(edges.confidence), pix))  # by pixel, then confidence
    order = order[valid[order]]
    _, first = np.unique(pix[order], return_index=True)
    keep = np.zeros_like(valid)
    keep[order[first]] = True
    return keep


def optimize_steps(config: OptimizeConfig) -> int:
    """Number of Adam steps of `optimize_disparity` (passes × blocks × iterations)."""
    return config.passes * len(config.blocks) * config.iterations


def optimize_disparity(
    lf: LightField,
    result: Result,
    config: PipelineConfig | OptimizeConfig | None = None,
    *,
    progress: Callable[[int, dict], None] | None = None,
    surface_offset: bool = True,
    one_per_pixel: bool = True,
    sharpen_result: bool = True,
    select_initial: bool = True,
    diffuse_residual: bool = True,
) -> tuple[Result, dict]:
    """Refine a Ch. 6 result with the differentiable multi-view edge model (thesis Ch. 7).

    1. Points: the valid edge points of ``result.edges`` that are visible in the centre view,
       at their centre-view positions moved by their surface vectors (``surface_offset``:
       onto the side of the edge their label belongs to, as in the Ch. 6 centre diffusion,
       eq 6.1), labelled with the Ch. 6 centre disparity ``result.disparity[U//2, V//2]``
       sampled bilinearly there (`params_from_edges`); ``R = 0``, ``Q = q_scale · |∇I|``.
       With ``one_per_pixel`` only the most confident point per pixel is kept (the
       horizontal and vertical EPIs find most edges twice; dense duplicates overflow the
       screen tiles of the renderer and cost time).
    2. Self-supervised block-coordinate Adam (`optimize`, eq 7.16) against the other views
       of the central cross-hair, with their ``(dr, dc)`` offsets. With
       ``diffuse_residual`` the diffusion spreads the points' departures from the Ch. 6 map
       rather than the labels themselves (`predict`'s ``prior``; not in the thesis): each
       point carries its departure from the Ch. 6 map under it, so the start reproduces the
       Ch. 6 map exactly, and slanted surfaces keep their slope between sparse points
       (antinous MSE×100 7.92 → 7.42, backgammon BadPix(0.07) 1.46 → 1.29 before the merge
       of step 4; session 5).
    3. With ``sharpen_result``: the optimised centre map is sharpened like the Ch. 6 one
       (`sharpen` with ``config.reconstruct``: photo-consistent snapping and the weighted
       median filter; the thesis, Sec. 7.2.1, post-processes its Ch. 7 results with the
       weighted median filter too).
    4. With ``select_initial``: the optimised map and the Ch. 6 centre map are merged pixel
       by pixel by photo-consistency with the cross-hair views (`select_centre`; not in the
       thesis): the optimised value is kept where it differs by more than
       ``config.reconstruct.select_min_change`` (0 by default) and matches the views
       better, by colour L1 plus ``select_ssim`` times the SSIM dissimilarity (eq 7.16's
       data terms; the L1 alone missed half the pixels the optimisation had fixed on
       antinous, session 8). The
       optimisation fixes gross errors at depth edges but re-renders the whole map from
       points and loses fine accuracy elsewhere; the merge keeps both (backgammon,
       BadPix(0.01) 24.5 % optimised alone, 12.1 % merged).
    5. The centre map is spread to every view by `propagate` (forward projection, angular
       EPI inpainting, off-cross-hair views; eqs 6.4–6.8) with ``config.reconstruct``.
       Steps 3–5 are compiled ahead of time, like the stages of `estimate_disparity`.

    Args:
        lf: the light field of ``result`` (its cross-hair must be complete).
        result: the `Result` of `estimate_disparity` on ``lf``.
        config: a `PipelineConfig` (its ``optimize`` and ``reconstruct`` are used), or an
            `OptimizeConfig` (with the default ``reconstruct``); default `PipelineConfig()`
            (`OPTIMIZE_DEFAULT`).
        progress: optional callback ``progress(step, info)`` after every Adam step (``info``:
            ``loss``, ``pass``, ``block``, ``solver_iterations``, ``seconds``, ...), for
            progress bars; `optimize_steps` gives the number of steps.
        surface_offset: place the points at ``(x, y) + surface.offset`` (default) instead of
            on the edge itself.
        one_per_pixel: keep one point per pixel (default).
        sharpen_result: sharpen the optimised centre map before the propagation (default).
        select_initial: merge it with the Ch. 6 centre map by photo-consistency (default).
        diffuse_residual: diffuse the departures from the Ch. 6 centre map (default) instead
            of the labels (the thesis' eq 7.2).

    Returns:
        ``(result, info)``: a new `Result` (``disparity`` and ``reconstruction`` replaced:
        ``reconstruction.centre`` is the optimised map, ``centre_sharp`` the map that was
        propagated; ``seconds_per_stage["optimize"]`` added: optimisation plus sharpening
        and propagation after their compilation; ``compile_seconds`` grows by that
        compilation) and ``info`` with ``optimize_seconds`` (wall seconds of the Adam steps,
        including the compilation of the step on the first one), ``propagate_seconds``
        (sharpening + propagation), ``loss_history`` (list of floats, one per step),
        ``solver_iterations`` (list of ints, one per step), ``selected_fraction`` (share of
        centre pixels that took the optimised value; 1.0 without ``select_initial``),
        ``overflow`` (most points dropped from a full screen tile in any step; 0 is good),
        ``n_points``, ``steps``, and ``centre_initial`` / ``centre_optimized``: the
        ``(H, W)`` centre maps before and after the optimisation (NumPy, before sharpening,
        merging and propagation).

    Raises:
        ValueError: if the result does not match the light field or has no visible points.

    References:
        Thesis Sec. 7.1.4–7.1.5 (Θ̄ = {Z, K, R, Q}, Adam one block at a time), eqs 7.15–7.16
        (self-supervised loss), Sec. 7.2.1 (WMF post-processing); Sec. 6.1 eqs 6.4–6.8
        (propagation).
    """
    if config is None:
        config = PipelineConfig()
    elif isinstance(config, OptimizeConfig):
        config = PipelineConfig(optimize=config)
    opt = config.optimize
    views = lf.views
    U, V = lf.grid
    H, W = lf.size
    if tuple(result.disparity.shape) != (U, V, H, W):
        raise ValueError(
            f"result.disparity has shape {tuple(result.disparity.shape)}; the light field "
            f"needs {(U, V, H, W)}"
        )
    rc, cc = lf.centre_index
    centre_view = lf.centre_view
    edges = result.edges
    points = edges
    if surface_offset:
        off = result.surface.offset
        points = eqx.tree_at(
            lambda e: (e.x, e.y), edges, (edges.x + off[:, 0], edges.y + off[:, 1])
        )
    valid = edges.valid & edges.visible
    if one_per_pixel:
        valid = jnp.asarray(_one_per_pixel(points, np.asarray(valid), (H, W)))
    n_points = int(valid.sum())
    if n_points == 0:
        raise ValueError(
            f"the edge set of {lf.name!r} has no valid point visible in the centre view; "
            "nothing to optimise"
        )
    initial = result.disparity[rc, cc]
    params, _ = params_from_edges(points, centre_view, opt.model, disparity=initial)
    others, offsets = cross_hair_others(views)

    t0 = time.perf_counter()
    prior = initial if diffuse_residual else None
    _, hist = optimize(
        params, centre_view, others, offsets, opt, valid=valid, prior=prior, callback=progress
    )
    optimize_seconds = time.perf_counter() - t0
    refined = jnp.asarray(hist["disparity"], jnp.float32)

    def finish(views, centre, initial, edges, surface):
        sharp = sharpen(views, centre, config.reconstruct) if sharpen_result else centre
        took = jnp.ones(sharp.shape, bool)
        if select_initial:
            sharp, took = select_centre(views, initial, sharp, config.reconstruct)
        rec = propagate(views, sharp, edges, surface, config.reconstruct)
        return eqx.tree_at(lambda r: r.centre, rec, centre), took

    args = (views, refined, initial, edges, result.surface)
    t0 = time.perf_counter()
    compiled = jax.jit(finish).lower(*args).compile()
    compile_seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    rec, took = jax.block_until_ready(compiled(*args))
    propagate_seconds = time.perf_counter() - t0

    seconds = dict(result.seconds_per_stage)
    seconds["optimize"] = optimize_seconds + propagate_seconds
    new = Result(
        disparity=rec.disparity,
        edges=edges,
        surface=result.surface,
        reconstruction=rec,
        seconds_per_stage=seconds,
        compile_seconds=result.compile_seconds + compile_seconds,
    )
    info = {
        "optimize_seconds": optimize_seconds,
        "propagate_seconds": propagate_seconds,
        "loss_history": [float(v) for v in hist["loss"]],
        "solver_iterations": [int(v) for v in hist["solver_iterations"]],
        "overflow": int(hist["overflow"].max()) if hist["overflow"].size else 0,
        "n_points": n_points,
        "steps": int(hist["loss"].size),
        "selected_fraction": float(np.mean(np.asarray(took))),
        "centre_initial": np.asarray(initial),
        "centre_optimized": np.asarray(refined),
    }
    return new, info


def _tuples(value):
    """TOML arrays → tuples (static config fields must be hashable)."""
    if isinstance(value, list | tuple):
        return tuple(_tuples(v) for v in value)
    return value


def _override(base: eqx.Module, table: dict) -> eqx.Module:
    """``base`` with the fields named in ``table`` replaced; a sub-table overrides the fields
    of a nested config (e.g. ``[optimize.model.render]``) and keeps its other values."""
    kwargs = {}
    for name, value in table.items():
        current = getattr(base, name, None)
        if isinstance(value, dict) and isinstance(current, eqx.Module):
            kwargs[name] = _override(current, value)
        else:
            kwargs[name] = _tuples(value)
    return dataclasses.replace(base, **kwargs)


CONFIG_TABLES = ("edges", "surface", "reconstruct", "optimize")


def config_from_dict(data: dict) -> PipelineConfig:
    """Build a `PipelineConfig` from ``{"edges": {...}, "surface": {...}, "reconstruct": {...},
    "optimize": {...}}`` (keyword arguments of the stage configs; missing tables and keys keep
    the defaults).

    Nested configs are sub-tables, e.g. in TOML ``[optimize.loss]`` (``LossConfig``),
    ``[optimize.model]``, ``[optimize.model.render]`` or ``[reconstruct.epi_solver]``; arrays
    become tuples (``blocks``, ``learning_rate``, ``tile_levels``).

    Raises:
        ValueError: on an unknown table name or a bad parameter value.
        TypeError: on an unknown parameter of a stage config.
    """
    unknown = set(data) - set(CONFIG_TABLES)
    if unknown:
        raise ValueError(f"unknown config tables {sorted(unknown)}; use {', '.join(CONFIG_TABLES)}")
    base = PipelineConfig()
    return PipelineConfig(
        **{name: _override(getattr(base, name), data.get(name, {})) for name in CONFIG_TABLES}
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
        ``view_consistency``, ``n_views``, ``n_edge_points``, ``n_dropped_points``, and with
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
