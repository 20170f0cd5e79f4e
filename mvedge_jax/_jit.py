"""`filter_jit_bound`: `equinox.filter_jit` for functions whose arguments have defaults."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable

import equinox as eqx


def filter_jit_bound(fn: Callable) -> Callable:
    """`equinox.filter_jit` of ``fn``, always called with every argument passed.

    `equinox.filter_jit` keys its compiled programs on the call's arguments as given: a call
    that omits an argument with a default (``reconstruct(views, edges, surface)``) is
    traced apart from one that passes it (``reconstruct(views, edges, surface,
    ReconstructConfig())``), and the omitted default is a constant of its program. This
    wrapper binds the defaults first (`inspect.Signature.apply_defaults`), so both calls are
    one program, and the array fields of a default config stay traced arguments.

    Raises:
        TypeError: as ``fn`` would, on arguments that do not fit its signature.
    """
    jitted = eqx.filter_jit(fn)
    signature = inspect.signature(fn)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        return jitted(*bound.args, **bound.kwargs)

    return call
