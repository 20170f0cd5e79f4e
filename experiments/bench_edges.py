"""Benchmark of multi-view edge detection (thesis Ch. 4.1): accuracy step by step, and speed.

Usage:
    python experiments/bench_edges.py SCENE_DIR... [--json OUT.json] [--overlays DIR]
        [--steps/--no-steps] [--d-max FLOAT] [--views N]

For every scene the edge detector runs once per step of the table (each step adds one stage to
the previous configuration, so each stage's effect is visible), then once more with the default
`EdgeConfig`. Scenes with ground truth get per-point errors: the minimum |d - GT| over the GT's
3x3 neighbourhood of the point's pixel. Times are measured after compilation (second call) on
whatever machine runs this; compile time is reported separately, peak memory is the process's
peak resident set size.

The JSON output is a list with one object per scene (the default configuration): ``scene``,
``n_points``, ``coverage`` (fraction of centre-view pixels holding a point), ``median_abs_err``,
``frac_within_0_1``, ``seconds``, ``compile_seconds``, plus ``steps`` (the same numbers for each
row of the table) and ``peak_rss_mb``.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
import warnings
from pathlib import Path

import click
import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mvedge_jax.edges import (  # noqa: E402
    EdgeConfig,
    FilterConfig,
    detect_edges,
    point_errors,
    render_overlay,
)
from mvedge_jax.pipeline import PipelineConfig, with_values  # noqa: E402


def steps(default: EdgeConfig) -> list[tuple[str, dict]]:
    """(name, EdgeConfig overrides by dotted path, e.g. ``"label.nms"``) of each row of the
    table.

    The first rows add the stages of the default configuration one at a time (thesis-style
    detection first); the last rows add each remaining optional stage to the default alone.
    """
    off = {"outliers.enabled": False, "refine.trilateral": False}
    thesis = {
        **off,
        "label.nms": True,
        "label.lambda_frac": 0.2,
        "label.min_ratio": 0.0,
        "label.subpixel": "none",
    }
    dense = {**off, "label.nms": False, "label.lambda_frac": 0.0, "label.subpixel": "variance"}
    variance = {**thesis, "label.subpixel": "variance"}
    return [
        ("raw: Alg.1 + NMS + line fit (λ=0.2h)", dict(thesis)),
        ("+ parabolic sub-pixel", {**thesis, "label.subpixel": "parabolic"}),
        ("+ colour-variance search", variance),
        ("+ colour std filter (0.03)", {**variance, "label.max_colour_std": 0.03}),
        ("dense candidates, λ=0, no filter", {**dense, "label.min_ratio": 0.0}),
        ("+ distinct-minimum filter (ratio 2)", dict(dense)),
        ("+ trilateral filter (eq 4.6) = default", {**dense, "refine.trilateral": True}),
        ("default + outlier rejection (4.1.3)", {"outliers.enabled": True}),
        ("default + gradient alignment (eq 4.3)", {"refine.gradient_alignment": True}),
        ("default + drop invisible (eq 4.4)", {"refine.drop_invisible": True}),
        ("default + entropy search (eq 4.5)", {"refine.entropy_search": True}),
        ("default + multi-scale (4.1.4)", {"refine.multiscale": True}),
        ("default, trilateral radius 10", {"refine.trilateral_radius": 10}),
    ]


def evaluate(lf, edges) -> dict:
    H, W = lf.size
    v = np.asarray(edges.valid)
    n = int(v.sum())
    xi = np.clip(np.round(np.asarray(edges.x)[v]).astype(int), 0, W - 1)
    yi = np.clip(np.round(np.asarray(edges.y)[v]).astype(int), 0, H - 1)
    cov = np.zeros((H, W), bool)
    cov[yi, xi] = True
    out = {"n_points": n, "coverage": float(cov.mean()), "n_dropped": int(edges.n_dropped)}
    dirs = np.asarray(edges.direction)
    out["n_horizontal"] = int((v & (dirs == 0)).sum())
    out["n_vertical"] = int((v & (dirs == 1)).sum())
    out["n_visible"] = int((v & np.asarray(edges.visible)).sum())
    if lf.centre_gt is not None:
        err = np.asarray(point_errors(edges, lf.centre_gt, lf.centre_gt_mask))
        for tag, sel in (("", v), ("_h", v & (dirs == 0)), ("_v", v & (dirs == 1))):
            e = err[sel]
            e = e[np.isfinite(e)]
            out["median_abs_err" + tag] = float(np.median(e)) if e.size else None
            out["frac_within_0_1" + tag] = float(np.mean(e < 0.1)) if e.size else None
    return out


def run_config(lf, cfg: EdgeConfig, key) -> tuple[object, float, float, float]:
    """Run twice; returns (edges, seconds of the 2nd run, compile seconds, CPU seconds of the
    2nd run). The CPU time (all threads) is less sensitive to a shared machine's load."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        e = detect_edges(lf, cfg, key=key)
        jax.block_until_ready(e)
        t1 = time.perf_counter()
        c1 = time.process_time()
        e = detect_edges(lf, cfg, key=key)
        jax.block_until_ready(e)
    t2 = time.perf_counter()
    cpu = time.process_time() - c1
    compile_s = max(0.0, (t1 - t0) - (t2 - t1))
    return e, t2 - t1, compile_s, cpu


