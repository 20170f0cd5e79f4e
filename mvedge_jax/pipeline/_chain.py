"""The edge-to-depth chain as jittable functions of arrays (thesis Ch. 4.1 → 4.2–4.3 → 6)."""

from __future__ import annotations

from jaxtyping import Array, Float

from ..edges import EdgeSet
from ..edges._pipeline import _detect_arrays, resolve_d_max
from ..reconstruct import Reconstruction, reconstruct
from ..surface import SurfaceResult, surface_vectors
from ._config import PipelineConfig

STAGES = ("edges", "surface", "reconstruct")


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
