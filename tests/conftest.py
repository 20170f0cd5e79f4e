"""Shared fixtures: data location, deterministic per-test PRNG keys, float64 switch."""

from __future__ import annotations

import importlib.metadata
import os
import warnings
import zlib
from pathlib import Path

import jax
import pytest

# Persistent compilation cache: repeated test runs do not recompile, and a program that one
# pytest-xdist worker compiled is read by the other (files of both compile the same stages). One
# folder for all workers: JAX's key of a program includes the cache folder's path (through
# the compile options), so per-worker folders could share nothing. JAX locks the folder
# (`filelock`) only when the cache has a size cap; without the lock, a worker could read an
# entry that the other is still writing. The cap is far above what the suite stores (about
# 70 MB).
jax.config.update(
    "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache" / "tests")
)
jax.config.update("jax_compilation_cache_max_size", 4 << 30)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

# On a GPU, scatter-adds sum in no fixed order, so two evaluations of the chain differ and its
# finite differences become noise; the tests compare against exact values and finite
# differences, so they ask for XLA's deterministic kernels (no effect on the CPU). Before any
# JAX computation: the flag is read when the backend starts. (After the cache setup above:
# importing mvedge_jax leaves a configured cache folder as it is.)
from mvedge_jax import request_deterministic_gpu  # noqa: E402

request_deterministic_gpu()

DATA = Path(os.environ.get("MVEDGE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


_XLA_OPT = "--xla_backend_optimization_level"


def _cpu_only() -> bool:
    """Whether JAX runs on the CPU here: ``JAX_PLATFORMS=cpu``, or no GPU or TPU plugin
    installed."""
    if os.environ.get("JAX_PLATFORMS", "").strip().lower() == "cpu":
        return True
    names = {(d.metadata["Name"] or "").lower() for d in importlib.metadata.distributions()}
    return not any(n.startswith(("jax-cuda", "jax_cuda", "jax-rocm", "libtpu")) for n in names)


def pytest_configure(config):
    """The default run (``-m 'not slow'``) on the CPU compiles with XLA's backend (LLVM) at -O0.

    That run compiles several hundred distinct programs and runs most of them on inputs of a
    few thousand pixels, so code generation costs more than optimised code saves
    (docs/RESULTS.md, "Unoptimised machine code for the default test run"). The HLO passes,
    fusion included, run as usual; the machine code differs in rounding only (the whole chain
    on a 5×5×48² scene: 64 of the 57,600 values of its maps differ from the default level's
    by more than 1e-5 px per view step, none by 1e-4; its solvers stop at a relative residual
    of 1e-5). The level is left as it is in the slow tests (whole jobs on full-size light
    fields), on a machine with a GPU or TPU plugin, and where ``$XLA_FLAGS`` already sets
    ``--xla_backend_optimization_level`` (``=3``, XLA's default, tests the optimised code).
    The flags are read when JAX starts its backend, which the test modules do when they are
    imported, after this hook. A folder's own conftest, loaded before it when the run is
    given a test folder or file, can start it earlier; then the level is left as it is, with
    a warning.
    """
    if config.getoption("markexpr") != "not slow" or not _cpu_only():
        return
    flags = os.environ.get("XLA_FLAGS", "").split()
    if any(f.split("=", 1)[0] == _XLA_OPT for f in flags):
        return
    from mvedge_jax._determinism import _backend_started

    if _backend_started():
        config.issue_config_time_warning(
            pytest.PytestConfigWarning(
                f"JAX started its backend before tests/conftest.py could set {_XLA_OPT}=0 "
                "(a test folder's conftest imports JAX arrays); the tests compile with XLA's "
                "default optimisation level"
            ),
            stacklevel=2,
        )
        return
    os.environ["XLA_FLAGS"] = " ".join([*flags, f"{_XLA_OPT}=0"])


@pytest.fixture(scope="module", autouse=True)
def _mapping_headroom():
    """After each test module, leave room for the memory mappings of the next one.

    XLA:CPU maps each loaded executable's code and data as separate memory regions, and JAX
    keeps every executable it compiled. A pytest-xdist worker that keeps them all reaches
    64,000 mappings by the end of the suite, next to Linux's default limit of 65,530
    (``vm.max_map_count``), where loading one more executable crashes the worker. One module
    adds up to about 18,000 (`test_pipeline_optimize.py`); when fewer than 35,000 are left,
    JAX's compiled programs are released (`ensure_mapping_headroom`, as the drivers do) and
    come back from the persistent cache when a later module needs them. If the release does
    not make the room, the module's teardown raises, naming the mappings, instead of a
    later crash.
    """
    from mvedge_jax._memory import ensure_mapping_headroom  # after the cache setup above

    yield
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the release is expected here
        ensure_mapping_headroom(35_000)


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """The shared light-field data folder; fails loudly when absent (CI has it)."""
    if not DATA.is_dir():
        pytest.fail(f"shared data not found at {DATA}; set MVEDGE_DATA")
    return DATA


@pytest.fixture
def key(request) -> jax.Array:
    """A PRNG key that is deterministic per test (crc32 of the node id, not hash())."""
    return jax.random.key(zlib.crc32(request.node.nodeid.encode()))


@pytest.fixture
def x64():
    """Enable float64 for the duration of a test (gradient checks)."""
    jax.config.update("jax_enable_x64", True)
    try:
        yield
    finally:
        jax.config.update("jax_enable_x64", False)


@pytest.fixture
def count_calls(monkeypatch):
    """``count_calls(module, name)`` replaces ``module.name`` by a wrapper for the test and
    returns a list that grows by one per call. Inside a jitted function the Python body runs
    only while JAX traces it, so the list counts traces."""

    def install(module, name: str) -> list:
        calls: list = []
        real = getattr(module, name)

        def counting(*args, **kwargs):
            calls.append(1)
            return real(*args, **kwargs)

        monkeypatch.setattr(module, name, counting)
        return calls

    return install
