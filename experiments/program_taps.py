"""Where the chain's forward program and its gradient program part: taps on the
reconstruction's steps.

Usage::

    python experiments/program_taps.py [--deterministic] [--save DIR]

The test point of ``tests/pipeline/test_pipeline_gradients.py`` (5×5×32² synthetic light
field, float64, `smooth_config` with the solvers to 1e-12). The outputs of the
reconstruction's steps (colour guides, cross-hair projection, edge lines and their
rasterisation, photometric confidences, EPI solves, cross-hair fill, the other views'
merges and fill, the views' matte), their array inputs (``NAME #k inputs``) and the inputs
of the reconstruction are recorded with `jax.debug.callback` in the compiled forward
program (the loss) and in the compiled gradient program (its forward pass); prints, per
step and call, the largest difference and the number of elements that differ by more than
1e-12, ``rounding only`` with the count of elements that are not bit-identical where no
difference exceeds 1e-12, and ``same`` where the two are bit-identical. On the CPU the two
programs agree to rounding (1e-14); a step whose inputs agree and whose outputs do not is
where a compiled program computes something else. ``--save DIR`` writes every recorded
array (``DIR/forward.npz``, ``DIR/gradient.npz``; keys ``"TAP | call N | I"``), so that a
step can be replayed on another device with either program's inputs. The taps change what
XLA fuses, so a difference can move or vanish with them: compare with
`experiments/chain_gradients.py`, which has none.
"""

from __future__ import annotations

import argparse
import collections
import functools
import sys
import time
from pathlib import Path

#: The steps of `mvedge_jax.reconstruct._reconstruct` whose outputs are recorded.
STEPS = (
    "colour_guide",
    "project_cross_hair",
    "edge_lines",
    "rasterise_lines",
    "photometric_confidence",
    "solve_epis",
    "_cross_hair_fill",
    "merge_reprojections",
    "_fill_views",
    "_matte_views",
)


def _differences(a: tuple, b: tuple) -> str:
    import numpy as np

    parts = []
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        if x.shape != y.shape:
            parts.append(f"[{i}] shape {x.shape} against {y.shape}")
        elif x.dtype.kind in "biu":
            n = int(np.sum(x != y))
            if n:
                parts.append(f"[{i}] {n} of {x.size} differ")
        else:
            d = np.abs(x.astype(np.float64) - y.astype(np.float64))
            d = np.where(np.isnan(x) & np.isnan(y), 0.0, d)
            n = int(np.sum(d > 1e-12))
            bits = int(np.sum((x != y) & ~(np.isnan(x) & np.isnan(y))))
            if n:
                parts.append(f"[{i}] largest {float(np.nanmax(d)):.3e}, {n} of {x.size}")
            elif bits:
                parts.append(
                    f"[{i}] rounding only: largest {float(np.nanmax(d)):.1e}, "
                    f"{bits} of {x.size} not bit-identical"
                )
    return "; ".join(parts) or "same"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--deterministic",
        action="store_true",
        help="request XLA's deterministic GPU kernels (no effect on the CPU)",
    )
    parser.add_argument(
        "--save",
        type=Path,
        default=None,
        help="write every recorded array to SAVE/forward.npz and SAVE/gradient.npz",
    )
    args = parser.parse_args(argv)
    if args.save is not None and any(
        (args.save / f"{p}.npz").exists() for p in ("forward", "gradient")
    ):
        sys.exit(f"{args.save} holds forward.npz or gradient.npz; not overwritten")
    if args.deterministic:
        from mvedge_jax import request_deterministic_gpu

        request_deterministic_gpu()
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    import mvedge_jax.reconstruct._reconstruct as rec
    from mvedge_jax.pipeline import estimate_disparity_arrays, replace_paths

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from chain_gradients import gradient_test_point

    records: dict = collections.defaultdict(list)  # (program, tap) -> recorded calls
    program = ["forward"]
    calls: collections.Counter = collections.Counter()

    def record(tap, *arrays):
        records[(program[0], tap)].append(tuple(np.array(a) for a in arrays))

    def tapped(name, fn):
        @functools.wraps(fn)
        def wrapper(*a, **kw):
            out = fn(*a, **kw)
            calls[name] += 1
            tap = f"{name} #{calls[name]}"
            inputs = [x for x in jax.tree.leaves((a, kw)) if hasattr(x, "dtype")]
            if inputs:
                jax.debug.callback(functools.partial(record, f"{tap} inputs"), *inputs)
            leaves = [x for x in jax.tree.leaves(out) if hasattr(x, "dtype")]
            jax.debug.callback(functools.partial(record, tap), *leaves)
            return out

        return wrapper

    originals = {name: getattr(rec, name) for name in STEPS}
    propagate = rec._propagate

    def propagate_tapped(views, centre, edges, surface, config):
        leaves = [x for x in jax.tree.leaves((centre, edges, surface)) if hasattr(x, "dtype")]
        jax.debug.callback(functools.partial(record, "inputs (centre, edges, surface)"), *leaves)
        return propagate(views, centre, edges, surface, config)

    for name, fn in originals.items():
        setattr(rec, name, tapped(name, fn))
    rec._propagate = propagate_tapped
    try:
        views, gt, config, d_max, values0, _ = gradient_test_point()

        def loss(values):
            c = replace_paths(config, values)
            out = estimate_disparity_arrays(views, c, key=jax.random.key(0), d_max=d_max)
            return jnp.mean((out.disparity - gt) ** 2)

        t0 = time.perf_counter()
        value = jax.jit(loss)(values0)
        jax.block_until_ready(value)
        jax.effects_barrier()
        print(f"forward program: loss {float(value):.15g} ({time.perf_counter() - t0:.1f} s)")
        program[0] = "gradient"
        calls.clear()
        t0 = time.perf_counter()
        value, grad = jax.jit(jax.value_and_grad(loss))(values0)
        jax.block_until_ready(grad)
        jax.effects_barrier()
        print(f"gradient program: loss {float(value):.15g} ({time.perf_counter() - t0:.1f} s)")
    finally:
        for name, fn in originals.items():
            setattr(rec, name, fn)
        rec._propagate = propagate
    print(f"device: {jax.devices()[0]}\n")
    taps = sorted({tap for _, tap in records})
    for tap in taps:
        f, g = records.get(("forward", tap), []), records.get(("gradient", tap), [])
        if len(f) != len(g):
            print(f"{tap}: {len(f)} calls in the forward program, {len(g)} in the gradient one")
        for call, (a, b) in enumerate(zip(f, g, strict=False)):
            print(f"{tap}, call {call}: {_differences(a, b)}", flush=True)
    if args.save is not None:
        args.save.mkdir(parents=True, exist_ok=True)
        for prog in ("forward", "gradient"):
            arrays = {
                f"{tap} | call {call} | {i}": x
                for (p, tap), recorded in records.items()
                if p == prog
                for call, leaves in enumerate(recorded)
                for i, x in enumerate(leaves)
            }
            np.savez_compressed(args.save / f"{prog}.npz", **arrays)
        print(f"recorded arrays written to {args.save}")


if __name__ == "__main__":
    main()
