"""Accuracy and run time of the smooth 4D reconstruction (thesis Ch. 6) stage by stage.

Usage:
    python experiments/bench_reconstruct.py [--scenes backgammon antinous synthetic]
        [--input detected|oracle] [--configs default thesis] [--timing]

For every scene: the edge model comes from `detect_edges` + `surface_vectors` (``detected``)
or from ground truth (``oracle``, `oracle_edges`); then `reconstruct` runs with each named
configuration and one row is printed per (scene, input, config): MSE×100 / BadPix(0.07) of the
centre view after diffusion (``centre``), after snapping + weighted median (``sharp``) and the
final output; for the synthetic scene (ground truth in every view) also the worst and mean
per-view MSE×100. ``--timing`` adds a table of per-stage run times at the scene size
(second call, i.e. without compilation). Times are wall-clock on a shared machine: ±2×.

Configs: ``default`` = `ReconstructConfig()`; ``thesis`` = the thesis' steps only (no
photo-consistent snapping, plain mean of reprojections, no photometric confidence).
"""

from __future__ import annotations

import argparse
import functools
import os
import time
from pathlib import Path

import jax

jax.config.update(
    "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from mvedge_jax.edges import detect_edges  # noqa: E402
from mvedge_jax.io import read_hci4d  # noqa: E402
from mvedge_jax.reconstruct import (  # noqa: E402
    EpiConfig,
    FillConfig,
    ReconstructConfig,
    SharpenConfig,
    centre_disparity,
    oracle_edges,
    photo_refine,
    project_cross_hair,
    reconstruct,
    weighted_median_filter,
)
from mvedge_jax.surface import surface_vectors  # noqa: E402
from mvedge_jax.synthetic import make_scene  # noqa: E402

DATA = Path(os.environ.get("MVEDGE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
SCENES = {
    "backgammon": "hci4d/stratified/backgammon",
    "antinous": "hci4d/additional/antinous",
}
CONFIGS = {
    "default": ReconstructConfig(),
    "thesis": ReconstructConfig(
        sharpen=SharpenConfig(refine=False),
        fill=FillConfig(merge="mean"),
        epi=EpiConfig(photo_sigma=1e6),
    ),
}


def load(name: str):
    if name == "synthetic":
        return make_scene(0, size=(128, 128))
    return read_hci4d(DATA / SCENES[name])


def edge_model(lf, kind: str):
    if kind == "oracle":
        return oracle_edges(lf.centre_view, lf.centre_gt, grid=lf.grid)
    edges = detect_edges(lf)
    return edges, jax.jit(surface_vectors)(edges, lf.centre_view)


def centre_metrics(d, gt) -> str:
    e = np.asarray(d) - np.asarray(gt)
    return f"{100 * np.mean(e**2):6.2f} / {100 * np.mean(np.abs(e) > 0.07):5.1f}"


def timed(fn, *args, repeat: int = 2):
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        dt = time.perf_counter() - t
    return out, dt


def timing_table(lf, edges, surface) -> None:
    cfg = ReconstructConfig()
    U, V = lf.grid
    img = lf.centre_view
    d, t_centre = timed(jax.jit(centre_disparity), edges, surface, img, cfg)
    rows = [("centre_disparity", t_centre)]
    pos = [(U // 2, c) for c in range(V) if c != V // 2] + [
        (r, V // 2) for r in range(U) if r != U // 2
    ]
    views = jnp.stack([lf.views[r, c] for r, c in pos])
    offs = jnp.asarray([(r - U // 2, c - V // 2) for r, c in pos], jnp.float32)
    refine = jax.jit(functools.partial(photo_refine, radius=3, jump=0.2, iterations=8))
    _, t = timed(refine, d, img, views, offs)
    rows.append(("photo_refine (8 passes)", t))
    _, t = timed(jax.jit(lambda d: weighted_median_filter(d, img)), d)
    rows.append(("weighted_median_filter r=7", t))
    _, t = timed(jax.jit(project_cross_hair, static_argnums=1), d, (U, V))
    rows.append(("project_cross_hair", t))
    _, t = timed(reconstruct, lf.views, edges, surface, cfg)
    rows.append(("reconstruct (all stages)", t))
    print(f"\nrun times at {lf.size[0]}x{lf.size[1]}, {U}x{V} views (second call):")
    for name, t in rows:
        print(f"  {name:28s} {t:7.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["backgammon", "antinous", "synthetic"])
    ap.add_argument("--input", nargs="+", default=["detected"], choices=["detected", "oracle"])
    ap.add_argument("--configs", nargs="+", default=["default", "thesis"], choices=list(CONFIGS))
    ap.add_argument("--timing", action="store_true")
    args = ap.parse_args()
    header = (
        f"{'scene':11s} {'input':9s} {'config':8s} | {'centre':14s} | {'sharp':14s} | "
        f"{'final':14s} | views max/mean | s"
    )
    print("MSE×100 / BadPix(0.07) of the centre view\n" + header + "\n" + "-" * len(header))
    for name in args.scenes:
        lf = load(name)
        for kind in args.input:
            edges, surface = edge_model(lf, kind)
            for cname in args.configs:
                t = time.perf_counter()
                rec = jax.block_until_ready(reconstruct(lf.views, edges, surface, CONFIGS[cname]))
                dt = time.perf_counter() - t
                gt = lf.centre_gt
                U, V = lf.grid
                views = ""
                if name == "synthetic":
                    mse = 100 * np.mean(
                        (np.asarray(rec.disparity) - np.asarray(lf.gt_disparity)) ** 2, axis=(2, 3)
                    )
                    views = f"{mse.max():5.2f} / {mse.mean():5.2f}"
                print(
                    f"{name:11s} {kind:9s} {cname:8s} | {centre_metrics(rec.centre, gt)} | "
                    f"{centre_metrics(rec.centre_sharp, gt)} | "
                    f"{centre_metrics(rec.disparity[U // 2, V // 2], gt)} | "
                    f"{views:14s} | {dt:5.1f}",
                    flush=True,
                )
            if args.timing:
                timing_table(lf, edges, surface)


if __name__ == "__main__":
    main()
