"""Run-to-run determinism on GPUs: XLA's flag for deterministic GPU kernels.

On the CPU every stage gives the same bits on every run. On an NVIDIA GPU XLA adds the
updates of a scatter-add (the splatting of edge points into grids) with atomic operations in
no fixed order, so the sums differ in their last bits from run to run; the chain's discrete
decisions (which point wins a pixel, which side of an edge a pixel takes) amplify that into
disparity differences of a fraction of a pixel, and finite differences of the chain become
noise (docs/RESULTS.md, "GPU"). XLA's ``--xla_gpu_deterministic_ops=true`` makes those
kernels deterministic, at some cost in speed. It is read from ``XLA_FLAGS`` when JAX starts
its backend, so it must be requested before the first computation.
"""

from __future__ import annotations

import os

#: The XLA flag (in ``XLA_FLAGS``) for deterministic GPU kernels.
DETERMINISTIC_FLAG = "--xla_gpu_deterministic_ops=true"


def _backend_started() -> bool | None:
    """Whether JAX has started a backend (``None`` when this JAX version does not say)."""
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):
        return None


def deterministic_gpu_requested() -> bool:
    """Whether ``XLA_FLAGS`` asks for deterministic GPU kernels (`request_deterministic_gpu`)."""
    return DETERMINISTIC_FLAG in os.environ.get("XLA_FLAGS", "").split()


def request_deterministic_gpu() -> None:
    """Ask XLA for run-to-run deterministic GPU kernels, before JAX starts its backend.

    Appends ``--xla_gpu_deterministic_ops=true`` to ``$XLA_FLAGS`` (once). On the CPU the flag
    changes nothing (CPU runs are deterministic already). With it, the Ch. 6 chain on an NVIDIA
    H200 (JAX 0.11.2) gave bit-identical results on repeated calls in one process; without it
    the final disparity of a 5×5×32² scene differed by up to 0.63 px between calls. Call it
    at the top of a notebook or script, right after ``import mvedge_jax`` and before any JAX
    computation or import of a stage package (``mvedge_jax.pipeline``, ``.edges``, ...: their
    default configurations hold JAX arrays, which start the backend); ``mvedge
    --deterministic`` does it for the command line.

    Raises:
        RuntimeError: if JAX has already started a backend (the flag would be ignored), or if
            ``$XLA_FLAGS`` already sets ``--xla_gpu_deterministic_ops`` to another value.
    """
    flags = os.environ.get("XLA_FLAGS", "").split()
    name = DETERMINISTIC_FLAG.split("=", 1)[0]
    others = [f for f in flags if f.split("=", 1)[0] == name and f != DETERMINISTIC_FLAG]
    if others:
        raise RuntimeError(
            f"XLA_FLAGS already sets {others[0]}; remove it to request {DETERMINISTIC_FLAG}"
        )
    if DETERMINISTIC_FLAG in flags:
        return
    if _backend_started():
        raise RuntimeError(
            "deterministic GPU kernels must be requested before JAX starts its backend (the "
            "first JAX computation); call request_deterministic_gpu() at the top of the "
            f"script, or start Python with XLA_FLAGS={DETERMINISTIC_FLAG}"
        )
    os.environ["XLA_FLAGS"] = " ".join([*flags, DETERMINISTIC_FLAG])
