"""`ensure_mapping_headroom`: compiled programs are released before the process runs out of
memory mappings, where loading one more XLA executable would crash it."""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import pytest

from mvedge_jax import _memory
from mvedge_jax.pipeline import _sweep, _tune
from mvedge_jax.pipeline._compile import StageCache

needs_proc = pytest.mark.skipif(
    _memory.memory_mappings() is None, reason="the system does not report memory mappings"
)


def _compile_some(n: int) -> list:
    fns = [jax.jit(lambda x, i=i: jnp.sin(x) * i + jnp.cumsum(x)) for i in range(n)]
    for i, f in enumerate(fns):
        f(jnp.ones(100 + i)).block_until_ready()
    return fns


@needs_proc
def test_compiled_programs_hold_mappings_that_the_release_gives_back():
    before, limit = _memory.memory_mappings()
    fns = _compile_some(30)
    loaded, _ = _memory.memory_mappings()
    assert loaded > before + 100  # about 25 per executable
    released = []
    # ask for exactly one mapping more than is left: only a release can make room
    with pytest.warns(RuntimeWarning, match="vm.max_map_count"):
        assert _memory.ensure_mapping_headroom(
            limit - loaded + 1, release=lambda: released.append(1)
        )
    assert released == [1]
    after, _ = _memory.memory_mappings()
    assert after < loaded - 100
    del fns


@needs_proc
def test_room_left_changes_nothing():
    traces = []
    f = jax.jit(lambda x: traces.append(1) or x + 1)
    f(jnp.ones(3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not _memory.ensure_mapping_headroom(100, release=lambda: pytest.fail("released"))
    f(jnp.ones(3))
    assert len(traces) == 1  # the compiled program was kept


@needs_proc
def test_mappings_held_by_something_else_raise_a_clear_error():
    _, limit = _memory.memory_mappings()
    with pytest.raises(RuntimeError, match=r"vm\.max_map_count.*could crash"):
        _memory.ensure_mapping_headroom(limit)


def test_unknown_mappings_are_left_alone(monkeypatch):
    monkeypatch.setattr(_memory, "memory_mappings", lambda: None)
    assert not _memory.ensure_mapping_headroom(10**9, release=lambda: pytest.fail("released"))


def test_the_stage_cache_releases_its_stages_when_room_runs_out(monkeypatch):
    cache = StageCache(store=None)
    cache.compile(jnp.sin, jnp.ones(4))
    assert len(cache) == 1
    counts = iter([(65_000, 65_530), (1_000, 65_530)])  # before and after the release
    monkeypatch.setattr(_memory, "memory_mappings", lambda: next(counts))
    with pytest.warns(RuntimeWarning, match="released JAX's compiled programs"):
        run, _ = cache.compile(jnp.cos, jnp.ones(4))
    assert len(cache) == 1  # sin's stage was dropped, cos's kept
    assert jnp.allclose(run()[0], jnp.cos(1.0))


def test_sweep_and_tune_check_the_room_for_a_whole_chain_program(monkeypatch):
    asked = []

    def record(need, *, release=None):
        asked.append(need)
        raise RuntimeError("stop here")

    monkeypatch.setattr(_sweep, "ensure_mapping_headroom", record)
    monkeypatch.setattr(_tune, "ensure_mapping_headroom", record)
    from mvedge_jax.pipeline import PipelineConfig, smooth_config, sweep, tune
    from mvedge_jax.synthetic import make_scene

    lf = make_scene(1, grid=(3, 3), size=(16, 16), disparity_range=(-1.0, 1.0), n_objects=1)
    with pytest.raises(RuntimeError, match="stop here"):
        sweep(
            lf.views,
            PipelineConfig(),
            {"reconstruct.centre.omega": jnp.ones(2)},
            key=jax.random.key(0),
            d_max=2.0,
        )
    with pytest.raises(RuntimeError, match="stop here"):
        tune(smooth_config(), [lf], fields=["reconstruct.centre.omega"], steps=1)
    assert asked == [_memory.CHAIN_MAPPINGS, _memory.CHAIN_MAPPINGS]
