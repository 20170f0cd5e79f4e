"""Ahead-of-time compiled stages, kept per (stage, static configuration, array shapes).

The driver compiles each stage once and separately from running it, so compilation time is
reported apart from work. Array arguments, including the array fields of the configs, are
traced: a second call with new hyperparameter values reuses the executable; a new shape,
dtype or static field compiles a new one.
"""

from __future__ import annotations

import functools
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax


def _aval(x) -> tuple:
    return (tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))


class StageCache:
    """Least-recently-used store of compiled stages.

    Args:
        maxsize: executables kept (each holds its compiled XLA program).
    """

    def __init__(self, maxsize: int = 32):
        self.maxsize = maxsize
        self._entries: OrderedDict[Any, Any] = OrderedDict()
        self.compilations = 0

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Forget every compiled stage."""
        self._entries.clear()

    def compile(self, fn: Callable, *args, **static) -> tuple[Callable[[], Any], float]:
        """``fn(*args, **static)`` compiled (on first use), not yet run.

        Args:
            fn: a pure function.
            *args: its positional arguments: pytrees whose array leaves are traced and whose
                other leaves (static config fields, Python scalars) are compile-time
                constants (they must be hashable).
            **static: keyword arguments passed as compile-time constants (hashable).

        Returns:
            ``(run, compile_seconds)``: ``run()`` executes it on ``args`` (asynchronously:
            use ``jax.block_until_ready`` on its output to time the work; ``run.func`` is
            the ``jax.stages.Compiled`` executable); ``compile_seconds`` is 0 when the
            executable was reused.
        """
        dyn, stat = eqx.partition(args, eqx.is_array)
        leaves, treedef = jax.tree.flatten(dyn)
        key = (fn, treedef, tuple(_aval(x) for x in leaves), stat, tuple(sorted(static.items())))
        compiled = self._entries.get(key)
        seconds = 0.0
        if compiled is None:

            def call(dyn_args):
                return fn(*eqx.combine(dyn_args, stat), **static)

            t0 = time.perf_counter()
            compiled = jax.jit(call).lower(dyn).compile()
            seconds = time.perf_counter() - t0
            self.compilations += 1
            self._entries[key] = compiled
            while len(self._entries) > self.maxsize:
                self._entries.popitem(last=False)
        else:
            self._entries.move_to_end(key)
        return functools.partial(compiled, dyn), seconds


#: The cache of `estimate_disparity` and `optimize_disparity` (one per process).
STAGE_CACHE = StageCache()