def fmt(r: dict) -> str:
    def f(k, spec):
        v = r.get(k)
        return format(v, spec) if isinstance(v, (int, float)) else "-".rjust(len(format(0, spec)))

    return (
        f"{f('n_points', '8d')} {f('n_horizontal', '7d')} {f('n_vertical', '7d')} "
        f"{f('coverage', '6.3f')} {f('median_abs_err', '8.4f')} {f('frac_within_0_1', '6.3f')} "
        f"{f('median_abs_err_h', '8.4f')} {f('median_abs_err_v', '8.4f')} "
        f"{f('seconds', '6.1f')} {f('cpu_seconds', '6.1f')} {f('compile_seconds', '6.1f')}"
    )


HEADER = (
    f"{'step':40s} {'points':>8s} {'horiz':>7s} {'vert':>7s} {'cover':>6s} {'med err':>8s} "
    f"{'<0.1':>6s} {'med H':>8s} {'med V':>8s} {'sec':>6s} {'cpu s':>6s} {'comp':>6s}"
)


@click.command()
@click.argument("scenes", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False))
@click.option("--json", "json_out", type=click.Path(dir_okay=False), default=None)
@click.option(
    "--overlays",
    type=click.Path(file_okay=False),
    default=None,
    help="folder for overlay PNGs of the default configuration",
)
@click.option("--steps/--no-steps", "with_steps", default=True, help="run the step table")
@click.option("--d-max", type=float, default=None, help="bank half-range for scenes without one")
@click.option("--views", type=int, default=None, help="central angular crop (e.g. 7 for Lytro)")
@click.option(
    "--cache/--no-cache",
    default=False,
    help="use the persistent compilation cache (.jax_cache); off by default so that "
    "compile_seconds is the real compile time",
)
def main(scenes, json_out, overlays, with_steps, d_max, views, cache):
    if cache:
        jax.config.update(
            "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache")
        )
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    try:
        from mvedge_jax.io import load_light_field
    except ImportError:  # the I/O team's loader is not there yet
        from mvedge_jax.io import read_hci4d as load_light_field

        views = None
    key = jax.random.key(0)
    results = []
    for scene in scenes:
        kw = {"views": views} if views else {}
        lf = load_light_field(scene, **kw)
        default = (
            EdgeConfig()
            if (d_max is None or lf.disparity_range)
            else EdgeConfig(filter=FilterConfig(d_max=d_max))
        )
        U, V = lf.grid
        H, W = lf.size
        print(f"\n=== {lf.name}: {U}x{V} views of {H}x{W}, disparity range {lf.disparity_range}")
        print(HEADER)
        rows = []
        if with_steps:
            for name, over in steps(default):
                cfg = replaced(default, over)
                e, sec, comp, cpu = run_config(lf, cfg, key)
                r = {"step": name, **evaluate(lf, e), "seconds": sec, "compile_seconds": comp}
                r["cpu_seconds"] = cpu
                rows.append(r)
                print(f"{name:40s} {fmt(r)}", flush=True)
        e, sec, comp, cpu = run_config(lf, default, key)
        r = {"scene": lf.name, **evaluate(lf, e), "seconds": sec, "compile_seconds": comp}
        r["cpu_seconds"] = cpu
        r["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        r["steps"] = rows
        print(f"{'DEFAULT EdgeConfig()':40s} {fmt(r)}   peak RSS {r['peak_rss_mb']:.0f} MB")
        results.append(r)
        if overlays:
            import cv2

            os.makedirs(overlays, exist_ok=True)
            img = render_overlay(e, lf.centre_view)
            path = os.path.join(overlays, f"edges_{lf.name}.png")
            cv2.imwrite(path, img[..., ::-1])
            print(f"overlay: {path}")
    if json_out:
        with open(json_out, "w") as f:
            json.dump(results, f, indent=1)
        print(f"wrote {json_out}")


def replaced(cfg: EdgeConfig, overrides: dict) -> EdgeConfig:
    """A copy of ``cfg`` with the fields at the dotted paths of ``overrides`` (relative to
    `EdgeConfig`, e.g. ``"label.nms"``) replaced and re-validated (`with_values`)."""
    values = {f"edges.{path}": value for path, value in overrides.items()}
    return with_values(PipelineConfig(edges=cfg), values).edges


if __name__ == "__main__":
    main()
