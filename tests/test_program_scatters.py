"""The chain's forward program holds no batched scatters.

``vmap`` of a scatter (``x.at[i].max(v)`` inside a vmapped function) gives a scatter with
batching dimensions. On a GPU with XLA's deterministic kernels
(`mvedge_jax.request_deterministic_gpu`) such scatters of the cross-hair projection gave
different pixels in the forward and the gradient programs of one function (JAX 0.11.2,
docs/RESULTS.md "GPU"); the chain's stacked scatters use flat indices instead
(`forward_project_views`, `pixel_subset`), and so do the occlusion masks of the
self-supervised losses (thesis eq 7.15). The CPU gives the same numbers either way, so
these tests read the traced programs (jaxprs).
"""

from __future__ import annotations

import jax
import jax.extend as jex
import jax.numpy as jnp

from mvedge_jax.diff import multiview_cameras, multiview_photometric_terms, photometric_terms
from mvedge_jax.lightfield import forward_project_views
from mvedge_jax.pipeline import PipelineConfig, estimate_disparity_arrays, smooth_config
from mvedge_jax.synthetic import make_multiview_scene


def _batched_scatters(jaxpr) -> list[str]:
    """Name and source line of every scatter with batching dimensions in ``jaxpr`` and in
    the programs nested in its equations."""
    found = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name.startswith("scatter"):
            if eqn.params["dimension_numbers"].operand_batching_dims:
                found.append(f"{eqn.primitive.name} at {eqn.source_info.traceback}")
        for sub in jex.core.jaxprs_in_params(eqn.params):
            found.extend(_batched_scatters(sub))
    return found


def test_the_scan_sees_a_vmapped_scatter():
    def splat(i, v):
        return jnp.zeros(4).at[i].max(v)

    i, v = jnp.zeros((3, 5), jnp.int32), jnp.ones((3, 5))
    assert len(_batched_scatters(jax.make_jaxpr(jax.vmap(splat))(i, v).jaxpr)) == 1
    assert _batched_scatters(jax.make_jaxpr(splat)(i[0], v[0]).jaxpr) == []


def test_whole_chain_has_no_batched_scatters():
    views = jnp.zeros((5, 5, 24, 32, 3), jnp.float32)
    for config in (PipelineConfig(), smooth_config()):

        def chain(v, config=config):
            return estimate_disparity_arrays(
                v, config, key=jax.random.PRNGKey(0), d_max=2.0
            ).disparity

        assert _batched_scatters(jax.make_jaxpr(chain)(views).jaxpr) == []


def test_photometric_losses_have_no_batched_scatters():
    """The occlusion masks of eq 7.15 (a z-buffer per view) in both losses' programs."""
    d = jnp.zeros((16, 20))
    views = jnp.zeros((4, 16, 20, 3))
    offsets = jnp.array([[0.0, 1.0], [1.0, 0.0], [0.0, -1.0], [-1.0, 0.0]])

    def light_field(x):
        return photometric_terms(x, views[0], views, offsets)["photometric"]

    assert _batched_scatters(jax.make_jaxpr(light_field)(d).jaxpr) == []
    scene = make_multiview_scene(n_views=3)
    ref = scene.names[1]
    cameras = multiview_cameras(scene.model, ref, [n for n in scene.names if n != ref])
    images = jnp.asarray(scene.images)
    label = cameras.label(jnp.asarray(scene.depth[1], jnp.float32))

    def multiview(x):
        return multiview_photometric_terms(x, images[1], images[jnp.array([0, 2])], cameras)[
            "photometric"
        ]

    assert _batched_scatters(jax.make_jaxpr(multiview)(label).jaxpr) == []


def test_stacked_projection_and_its_gradient_have_no_batched_scatters():
    """`forward_project_views` gathers the winners' values through flat indices, so the
    scatter-add of its reverse pass is unbatched too."""
    d = jnp.zeros((3, 12, 16))
    offsets = jnp.array([[0.0, 1.0], [1.0, 0.0], [-1.0, 2.0]])

    def total(x):
        return jnp.sum(forward_project_views(x, offsets)[0])

    assert _batched_scatters(jax.make_jaxpr(jax.grad(total))(d).jaxpr) == []
