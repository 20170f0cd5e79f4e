"""Whole-chain benchmark of the main job: `estimate_disparity` (and `optimize_disparity`).

Usage::

    python experiments/bench_chain.py [SCENE ...] [--repeat 3] [--optimize] [--deterministic]
        [--json OUT.json]

``SCENE`` is a light-field folder (default: HCI backgammon under ``$MVEDGE_DATA`` or
``../shared/data``) or ``synthetic`` (the embedded default light field, 9×9×160²). For every
scene, in one process: a first call of `estimate_disparity` (tracing, compilation and run),
then ``--repeat`` timed calls with the compiled stages; with ``--optimize`` also a first and a
second call of `optimize_disparity` on the last result (thesis Ch. 7; the second one reuses
the compiled step). With ``--deterministic`` XLA's deterministic GPU kernels are requested
first (`mvedge_jax.request_deterministic_gpu`; run it with and without on the same GPU to
measure their cost). Prints one table row per scene: the device, the first call's wall and
compile seconds, the medians (and ranges) of the timed calls per stage (``edges``,
``surface``, ``reconstruct``) and in all, the centre view's MSE×100 and BadPix(0.07) against
the ground truth when there is one, and the ``--optimize`` walls. Times are wall seconds
after `jax.block_until_ready`; compare them only between rows of one run on one machine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MVEDGE_DATA", ROOT.parent / "shared" / "data"))
STAGES = ("edges", "surface", "reconstruct")


def _load(scene: str):
    from mvedge_jax.io import load_light_field
    from mvedge_jax.synthetic import default_light_field

    if scene == "synthetic":
        return default_light_field()
    return load_light_field(scene)


def bench_scene(scene: str, repeat: int, optimize: bool) -> dict:
    """Time the chain on one scene; returns the row of the table as a dict."""
    import jax
    import numpy as np

    from mvedge_jax.pipeline import (
        PipelineConfig,
        device_info,
        estimate_disparity,
        optimize_disparity,
        quality_metrics,
    )

    lf = _load(scene)
    config = PipelineConfig()
    t0 = time.perf_counter()
    result = estimate_disparity(lf, config)
    jax.block_until_ready(result.disparity)
    first = time.perf_counter() - t0
    device = device_info()
    row: dict = {
        "scene": lf.name,
        "device": device["device"],
        "deterministic": device["deterministic"],
        "first_call_s": first,
        "compile_s": result.compile_seconds,
    }
    per_stage: dict[str, list[float]] = {s: [] for s in STAGES}
    totals: list[float] = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = estimate_disparity(lf, config)
        jax.block_until_ready(result.disparity)
        totals.append(time.perf_counter() - t0)
        for s in STAGES:
            per_stage[s].append(result.seconds_per_stage[s])
    row["stage_median_s"] = {s: statistics.median(v) for s, v in per_stage.items()}
    row["total_s"] = totals
    row["total_median_s"] = statistics.median(totals)
    row["metrics"] = quality_metrics(lf, np.asarray(result.disparity))
    if optimize:
        walls = []
        for _ in range(2):
            t0 = time.perf_counter()
            refined, _ = optimize_disparity(lf, result, config)
            jax.block_until_ready(refined.disparity)
            walls.append(time.perf_counter() - t0)
        row["optimize_first_s"], row["optimize_second_s"] = walls
        row["optimize_metrics"] = quality_metrics(lf, np.asarray(refined.disparity))
    return row


def _score(metrics: dict) -> str:
    if "mse_x100" not in metrics:
        return "—"
    return f"{metrics['mse_x100']:.2f} / {metrics['badpix_0.07']:.2f}"


def print_table(rows: list[dict]) -> None:
    """Print the rows as a Markdown table."""
    head = (
        "| scene | device (deterministic) | first call (compile) s | edges | surface | reconstruct "
        "| total median (range) s | MSE×100 / BadPix(0.07) | --optimize 1st / 2nd s "
        "| optimized MSE×100 / BadPix(0.07) |"
    )
    print(head)
    print("|" + "---|" * head.count(" | ") + "---|")
    for r in rows:
        st = r["stage_median_s"]
        opt = (
            f"{r['optimize_first_s']:.1f} / {r['optimize_second_s']:.1f}"
            if "optimize_first_s" in r
            else "—"
        )
        print(
            f"| {r['scene']} | {r['device']} ({'yes' if r['deterministic'] else 'no'}) "
            f"| {r['first_call_s']:.1f} ({r['compile_s']:.1f}) "
            f"| {st['edges']:.2f} | {st['surface']:.2f} | {st['reconstruct']:.2f} "
            f"| {r['total_median_s']:.2f} ({min(r['total_s']):.2f}–{max(r['total_s']):.2f}) "
            f"| {_score(r['metrics'])} | {opt} | {_score(r.get('optimize_metrics', {}))} |"
        )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=None)
    parser.add_argument("--repeat", type=int, default=3, help="timed calls after the first")
    parser.add_argument("--optimize", action="store_true", help="also time optimize_disparity")
    parser.add_argument(
        "--deterministic",
        action="store_true",
        help="request XLA's deterministic GPU kernels (no effect on the CPU)",
    )
    parser.add_argument("--json", type=Path, default=None, help="write the rows as JSON here")
    args = parser.parse_args(argv)
    if args.deterministic:
        from mvedge_jax import request_deterministic_gpu

        request_deterministic_gpu()  # before the stage packages start the backend
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    if args.json is not None and args.json.exists():
        parser.error(f"{args.json} exists; not overwriting it")
    scenes = args.scenes or [str(DATA / "hci4d" / "stratified" / "backgammon")]
    for s in scenes:
        if s != "synthetic" and not Path(s).is_dir():
            parser.error(f"scene folder not found: {s}")
    rows = []
    for s in scenes:
        print(f"[bench_chain] {s} ...", flush=True)
        rows.append(bench_scene(s, args.repeat, args.optimize))
    print_table(rows)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
