"""Whole-chain gradient check: reverse-mode gradient against central differences, per field.

Usage::

    python experiments/chain_gradients.py [--fields PATH,...] [--steps 1e-5,1e-6]
        [--deterministic] [--by-stage] [--json OUT.json]

The test point of ``tests/pipeline/test_pipeline_gradients.py`` (loaded from that file): the
5×5×32² synthetic light field in float64, `smooth_config` with the solvers to a 1e-12 residual,
loss = mean squared disparity error of every view. Prints, on the default JAX device:

1. the solver residuals of the forward program (compare with the 1e-12 tolerance);
2. how far the outputs of the compiled gradient program (its forward pass, returned as
   ``aux``) are from those of the compiled forward program, per output array (largest
   absolute difference and the number of elements that differ by more than 1e-9): a discrete
   choice taken differently by the two programs shows here;
3. a table per field: the gradient, the central difference at each relative step, and the
   relative error of the gradient against the difference at the smallest step.

With ``--by-stage`` it also computes the gradient as the chain rule over the three stages
compiled apart (`edges_stage`, `surface_stage`, `reconstruct_stage`, each forward and
backward its own XLA program; the stages' contributions printed one by one), and prints how
far that gradient is from the whole program's: where the stages compiled apart give the
central difference and the whole program does not, the error comes from how XLA compiles the
stages together.

Use it where the test file cannot run as it is (on a GPU, after a change to the chain) to see
which fields and which outputs disagree. With ``--deterministic`` XLA's deterministic GPU
kernels are requested first (no effect on the CPU).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TEST_FILE = ROOT / "tests" / "pipeline" / "test_pipeline_gradients.py"


def _test_module():
    """The gradient test file as a module (its test point ``_tight`` and the field list)."""
    spec = importlib.util.spec_from_file_location("chain_gradient_tests", TEST_FILE)
    if spec is None or spec.loader is None:
        raise FileNotFoundError(f"the chain's gradient tests are missing: {TEST_FILE}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def gradient_test_point() -> tuple:
    """The gradient tests' test point, in float64 (call after enabling ``jax_enable_x64``):
    ``(views, gt, config, d_max, values0, tests)``: the 5×5×32² synthetic light field and its
    ground truth, the configuration (`smooth_config`, solvers to 1e-12), the filter bank's
    ``d_max``, the differentiable fields' values and the test module."""
    import jax.numpy as jnp

    from mvedge_jax.edges import resolve_d_max
    from mvedge_jax.pipeline import get_path, smooth_config
    from mvedge_jax.synthetic import make_scene

    tests = _test_module()
    lf = make_scene(3, grid=(5, 5), size=(32, 32), disparity_range=(-1.0, 1.0), n_objects=3)
    views = jnp.asarray(lf.views, jnp.float64)
    gt = jnp.asarray(lf.gt_disparity, jnp.float64)
    config = tests._tight(smooth_config())
    d_max = resolve_d_max(config.edges, lf.disparity_range)
    values0 = {p: jnp.asarray(get_path(config, p), jnp.float64) for p in tests.SMOOTH_PATHS}
    return views, gt, config, d_max, values0, tests


