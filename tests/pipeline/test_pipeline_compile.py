"""Compile once: the driver reuses compiled stages across calls and hyperparameter values; the
library enables the persistent compilation cache; no host callbacks in the stages."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mvedge_jax
from mvedge_jax.edges import resolve_d_max
from mvedge_jax.pipeline import (
    STAGE_CACHE,
    PipelineConfig,
    edges_stage,
    estimate_disparity,
    estimate_disparity_arrays,
    reconstruct_stage,
    replace_paths,
    surface_stage,
    sweep,
)
from mvedge_jax.synthetic import make_scene


@pytest.fixture(scope="module")
def small():
    return make_scene(5, grid=(5, 5), size=(32, 32), disparity_range=(-1.0, 1.0), n_objects=2)


OMEGAS = np.array([20.0, 150.0, 600.0])


def _close_to_batched(batched, single):
    """The batched (swept) and the single program round differently; the plane sweep's
    parabola vertex (where the cost curve is flat) and the weighted median's choice of sample
    turn that into differences of up to ~1e-3 at a few pixels (2 of 1024 measured)."""
    diff = np.abs(np.asarray(batched) - np.asarray(single))
    assert np.mean(diff <= 1e-4) >= 0.99 and diff.max() < 5e-3, (np.mean(diff <= 1e-4), diff.max())


def test_second_call_and_new_hyperparameters_do_not_recompile(small):
    config = PipelineConfig()
    first = estimate_disparity(small, config)
    n = STAGE_CACHE.compilations
    again = estimate_disparity(small, config)
    changed = replace_paths(
        config, {"reconstruct.centre.omega": jnp.asarray(20.0), "edges.filter.presmooth_sigma": 1.3}
    )
    other = estimate_disparity(small, changed)
    assert STAGE_CACHE.compilations == n
    assert again.compile_seconds == 0.0 and other.compile_seconds == 0.0
    np.testing.assert_array_equal(np.asarray(again.disparity), np.asarray(first.disparity))
    # the new values are used: the result changes (by up to 1.4 here) and equals the pure
    # chain's
    change = np.abs(np.asarray(other.disparity) - np.asarray(first.disparity)).max()
    assert change > 0.1
    chain = jax.jit(estimate_disparity_arrays, static_argnames="d_max")(
        jnp.asarray(small.views),
        changed,
        key=jax.random.key(0),
        d_max=resolve_d_max(changed.edges, small.disparity_range),
    )
    # The driver's stages and one jit of the whole chain are compiled separately, and XLA
    # fuses (and so rounds) them differently; the PCG solves stop at a relative residual of
    # 1e-5 (`SolverConfig.rtol`), so the maps agree to about that (1.03e-5 at most on an AMD
    # EPYC host), far closer than the new hyperparameters move them.
    np.testing.assert_allclose(
        np.asarray(other.disparity), np.asarray(chain.disparity), rtol=0, atol=1e-4
    )


def test_sweep_equals_separate_runs(small):
    config = PipelineConfig()
    d_max = resolve_d_max(config.edges, small.disparity_range)
    centres = sweep(
        small.views,
        config,
        {"reconstruct.centre.omega": OMEGAS},
        key=jax.random.key(0),
        d_max=d_max,
    )
    assert centres.shape == (3, 32, 32)
    for i, w in enumerate(OMEGAS):
        one = estimate_disparity(small, replace_paths(config, {"reconstruct.centre.omega": w}))
        _close_to_batched(centres[i], one.disparity[2, 2])
    with pytest.raises(ValueError, match="static field"):
        sweep(
            small.views, config, {"edges.filter.n_filters": [3.0]}, key=jax.random.key(0), d_max=1.0
        )
    with pytest.raises(ValueError, match="same length"):
        sweep(
            small.views,
            config,
            {"reconstruct.centre.omega": [1.0, 2.0], "reconstruct.centre.a": [1.0]},
            key=jax.random.key(0),
            d_max=1.0,
        )


def test_sweep_reuses_its_program_for_new_base_values_and_keys(small, count_calls):
    """The base configuration's array fields and the key are arguments of the compiled sweep,
    not constants: changing them does not trace the chain again, and the new values are
    used."""
    from mvedge_jax.pipeline import _sweep

    traces = count_calls(_sweep, "estimate_disparity_arrays")
    config = PipelineConfig()
    d_max = resolve_d_max(config.edges, small.disparity_range)
    omegas = {"reconstruct.centre.omega": OMEGAS}
    first = sweep(small.views, config, omegas, key=jax.random.key(0), d_max=d_max)
    n = len(traces)
    assert n <= 1, n  # 0 when another test of this file compiled it in this process
    other = replace_paths(config, {"reconstruct.centre.a": 0.5, "reconstruct.centre.c": 2.0})
    second = sweep(small.views, other, omegas, key=jax.random.key(1), d_max=d_max)
    assert len(traces) == n
    assert not np.allclose(np.asarray(first), np.asarray(second))
    one = estimate_disparity(
        small, replace_paths(other, {"reconstruct.centre.omega": 150.0}), key=jax.random.key(1)
    )
    _close_to_batched(second[1], one.disparity[2, 2])


def test_no_stage_has_a_host_callback(small):
    """Host callbacks would keep the stages out of the persistent cache and the stage store.
    (Lowered only: each stage takes the shapes its predecessor gives, `jax.eval_shape`.)"""
    config = PipelineConfig()
    views = jnp.asarray(small.views)
    key = jax.random.key(0)
    edges_jit = jax.jit(edges_stage, static_argnames="d_max")
    edges = jax.eval_shape(lambda v, k: edges_stage(v, config, key=k, d_max=1.25), views, key)
    surface = jax.eval_shape(lambda v, e: surface_stage(v, e, config), views, edges)
    texts = [
        edges_jit.lower(views, config, key=key, d_max=1.25).as_text(),
        jax.jit(surface_stage).lower(views, edges, config).as_text(),
        jax.jit(reconstruct_stage).lower(views, edges, surface, config).as_text(),
    ]
    for text in texts:
        assert "callback" not in text.lower()


def test_library_enables_the_persistent_cache(tmp_path, monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    try:
        monkeypatch.setenv("MVEDGE_JAX_CACHE", "off")
        jax.config.update("jax_compilation_cache_dir", None)
        assert mvedge_jax.enable_compilation_cache() is None
        assert jax.config.jax_compilation_cache_dir is None
        monkeypatch.setenv("MVEDGE_JAX_CACHE", str(tmp_path / "c"))
        assert mvedge_jax.enable_compilation_cache() == str(tmp_path / "c")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "c")
        # an existing setting is kept
        monkeypatch.setenv("MVEDGE_JAX_CACHE", str(tmp_path / "other"))
        assert mvedge_jax.enable_compilation_cache() == str(tmp_path / "c")
    finally:
        jax.config.update("jax_compilation_cache_dir", before)
