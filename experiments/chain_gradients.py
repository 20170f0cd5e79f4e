"""Whole-chain gradient check: reverse-mode gradient against central differences, per field.

Usage::

    python experiments/chain_gradients.py [--fields PATH,...] [--steps 1e-5,1e-6]
        [--deterministic] [--json OUT.json]

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


def check(fields: list[str] | None, steps: list[float]) -> dict:
    """Run the check; returns the measurements as a JSON-ready dict."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from mvedge_jax.edges import resolve_d_max
    from mvedge_jax.pipeline import (
        estimate_disparity_arrays,
        get_path,
        replace_paths,
        smooth_config,
    )
    from mvedge_jax.synthetic import make_scene

    tests = _test_module()
    paths = list(tests.SMOOTH_PATHS) if not fields else fields
    unknown = sorted(set(paths) - set(tests.SMOOTH_PATHS))
    if unknown:
        raise ValueError(f"not differentiable fields of the chain: {unknown}")
    lf = make_scene(3, grid=(5, 5), size=(32, 32), disparity_range=(-1.0, 1.0), n_objects=3)
    views = jnp.asarray(lf.views, jnp.float64)
    gt = jnp.asarray(lf.gt_disparity, jnp.float64)
    config = tests._tight(smooth_config())
    d_max = resolve_d_max(config.edges, lf.disparity_range)
    values0 = {p: jnp.asarray(get_path(config, p), jnp.float64) for p in tests.SMOOTH_PATHS}

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
    parser.add_argument("--json", type=Path, default=None, help="write the measurements here")
    args = parser.parse_args(argv)
    if args.deterministic:
        from mvedge_jax import request_deterministic_gpu

        request_deterministic_gpu()
    fields = [p for p in args.fields.split(",") if p]
    steps = [float(s) for s in args.steps.split(",") if s]
    if not steps or any(s <= 0 for s in steps):
        parser.error(f"--steps needs positive relative steps, got {args.steps!r}")
    report = check(fields, steps)
    if args.json is not None:
        if args.json.exists():
            sys.exit(f"{args.json} exists; not overwritten")
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
