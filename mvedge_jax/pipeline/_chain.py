"""The edge-to-depth chain as pure, jittable functions of arrays (thesis Ch. 4.1 → 4.2–4.3 → 6).

`estimate_disparity_arrays` is the whole chain; `edges_stage`, `surface_stage` and
`reconstruct_stage` are its three steps, which the driver (`estimate_disparity`) compiles and
times one by one. Every function here is pure: the configuration's array fields are traced
(sweeping or differentiating them never recompiles), its static fields and ``d_max`` are
compile-time constants.
"""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array, Float

from ..edges import EdgeSet, detect_edges_arrays
from ..reconstruct import Reconstruction, reconstruct
from ..surface import SurfaceResult, surface_vectors
from ._config import PipelineConfig

#: The stages of the chain, in order (the keys of ``Result.seconds_per_stage``).
STAGES = ("edges", "surface", "reconstruct")


class ChainOutput(eqx.Module):
    """Output of `estimate_disparity_arrays`.

    Attributes:
        disparity: ``(U, V, H, W)`` disparity of every view, pixels per view step.
        edges: the multi-view edge set (thesis Ch. 4.1).
        surface: surface vectors, λ_e and depth-edge confidence (Ch. 4.2–4.3).
        reconstruction: intermediate maps of the smooth 4D reconstruction (Ch. 6).
    """

    disparity: Float[Array, "U V H W"]
    edges: EdgeSet
    surface: SurfaceResult
    reconstruction: Reconstruction


def _check_views(views) -> None:
    if views.ndim != 5 or views.shape[-1] != 3 or min(views.shape[:2]) < 3:
        raise ValueError(
            f"views must have shape (U >= 3, V >= 3, H, W, 3); got {tuple(views.shape)}"
        )


def edges_stage(
    views: Float[Array, "U V H W 3"], config: PipelineConfig, *, key: Array, d_max: float
) -> EdgeSet:
    """Step 1: multi-view edges of the central cross-hair (`detect_edges_arrays`).

    Args:
        views: ``(U, V, H, W, 3)`` RGB in [0, 1] (only the central row and column are read).
        config: `PipelineConfig` (``config.edges`` is used).
        key: PRNG key of the entropy search.
        d_max: half-range of the filter bank, pixels per view step (static).

    Returns:
        The `EdgeSet`.

    Raises:
        ValueError: on a bad shape.

    References:
        Thesis Ch. 4.1.
    """
    _check_views(views)
    rc, cc = views.shape[0] // 2, views.shape[1] // 2
    return detect_edges_arrays(views[rc], views[:, cc], config.edges, d_max=d_max, key=key)


def surface_stage(
    views: Float[Array, "U V H W 3"], edges: EdgeSet, config: PipelineConfig
) -> SurfaceResult:
    """Step 2: surface vectors and depth-edge confidence in the centre view
    (`surface_vectors`).

    References:
        Thesis Ch. 4.2–4.3.
    """
    _check_views(views)
    rc, cc = views.shape[0] // 2, views.shape[1] // 2
    return surface_vectors(edges, views[rc, cc], config.surface)


def reconstruct_stage(
    views: Float[Array, "U V H W 3"],
    edges: EdgeSet,
    surface: SurfaceResult,
    config: PipelineConfig,
) -> Reconstruction:
    """Step 3: smooth 4D reconstruction of every view (`reconstruct`).

    References:
        Thesis Ch. 6.1 (eqs 6.1–6.8).
    """
    return reconstruct(views, edges, surface, config.reconstruct)


def estimate_disparity_arrays(
    views: Float[Array, "U V H W 3"],
    config: PipelineConfig,
    *,
    key: Array,
    d_max: float,
) -> ChainOutput:
    """The whole chain as one pure function of arrays: views → disparity of every view.

    Jit it with ``d_max`` static (``jax.jit(estimate_disparity_arrays,
    static_argnames="d_max")``); differentiate or ``vmap`` it with respect to ``views`` or
    the array fields of ``config`` (e.g. ``eqx.tree_at(lambda c:
    c.edges.filter.presmooth_sigma, config, s)``). `hyperparameter_paths`
    (``differentiable=True``) lists the fields it is smooth in; the thresholds are piecewise
    constant. It computes in the precision of ``views`` (float32, or float64 under
    ``jax_enable_x64``).

    Args:
        views: ``(U, V, H, W, 3)`` RGB in [0, 1], finite; the cross-hair must be complete.
        config: `PipelineConfig`.
        key: PRNG key of the randomised line refinement (thesis eq 4.5).
        d_max: half-range of the filter bank, pixels per view step (static;
            `mvedge_jax.edges.resolve_d_max` of the scene's disparity range).

    Returns:
        `ChainOutput` with ``disparity`` of shape ``(U, V, H, W)``.

    Raises:
        ValueError: on a bad shape.

    References:
        Thesis Ch. 4.1 (edges), 4.2–4.3 (surface vectors), 6.1 (reconstruction).
    """
    edges = edges_stage(views, config, key=key, d_max=d_max)
    surface = surface_stage(views, edges, config)
    rec = reconstruct_stage(views, edges, surface, config)
    return ChainOutput(disparity=rec.disparity, edges=edges, surface=surface, reconstruction=rec)
