"""Drivers of the main job: `estimate_disparity` (Ch. 6) and `optimize_disparity` (Ch. 7)."""

from __future__ import annotations

import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..diff import OptimizeConfig, optimize, params_from_edges
from ..edges import EdgeSet, check_cross_hair, warn_dropped
from ..lightfield import LightField
from ..reconstruct import Reconstruction, propagate, select_centre, sharpen
from ..surface import SurfaceResult
from ._chain import edges_stage, reconstruct_stage, surface_stage
from ._checks import (
    check_compiled_memory,
    check_memory,
    check_solver,
    diagnose,
    reconstruct_solver_status,
)
from ._compile import STAGE_CACHE
from ._config import PipelineConfig


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
        diagnostics: ``warnings`` (list of str: almost no edge points, unconverged solves)
            and ``solver`` (status per stage) from `diagnose`.
    """

    disparity: Float[Array, "U V H W"]
    edges: EdgeSet
    surface: SurfaceResult
    reconstruction: Reconstruction
    seconds_per_stage: dict[str, float] = eqx.field(static=True)
    compile_seconds: float = eqx.field(static=True)
    diagnostics: dict = eqx.field(static=True, default_factory=dict)


def _edges(views, config, key, *, d_max):
    return edges_stage(views, config, key=key, d_max=d_max)


def estimate_disparity(
    lf: LightField,
    config: PipelineConfig | None = None,
    *,
    key: Array | None = None,
    progress: Callable[[str, str], None] | None = None,
) -> Result:
    """Disparity for every view of a light field (the main job, thesis Ch. 6).

    A thin driver over the chain (`estimate_disparity_arrays`): the host-side checks of
    `mvedge_jax.edges.check_cross_hair`, then each stage (`edges_stage`, `surface_stage`,
    `reconstruct_stage`) compiled ahead of time and run, then `warn_dropped`. Compiled
    stages are kept per (static configuration, array shapes): a second call, also with new
    values of the configuration's array fields, does not recompile, and ``compile_seconds``
    is then 0. The library's persistent compilation cache makes the first compilation in a
    new process cheap too (`mvedge_jax.enable_compilation_cache`).

    Args:
        lf: the light field; its cross-hair must be complete.
        config: pipeline configuration (default `PipelineConfig()`).
        key: PRNG key for the randomised line refinement; default ``jax.random.key(0)``.
        progress: optional callback ``progress(stage, event)`` with event ``"compile"``,
            ``"run"`` or ``"done"``, for progress bars.

    Returns:
        A `Result` with ``disparity`` of shape ``(U, V, H, W)``.

    Raises:
        ValueError: if the views contain NaN/Inf, no edge point is found, the result holds
            NaN/Inf, or the scene's disparity range does not suit the filter bank
            (`check_cross_hair`).
        ConfigError: (a `ValueError`) if a stage would not fit in memory (checked before
            anything is allocated, and again on each compiled stage).

    Warns:
        UserWarning: when edge candidates were dropped for lack of capacity (`warn_dropped`).

    References:
        Thesis Ch. 4.1, 4.2–4.3 and 6.1.
    """
    config = PipelineConfig() if config is None else config
    key = jax.random.key(0) if key is None else key
    if not bool(np.isfinite(np.asarray(lf.views)).all()):
        raise ValueError(f"light field {lf.name!r} contains NaN or Inf pixel values")
    check_memory(config, lf.grid, lf.size, lf.disparity_range)
    d_max = check_cross_hair(lf, config.edges)
    views = jnp.asarray(lf.views)
    seconds: dict[str, float] = {}
    compile_total = 0.0

    def run_stage(stage, fn, *args, **static):
        nonlocal compile_total
        if progress:
            progress(stage, "compile")
        execute, c_seconds = STAGE_CACHE.compile(fn, *args, **static)
        compile_total += c_seconds
        check_compiled_memory(stage, execute.func)
        if progress:
            progress(stage, "run")
        t0 = time.perf_counter()
        out = jax.block_until_ready(execute())
        seconds[stage] = time.perf_counter() - t0
        if progress:
            progress(stage, "done")
        return out

    edges = run_stage("edges", _edges, views, config, key, d_max=d_max)
    warn_dropped(edges, config.edges)
    surface = run_stage("surface", surface_stage, views, edges, config)
    rec = run_stage("reconstruct", reconstruct_stage, views, edges, surface, config)
    return Result(
        disparity=rec.disparity,
        edges=edges,
        surface=surface,
        reconstruction=rec,
        seconds_per_stage=seconds,
        compile_seconds=compile_total,
        diagnostics=diagnose(lf, config, edges, surface, rec, d_max=d_max),
    )


def _optimize_diagnostics(diagnostics: dict, residuals, rec, config: PipelineConfig) -> dict:
    """``diagnostics`` with the status of the optimisation's Poisson solves (the worst
    relative residual over its steps) under ``solver["optimize"]``, the status of the
    propagation's solves of ``rec`` (replacing the Ch. 6 ones), and their warnings."""
    warnings = list(diagnostics.get("warnings", []))
    status, more = check_solver("optimize", residuals, float(config.optimize.model.solver.rtol))
    warnings += more
    solver = {**diagnostics.get("solver", {}), "optimize": status}
    rec_status, more = reconstruct_solver_status(rec, config)
    solver.update(rec_status)
    warnings += more
    return {**diagnostics, "warnings": warnings, "solver": solver}


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


def _finish(views, centre, initial, edges, surface, config, *, sharpen_result, select_initial):
    """Steps 3–5 of `optimize_disparity`: sharpen, merge with the Ch. 6 map, propagate."""
    sharp = sharpen(views, centre, config) if sharpen_result else centre
    took = jnp.ones(sharp.shape, bool)
    if select_initial:
        sharp, took = select_centre(views, initial, sharp, config)
    rec = propagate(views, sharp, edges, surface, config)
    return eqx.tree_at(lambda r: r.centre, rec, centre), took


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
       ``config.reconstruct.select.min_change`` (0 by default) and matches the views
       better, by colour L1 plus ``select.ssim`` times the SSIM dissimilarity (eq 7.16's
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

    execute, compile_seconds = STAGE_CACHE.compile(
        _finish,
        views,
        refined,
        initial,
        edges,
        result.surface,
        config.reconstruct,
        sharpen_result=sharpen_result,
        select_initial=select_initial,
    )
    t0 = time.perf_counter()
    rec, took = jax.block_until_ready(execute())
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
        diagnostics=_optimize_diagnostics(result.diagnostics, hist["solver_residual"], rec, config),
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
