"""Ahead-of-time compiled stages, kept per (stage, static configuration, array shapes).

The driver compiles each stage once and separately from running it, so compilation time is
reported apart from work. Array arguments, including the array fields of the configs, are
traced: a second call with new hyperparameter values reuses the executable; a new shape,
dtype or static field compiles a new one. The package's own stages are also kept on disk as
exported programs (`mvedge_jax._cache.StageStore`), so a new process compiles them without
tracing them.
"""

from __future__ import annotations

import dataclasses
import inspect
import logging
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax

from .._cache import StageStore
from .._memory import STAGE_MAPPINGS, ensure_mapping_headroom

log = logging.getLogger(__name__)


def _aval(x) -> tuple:
    return (tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))


@dataclasses.dataclass(frozen=True)
class BoundStage:
    """A compiled stage bound to its arguments; calling it runs the stage.

    Attributes:
        func: the `jax.stages.Compiled` executable, over the flat array leaves of the stage's
            arguments, returning the flat leaves of its result.
        args: those array leaves.
        out_tree: the result's tree structure.
    """

    func: Any
    args: tuple
    out_tree: Any

    def __call__(self):
        return jax.tree.unflatten(self.out_tree, self.func(*self.args))


def _flat(fn: Callable, treedef, stat, static: dict):
    """``fn`` over flat array arguments and results, and a dict that holds the result's tree
    structure (``"tree"``) once it has been traced."""
    box = {}

    def flat(*flat_args):
        out = fn(*eqx.combine(jax.tree.unflatten(treedef, flat_args), stat), **static)
        out_leaves, box["tree"] = jax.tree.flatten(out)
        return out_leaves

    return flat, box


class StageCache:
    """Least-recently-used store of compiled stages.

    Args:
        maxsize: executables kept in memory (each holds its compiled XLA program).
        store: where traced stages are also kept on disk, so that a new process compiles
            them without tracing (default: a `StageStore` beside JAX's compilation cache;
            ``None`` keeps them in memory only). Only module-level functions of
            `mvedge_jax` are stored: the key covers the package's source but not a
            closure's captured values or another package's code.

    Attributes:
        compilations: stages traced and compiled by this cache.
        loads: stages compiled from the disk store instead, without tracing.
    """

    def __init__(self, maxsize: int = 32, *, store: StageStore | None = ...):
        self.maxsize = maxsize
        self.store = StageStore() if store is ... else store
        self._entries: OrderedDict[Any, Any] = OrderedDict()
        self.compilations = 0
        self.loads = 0

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Forget every compiled stage held in memory (the disk store is kept)."""
        self._entries.clear()

    def compile(self, fn: Callable, *args, **static) -> tuple[BoundStage, float]:
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
            executable was reused from memory.
        """
        dyn, stat = eqx.partition(args, eqx.is_array)
        leaves, treedef = jax.tree.flatten(dyn)
        avals = tuple(_aval(x) for x in leaves)
        static_items = tuple(sorted(static.items()))
        key = (fn, treedef, avals, stat, static_items)
        entry = self._entries.get(key)
        seconds = 0.0
        if entry is None:
            ensure_mapping_headroom(STAGE_MAPPINGS, release=self.clear)
            t0 = time.perf_counter()
            entry = self._compile(fn, stat, static, leaves, treedef, avals, static_items)
            seconds = time.perf_counter() - t0
            self._entries[key] = entry
            while len(self._entries) > self.maxsize:
                self._entries.popitem(last=False)
        else:
            self._entries.move_to_end(key)
        compiled, out_tree = entry
        return BoundStage(compiled, tuple(leaves), out_tree), seconds

    def _compile(self, fn, stat, static, leaves, treedef, avals, static_items):
        """``(compiled, out_tree)`` of the stage over its flat array leaves: from the disk
        store when it holds the stage, else traced (and exported to the store when the stage
        is one it keeps)."""
        disk_key = self._disk_key(fn, treedef, avals, stat, static_items)
        if disk_key is not None:
            stored = self.store.load(disk_key)
            if stored is not None:
                exported, out_tree = stored
                self.loads += 1
                return jax.jit(exported.call).lower(*leaves).compile(), out_tree
        flat, box = _flat(fn, treedef, stat, static)
        self.compilations += 1
        if disk_key is not None:
            specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
            try:
                exported = jax.export.export(jax.jit(flat))(*specs)
            except Exception as err:  # not exportable: compile it directly, in memory only
                log.info("%s not exported (%s); compiled without the disk store", fn, err)
            else:
                self.store.save(disk_key, exported, box["tree"])
                return jax.jit(exported.call).lower(*leaves).compile(), box["tree"]
        return jax.jit(flat).lower(*leaves).compile(), box["tree"]

    def _disk_key(self, fn, treedef, avals, stat, static_items) -> str | None:
        if self.store is None or self.store.path is None:
            return None
        name = f"{getattr(fn, '__module__', '')}.{getattr(fn, '__qualname__', '')}"
        stored = (
            inspect.isfunction(fn)
            and fn.__closure__ is None
            and "<locals>" not in fn.__qualname__
            and name.startswith("mvedge_jax.")
        )
        if not stored:
            return None
        return self.store.key(name, f"{treedef}|{avals}", repr((stat, static_items)))


#: The cache of `estimate_disparity` and `optimize_disparity` (one per process).
STAGE_CACHE = StageCache()
