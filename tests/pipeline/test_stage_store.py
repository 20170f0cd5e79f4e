"""Stages kept on disk as exported programs: a new process compiles them without tracing, the
key covers everything that changes the program, and a bad file is a cache miss."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax import _cache
from mvedge_jax.lightfield import rgb_to_lab
from mvedge_jax.pipeline import PipelineConfig, _compile, estimate_disparity
from mvedge_jax.pipeline._compile import StageCache
from mvedge_jax.synthetic import make_scene


@pytest.fixture
def rgb():
    return jnp.asarray(np.random.default_rng(0).uniform(size=(4, 5, 3)), jnp.float32)


def _no_tracing(*args, **kwargs):
    raise AssertionError("the stage was traced")


def test_a_new_cache_compiles_a_stored_stage_without_tracing(tmp_path, rgb, monkeypatch):
    first = StageCache(store=_cache.StageStore(tmp_path))
    run, _ = first.compile(rgb_to_lab, rgb)
    expected = np.asarray(run())
    assert (first.compilations, first.loads) == (1, 0)
    assert len(list(tmp_path.glob("*.bin"))) == 1

    monkeypatch.setattr(_compile, "_flat", _no_tracing)
    second = StageCache(store=_cache.StageStore(tmp_path))
    run, seconds = second.compile(rgb_to_lab, rgb)
    assert (second.compilations, second.loads) == (0, 1)
    assert seconds > 0
    np.testing.assert_array_equal(np.asarray(run()), expected)
    np.testing.assert_allclose(expected, np.asarray(rgb_to_lab(rgb)), rtol=1e-6, atol=1e-4)
    # in memory afterwards: no second load
    second.compile(rgb_to_lab, rgb)
    assert second.loads == 1


def test_the_key_covers_shapes_static_arguments_source_and_settings(tmp_path, rgb, monkeypatch):
    store = _cache.StageStore(tmp_path)
    cache = StageCache(store=store)
    cache.compile(rgb_to_lab, rgb)
    cache.clear()
    cache.compile(rgb_to_lab, rgb[:2])  # new shape
    assert cache.compilations == 2
    base = store.key("f", "s", "static=1")
    assert base == store.key("f", "s", "static=1")
    assert base != store.key("f", "s", "static=2")
    assert base != store.key("g", "s", "static=1")
    assert store.key("f", "s", "<Foo object at 0x7f00>") is None
    monkeypatch.setattr(_cache, "_source_digest", lambda: "edited source")
    assert store.key("f", "s", "static=1") != base
    monkeypatch.setattr(_cache, "_source_digest", lambda: "")  # source not readable
    assert store.key("f", "s", "static=1") is None
    monkeypatch.undo()
    jax.config.update("jax_enable_x64", True)
    try:
        assert store.key("f", "s", "static=1") != base
    finally:
        jax.config.update("jax_enable_x64", False)


def test_the_source_digest_follows_edits(tmp_path, monkeypatch):
    package = tmp_path / "mvedge_jax"
    package.mkdir()
    module = package / "m.py"
    module.write_text("x = 1\n")
    monkeypatch.setattr(_cache, "__file__", str(package / "_cache.py"))
    first = _cache._source_digest()
    assert first == _cache._source_digest()
    module.write_text("x = 22\n")
    assert _cache._source_digest() not in ("", first)


def test_a_damaged_file_is_a_miss_and_is_replaced(tmp_path, rgb):
    StageCache(store=_cache.StageStore(tmp_path)).compile(rgb_to_lab, rgb)
    (file,) = tmp_path.glob("*.bin")
    file.write_bytes(file.read_bytes()[:100])
    cache = StageCache(store=_cache.StageStore(tmp_path))
    run, _ = cache.compile(rgb_to_lab, rgb)
    assert (cache.compilations, cache.loads) == (1, 0)
    np.testing.assert_allclose(np.asarray(run()), np.asarray(rgb_to_lab(rgb)), atol=1e-4)
    (again,) = tmp_path.glob("*.bin")
    assert again.stat().st_size > 100


def test_only_module_level_package_functions_are_stored(tmp_path, rgb):
    cache = StageCache(store=_cache.StageStore(tmp_path))
    offset = jnp.float32(1.0)
    cache.compile(lambda x: x + offset, rgb)
    cache.compile(jnp.sin, rgb)
    assert cache.compilations == 2
    assert not list(tmp_path.glob("*.bin"))


def test_the_store_is_pruned_to_its_size(tmp_path, rgb):
    store = _cache.StageStore(tmp_path, max_bytes=1)
    StageCache(store=store).compile(rgb_to_lab, rgb)
    assert not list(tmp_path.glob("*.bin"))


def test_the_store_follows_the_compilation_cache_setting(tmp_path, monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    try:
        jax.config.update("jax_compilation_cache_dir", str(tmp_path))
        monkeypatch.delenv("MVEDGE_JAX_CACHE", raising=False)
        assert _cache.stages_dir() == tmp_path / _cache.STAGES_SUBDIR
        monkeypatch.setenv("MVEDGE_JAX_CACHE", "off")
        assert _cache.stages_dir() is None
        assert StageCache().store.path is None
        monkeypatch.delenv("MVEDGE_JAX_CACHE")
        jax.config.update("jax_compilation_cache_dir", None)
        assert _cache.stages_dir() is None
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


_PROCESS = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    from mvedge_jax.pipeline import STAGE_CACHE, PipelineConfig, estimate_disparity
    from mvedge_jax.synthetic import make_scene

    lf = make_scene(5, grid=(5, 5), size=(32, 32), disparity_range=(-1.0, 1.0), n_objects=2)
    result = estimate_disparity(lf, PipelineConfig())
    np.save(sys.argv[1], np.asarray(result.disparity))
    print(json.dumps({"compilations": STAGE_CACHE.compilations, "loads": STAGE_CACHE.loads}))
    """
)


@pytest.mark.slow
def test_a_new_process_runs_the_whole_chain_from_the_store(tmp_path):
    """This process stores the stages (in the test run's cache folder); a new process
    compiles all three from the store, without tracing, to the same result."""
    lf = make_scene(5, grid=(5, 5), size=(32, 32), disparity_range=(-1.0, 1.0), n_objects=2)
    here = np.asarray(estimate_disparity(lf, PipelineConfig()).disparity)
    assert len(list(_cache.stages_dir().glob("*.bin"))) >= 3
    env = dict(os.environ, MVEDGE_JAX_CACHE=str(jax.config.jax_compilation_cache_dir))
    out = subprocess.run(
        [sys.executable, "-c", _PROCESS, str(tmp_path / "d.npy")],
        env=env,
        check=True,
        capture_output=True,
        text=True,
        timeout=600,
    ).stdout
    assert json.loads(out.strip().splitlines()[-1]) == {"compilations": 0, "loads": 3}
    np.testing.assert_array_equal(np.load(tmp_path / "d.npy"), here)
