"""Call costs of `tune` and `sweep`: what a second step and a second call cost.

Runs in one fresh Python process with JAX's persistent compilation cache off
(``MVEDGE_JAX_CACHE=off``), so every trace and XLA compilation shows in the wall time. On a
synthetic 5×5 light field (``--size`` pixels square):

- ``tune`` call 1: `tune` of ``reconstruct.centre.omega`` and ``reconstruct.epi.c`` from
  `smooth_config`, ``--steps`` Adam steps at ``--learning-rate``; the per-step seconds of its
  history show whether a later step compiled again. Call 2: another start value of ω and a
  third of the learning rate.
- ``sweep`` call 1: three values of ``reconstruct.centre.omega``; call 2: the same grid with
  other base values (``reconstruct.centre.a``, ``reconstruct.centre.c``) and another key.

Usage::

    MVEDGE_JAX_CACHE=off python experiments/bench_tune_sweep.py [--size 48] [--steps 3]

Prints one row per call: wall seconds, the seconds of its first and of its later steps
(``tune``), and the number of times the chain was traced during the call.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MVEDGE_JAX_CACHE", "off")

import jax  # noqa: E402
import numpy as np  # noqa: E402

from mvedge_jax.edges import resolve_d_max  # noqa: E402
from mvedge_jax.pipeline import (  # noqa: E402
    PipelineConfig,
    _sweep,
    _tune,
    replace_paths,
    smooth_config,
    sweep,
    tune,
)
from mvedge_jax.synthetic import make_scene  # noqa: E402


def _count(module, name: str) -> list:
    """Count the Python calls of ``module.name`` (a call happens only when JAX traces)."""
    calls: list = []
    real = getattr(module, name)

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    setattr(module, name, counting)
    return calls


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=48, help="pixels (square)")
    ap.add_argument("--steps", type=int, default=3, help="Adam steps per tune call")
    ap.add_argument(
        "--learning-rate", type=float, default=0.3, help="of tune call 1 (call 2: a third)"
    )
    args = ap.parse_args()
    lf = make_scene(
        11, grid=(5, 5), size=(args.size, args.size), disparity_range=(-1.0, 1.0), n_objects=2
    )
    print(
        f"device: {jax.devices()[0].device_kind}; jax {jax.__version__}; "
        f"5x5x{args.size}x{args.size}; persistent cache: {os.environ['MVEDGE_JAX_CACHE']}"
    )
    rows = []
    fields = ["reconstruct.centre.omega", "reconstruct.epi.c"]
    traces = _count(_tune, "chain_loss")
    cfg = smooth_config()
    lr = args.learning_rate
    calls = [(cfg, lr), (replace_paths(cfg, {fields[0]: 80.0}), lr / 3)]
    for i, (start, lr) in enumerate(calls):
        n0, t0 = len(traces), time.perf_counter()
        _, hist = tune(start, [lf], fields=fields, steps=args.steps, learning_rate=lr)
        wall = time.perf_counter() - t0
        sec = hist["seconds"]
        rows.append(
            (f"tune call {i + 1}", wall, sec[0], float(np.median(sec[1:])), len(traces) - n0)
        )
    traces = _count(_sweep, "estimate_disparity_arrays")
    config = PipelineConfig()
    d_max = resolve_d_max(config.edges, lf.disparity_range)
    grid = {"reconstruct.centre.omega": np.array([20.0, 150.0, 600.0])}
    other = replace_paths(config, {"reconstruct.centre.a": 0.5, "reconstruct.centre.c": 2.0})
    for i, (base, seed) in enumerate([(config, 0), (other, 1)]):
        n0, t0 = len(traces), time.perf_counter()
        jax.block_until_ready(sweep(lf.views, base, grid, key=jax.random.key(seed), d_max=d_max))
        rows.append((f"sweep call {i + 1}", time.perf_counter() - t0, None, None, len(traces) - n0))
    print(f"{'call':<14}{'wall s':>9}{'step 1 s':>10}{'later steps s (median)':>24}{'traces':>8}")
    for name, wall, first, later, n in rows:
        f = "" if first is None else f"{first:.2f}"
        m = "" if later is None else f"{later:.2f}"
        print(f"{name:<14}{wall:>9.2f}{f:>10}{m:>24}{n:>8}")


if __name__ == "__main__":
    main()