def staged_gradient(
    run_stages, values0: dict, rel_step: float = 1e-6
) -> tuple[dict, dict, float, list]:
    """The loss's gradient as the chain rule over the stages compiled apart.

    ``run_stages`` is ``(edges_fn, surface_fn, loss_fn)``: ``edges_fn(values) -> EdgeSet``,
    ``surface_fn(values, edges) -> SurfaceResult``, ``loss_fn(values, edges, surface) ->
    scalar``. Each is jitted alone, so XLA fuses nothing across a stage boundary. Only the
    inexact (floating) leaves of the stages' outputs carry cotangents; the integer and
    boolean leaves (indices, validity masks) are constants of the later stages.

    Each stage's reverse pass is also checked alone, against central differences (relative
    step ``rel_step``) of the stage's scalar: the loss for the reconstruction, and the dot
    product of the stage's output with its cotangent for the surface and edge stages, per
    field. (Not along the edge set or the surface result: the later stages round positions
    to pixels, so the chain is smooth along the fields' directions only.)

    Returns:
        ``(gradient, contributions, loss, checks)``: the gradient per field; per stage name
        the part of it that flows through that stage's own use of the fields; the loss value;
        the stage checks as rows ``(stage, input, reverse pass, central difference)``, only
        those where either is non-zero.
    """
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    edges_fn, surface_fn, loss_fn = run_stages

    def split(tree):
        return eqx.partition(tree, eqx.is_inexact_array)

    # Each stage runs once: its floating outputs are the primal of its VJP, the rest is aux.
    e_float, vjp_e, e_rest = jax.vjp(jax.jit(lambda v: split(edges_fn(v))), values0, has_aux=True)

    def surface_of(v, e_f):
        return surface_fn(v, eqx.combine(e_f, e_rest))

    s_float, vjp_s, s_rest = jax.vjp(
        jax.jit(lambda v, e_f: split(surface_of(v, e_f))), values0, e_float, has_aux=True
    )

    def loss_of(v, e_f, s_f):
        return loss_fn(v, eqx.combine(e_f, e_rest), eqx.combine(s_f, s_rest))

    loss, (g_r, g_e_r, g_s) = jax.jit(jax.value_and_grad(loss_of, argnums=(0, 1, 2)))(
        values0, e_float, s_float
    )
    g_s_v, g_e_s = vjp_s(g_s)
    g_e = jax.tree_util.tree_map(lambda a, b: a + b, g_e_r, g_e_s)
    (g_e_v,) = vjp_e(g_e)
    contributions = {
        "edges": {p: float(g_e_v[p]) for p in values0},
        "surface": {p: float(g_s_v[p]) for p in values0},
        "reconstruct": {p: float(g_r[p]) for p in values0},
    }
    gradient = {p: sum(c[p] for c in contributions.values()) for p in values0}

    def dot(a, b):
        return sum(
            jnp.vdot(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
        )

    stage_scalars = {
        "reconstruct": (jax.jit(loss_of), (values0, e_float, s_float), g_r),
        "surface": (
            jax.jit(lambda v, e_f: dot(g_s, split(surface_of(v, e_f))[0])),
            (values0, e_float),
            g_s_v,
        ),
        "edges": (
            jax.jit(lambda v: dot(g_e, split(edges_fn(v))[0])),
            (values0,),
            g_e_v,
        ),
    }
    checks = []
    for stage, (scalar, args, g_fields) in stage_scalars.items():
        for path in values0:
            h = rel_step * max(abs(float(values0[path])), 1e-2)
            up, down = dict(values0), dict(values0)
            up[path] = values0[path] + h
            down[path] = values0[path] - h
            fd = (float(scalar(up, *args[1:])) - float(scalar(down, *args[1:]))) / (2 * h)
            ad = float(g_fields[path])
            if ad != 0.0 or fd != 0.0:
                checks.append((stage, path, ad, fd))
    return gradient, contributions, float(loss), checks


def check(fields: list[str] | None, steps: list[float], by_stage: bool = False) -> dict:
    """Run the check; returns the measurements as a JSON-ready dict."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from mvedge_jax.pipeline import (
        edges_stage,
        estimate_disparity_arrays,
        reconstruct_stage,
        replace_paths,
        surface_stage,
    )

    views, gt, config, d_max, values0, tests = gradient_test_point()
    paths = list(tests.SMOOTH_PATHS) if not fields else fields
    unknown = sorted(set(paths) - set(tests.SMOOTH_PATHS))
    if unknown:
        raise ValueError(f"not differentiable fields of the chain: {unknown}")

    def run(values):
        c = replace_paths(config, values)
        return estimate_disparity_arrays(views, c, key=jax.random.key(0), d_max=d_max)

    def loss_aux(values):
        out = run(values)
        return jnp.mean((out.disparity - gt) ** 2), out

    t0 = time.perf_counter()
    forward = jax.jit(loss_aux)
    value_f, out_f = forward(values0)
    jax.block_until_ready(out_f)
    print(f"forward program: {time.perf_counter() - t0:.1f} s (with compilation)", flush=True)
    t0 = time.perf_counter()
    (value_g, out_g), grad = jax.jit(jax.value_and_grad(loss_aux, has_aux=True))(values0)
    jax.block_until_ready(grad)
    print(f"gradient program: {time.perf_counter() - t0:.1f} s (with compilation)", flush=True)

    report: dict = {
        "device": str(jax.devices()[0]),
        "loss_forward": float(value_f),
        "loss_gradient_program": float(value_g),
        "residuals": {},
        "program_differences": {},
        "fields": {},
    }
    print(f"\nloss: forward {float(value_f):.15g}, gradient program {float(value_g):.15g}")
    print("\nsolver residuals of the forward program:")
    for key, leaf in jax.tree_util.tree_flatten_with_path(out_f)[0]:
        name = jax.tree_util.keystr(key)
        if "resid" in name:
            report["residuals"][name] = np.asarray(leaf).tolist()
            print(f"  {name}: {np.asarray(leaf)}")
    print("\noutputs that differ between the two programs (largest |difference|, count > 1e-9):")
    pairs = zip(
        jax.tree_util.tree_flatten_with_path(out_f)[0],
        jax.tree_util.tree_leaves(out_g),
        strict=True,
    )
    for (key, a), b in pairs:
        a, b = np.asarray(a), np.asarray(b)
        if a.dtype.kind not in "fiub" or a.size == 0:
            continue
        diff = np.abs(a.astype(np.float64) - b.astype(np.float64))
        largest, count = float(np.nanmax(diff)), int(np.sum(diff > 1e-9))
        name = jax.tree_util.keystr(key)
        report["program_differences"][name] = {"largest": largest, "count": count}
        if count:
            print(f"  {name}: {largest:.3e} ({count} of {a.size})")
    if not any(d["count"] for d in report["program_differences"].values()):
        print("  none")

    def f(values):
        return forward(values)[0]  # the compiled forward program, not a second one

    head = "| field | gradient | " + " | ".join(f"difference ({s:g})" for s in steps)
    print("\n" + head + " | relative error |")
    print("|---" * (len(steps) + 3) + "|")
    for path in paths:
        x = float(values0[path])
        row = {"gradient": float(grad[path])}
        for step in steps:
            h = step * max(abs(x), 1e-2)
            up, down = dict(values0), dict(values0)
            up[path] = values0[path] + h
            down[path] = values0[path] - h
            row[f"{step:g}"] = (float(f(up)) - float(f(down))) / (2 * h)
        fd = row[f"{min(steps):g}"]
        ad = row["gradient"]
        row["relative_error"] = abs(ad - fd) / max(abs(ad), abs(fd), 1e-300)
        report["fields"][path] = row
        cells = " | ".join(f"{row[f'{s:g}']:.6e}" for s in steps)
        print(f"| {path} | {ad:.6e} | {cells} | {row['relative_error']:.1e} |", flush=True)
    if by_stage:
        key = jax.random.key(0)
        stages = (
            lambda v: edges_stage(views, replace_paths(config, v), key=key, d_max=d_max),
            lambda v, e: surface_stage(views, e, replace_paths(config, v)),
            lambda v, e, s: jnp.mean(
                (reconstruct_stage(views, e, s, replace_paths(config, v)).disparity - gt) ** 2
            ),
        )
        t0 = time.perf_counter()
        gradient, contributions, loss, checks = staged_gradient(stages, values0, min(steps))
        print(
            f"\nstages compiled apart: {time.perf_counter() - t0:.1f} s (with compilation); "
            f"loss {loss:.15g}"
        )
        report["by_stage"] = {"loss": loss, "gradient": gradient, "contributions": contributions}
        print(
            "\n| field | whole program | stages apart | edges | surface | reconstruct "
            "| difference of the smallest step | stages apart vs difference |"
        )
        print("|---" * 8 + "|")
        for path in paths:
            fd = report["fields"][path][f"{min(steps):g}"]
            g = gradient[path]
            err = abs(g - fd) / max(abs(g), abs(fd), 1e-300)
            report["by_stage"].setdefault("relative_error", {})[path] = err
            parts = " | ".join(f"{contributions[s][path]:.6e}" for s in contributions)
            print(
                f"| {path} | {float(grad[path]):.6e} | {g:.6e} | {parts} | {fd:.6e} | {err:.1e} |",
                flush=True,
            )
        report["by_stage"]["checks"] = [list(row) for row in checks]
        print(
            "\neach stage's reverse pass alone against central differences of its scalar\n"
            "| stage | input | reverse pass | difference | relative error |\n|---|---|---|---|---|"
        )
        for stage, name, ad, fd in checks:
            err = abs(ad - fd) / max(abs(ad), abs(fd), 1e-300)
            print(f"| {stage} | {name} | {ad:.6e} | {fd:.6e} | {err:.1e} |", flush=True)
    return report


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fields", default="", help="comma-separated field paths (default: all)")
    parser.add_argument("--steps", default="1e-5,1e-6", help="relative steps of the differences")
    parser.add_argument(
        "--deterministic",
        action="store_true",
        help="request XLA's deterministic GPU kernels (no effect on the CPU)",
    )
    parser.add_argument(
        "--by-stage",
        action="store_true",
        help="also the gradient over the three stages compiled apart, per stage",
    )
    parser.add_argument("--json", type=Path, default=None, help="write the measurements here")
    args = parser.parse_args(argv)
    if args.json is not None and args.json.exists():
        sys.exit(f"{args.json} exists; not overwritten")
    if args.deterministic:
        from mvedge_jax import request_deterministic_gpu

        request_deterministic_gpu()
    fields = [p for p in args.fields.split(",") if p]
    steps = [float(s) for s in args.steps.split(",") if s]
    if not steps or any(s <= 0 for s in steps):
        parser.error(f"--steps needs positive relative steps, got {args.steps!r}")
    report = check(fields, steps, by_stage=args.by_stage)
    if args.json is not None:
        if args.json.exists():
            sys.exit(f"{args.json} exists; not overwritten")
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
