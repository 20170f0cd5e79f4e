"""Room in the process's memory mappings for new XLA executables.

XLA:CPU maps the code and data of every executable it loads as separate memory regions
(about 25 for a small jitted function, about 3,400 for all the stages of one
`estimate_disparity` configuration, about 5,000 for `tune`'s gradient through the chain),
and JAX keeps every executable it compiled for the life of the process. Linux caps the
mappings of one process (``vm.max_map_count``, 65,530 by default); at the cap LLVM cannot
map a new executable ("LLVM compilation error: Cannot allocate memory") and the process
crashes. A notebook that runs the chain for a few dozen shapes or static configurations gets
there. The drivers therefore check the headroom before they compile and release JAX's
compiled programs when it runs out.
"""

from __future__ import annotations

import gc
import warnings
from collections.abc import Callable

import jax

#: Mappings one compiled stage of `estimate_disparity` may add (all the stages of one
#: configuration add about 3,400 together).
STAGE_MAPPINGS = 4000
#: Mappings one program of the whole chain may add (`sweep`, `tune`'s gradient: about 5,000).
CHAIN_MAPPINGS = 8000

_MAPS = "/proc/self/maps"
_LIMIT = "/proc/sys/vm/max_map_count"


def memory_mappings() -> tuple[int, int] | None:
    """``(mappings of this process, the kernel's per-process limit)``, or ``None`` where the
    system does not report them (anything but Linux)."""
    try:
        with open(_MAPS, "rb") as f:
            mapped = sum(1 for _ in f)
        with open(_LIMIT) as f:
            limit = int(f.read())
    except (OSError, ValueError):
        return None
    return mapped, limit


def ensure_mapping_headroom(need: int, *, release: Callable[[], None] | None = None) -> bool:
    """Make room for ``need`` more memory mappings before compiling.

    When fewer than ``need`` mappings are left under the kernel's limit, every compiled
    program JAX holds is dropped (`jax.clear_caches`, and ``release`` for caches of our
    own), with a `RuntimeWarning`. Later calls recompile them, or read them back from the
    persistent compilation cache.

    Args:
        need: mappings the coming compilation may add (an upper estimate).
        release: also called to drop compiled programs that JAX's caches do not hold.

    Returns:
        True when compiled programs were released, False when there was room (or the
        system does not report its mappings).

    Raises:
        RuntimeError: when the room is still missing after the release, i.e. something
            other than compiled programs holds the mappings; compiling would crash the
            process.
    """
    counts = memory_mappings()
    if counts is None or counts[0] + need <= counts[1]:
        return False
    before, limit = counts
    jax.clear_caches()
    if release is not None:
        release()
    gc.collect()
    after = memory_mappings()
    mapped = before if after is None else after[0]
    if mapped + need > limit:
        raise RuntimeError(
            f"this process holds {mapped} of the kernel's {limit} memory mappings "
            f"(vm.max_map_count) even after JAX's compiled programs were released; "
            f"compiling another XLA program (up to {need} more) could crash it. Restart the "
            f"process or raise the limit (sysctl -w vm.max_map_count=262144)."
        )
    warnings.warn(
        f"this process held {before} of the kernel's {limit} memory mappings "
        f"(vm.max_map_count); released JAX's compiled programs ({mapped} left) so that new "
        f"ones can be loaded; they are recompiled, or read from the persistent cache, "
        f"when used again",
        RuntimeWarning,
        stacklevel=2,
    )
    return True
