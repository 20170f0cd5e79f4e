"""Thesis Fig. 5.4: superpixel metrics over sizes 15–40 for ours and the k-means baseline.

For every scene, ours (`superpixels`; ``ours``: projected with the EPI segments' disparity,
``ours_dense``: with the Ch. 6 disparity passed as ``disparity=``) and the k-means baseline
(`kmeans_superpixels`, the thesis' baseline: one seed grid, ``seed_candidates=1``) with our
Ch. 6 disparity (`estimate_disparity`) and with the ground-truth disparity, at every size;
``kmeans_ours_disparity_select`` is that baseline with the seed-grid choice of ours
(``seed_candidates`` of the config, default 6; not in the thesis); prints one table per
scene and the mean over scenes, and plots each metric against the size. ``--methods`` picks
a subset; ``--cache DIR`` keeps each scene's edges, surface vectors and Ch. 6 disparity
(pickled numpy) for later runs. The extra column ``depth_edge_recall`` is the centre view's
recall of ground-truth disparity jumps (not a thesis metric).

Usage:
    PYTHONPATH=. python experiments/superpixels_ch5.py --synthetic 0 1 --plot /tmp/fig54.png
    PYTHONPATH=. python experiments/superpixels_ch5.py \
        ../shared/data/hci4d/stratified/backgammon --scale 0.5 --plot /tmp/bg.png

Synthetic scenes (``--synthetic SEED ...``, 9x9 views of ``--size-px`` pixels) have per-view
object IDs and disparity, so every metric is computed; real folders with a centre-view
disparity ground truth give compactness, self-similarity error and labels per pixel.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

METRICS = (
    "self_similarity_error",
    "labels_per_pixel",
    "asa",
    "boundary_recall",
    "undersegmentation_error",
    "compactness",
    "depth_edge_recall",
)
METHODS = (
    "ours",
    "ours_dense",
    "kmeans_ours_disparity",
    "kmeans_gt_disparity",
    "kmeans_ours_disparity_select",
)


def _scenes(args):
    from mvedge_jax.io import load_light_field
    from mvedge_jax.synthetic import make_scene_with_objects

    for seed in args.synthetic:
        lf, ids = make_scene_with_objects(
            seed, grid=(9, 9), size=(args.size_px, args.size_px), n_objects=6
        )
        yield lf.name, lf, np.asarray(ids)
    for path in args.paths:
        yield path, load_light_field(path, scale=args.scale), None


def _estimate(lf, cache: str | None):
    """`estimate_disparity(lf)` as ``(edges, surface offset, disparity)``; with ``cache`` (a
    folder) read from / written to ``<cache>/<name>.pkl`` (numpy leaves)."""
    import os
    import pickle

    import jax

    from mvedge_jax.pipeline import estimate_disparity

    path = None
    if cache:
        os.makedirs(cache, exist_ok=True)
        path = os.path.join(cache, f"{lf.name}_{lf.size[0]}x{lf.size[1]}.pkl")
        if os.path.exists(path):
            with open(path, "rb") as f:
                edges, offset, disp = pickle.load(f)
            return jax.tree_util.tree_map(jax.numpy.asarray, edges), offset, disp
    est = estimate_disparity(lf)
    jax.block_until_ready(est.disparity)
    out = (est.edges, np.asarray(est.surface.offset), np.asarray(est.disparity))
    if path:
        with open(path, "wb") as f:
            pickle.dump((jax.tree_util.tree_map(np.asarray, out[0]), out[1], out[2]), f)
    return out


def depth_edge_recall(centre_labels, centre_gt, jump: float = 0.3, distance: int = 2) -> float:
    """Centre view: fraction of depth-edge pixels (a 4-neighbour whose ground-truth disparity
    differs by more than ``jump`` px per view step, both sides) with a superpixel boundary
    pixel within chessboard ``distance``."""
    from scipy.ndimage import maximum_filter

    def edge_map(a, diff):
        e = np.zeros(a.shape, bool)
        h, v = diff(a[:, 1:], a[:, :-1]), diff(a[1:], a[:-1])
        e[:, 1:] |= h
        e[:, :-1] |= h
        e[1:] |= v
        e[:-1] |= v
        return e

    depth = edge_map(np.asarray(centre_gt, np.float64), lambda a, b: np.abs(a - b) > jump)
    sp = edge_map(np.asarray(centre_labels), lambda a, b: a != b)
    near = maximum_filter(sp, size=2 * distance + 1)
    return float(near[depth].mean()) if depth.any() else float("nan")


def run_scene(lf, ids, sizes, config_kw, cache=None, methods=METHODS) -> dict:

    from mvedge_jax.metrics import superpixel_metrics
    from mvedge_jax.superpixels import SuperpixelConfig, kmeans_superpixels, superpixels

    if lf.gt_disparity is None:
        raise SystemExit(f"{lf.name}: no disparity ground truth; the metrics need it")
    edges, offset, disparity = _estimate(lf, cache)
    U, V = lf.grid
    ours_d = np.asarray(disparity[U // 2, V // 2])
    gt_c = np.asarray(lf.centre_gt)
    gt_kw = dict(gt_disparity=lf.gt_disparity, gt_mask=lf.gt_mask, gt_ids=ids)
    rows = {}
    for size in sizes:
        cfg = SuperpixelConfig(size=float(size), **config_kw)
        # the thesis' baseline clusters from SLIC's seed grid only
        base_cfg = SuperpixelConfig(size=float(size), **{**config_kw, "seed_candidates": 1})
        out = {}
        for name, dense in (("ours", None), ("ours_dense", disparity)):
            if name not in methods:
                continue
            t0 = time.perf_counter()
            res = superpixels(lf, cfg, edges=edges, surface_offset=offset, disparity=dense)
            out[name] = dict(
                superpixel_metrics(res.labels, **gt_kw),
                seconds=time.perf_counter() - t0,
                consistent_fraction=res.consistent_fraction,
                depth_edge_recall=depth_edge_recall(res.labels[U // 2, V // 2], gt_c),
            )
        for name, d, c in (
            ("kmeans_ours_disparity", ours_d, base_cfg),
            ("kmeans_gt_disparity", gt_c, base_cfg),
            ("kmeans_ours_disparity_select", ours_d, cfg),
        ):
            if name not in methods:
                continue
            t0 = time.perf_counter()
            b = kmeans_superpixels(lf, d, c)
            out[name] = dict(
                superpixel_metrics(b.labels, **gt_kw),
                seconds=time.perf_counter() - t0,
                depth_edge_recall=depth_edge_recall(b.labels[U // 2, V // 2], gt_c),
            )
        rows[size] = out
    return rows


def print_table(title: str, rows: dict) -> None:
    sizes = sorted(rows)
    first = next(iter(rows[sizes[0]].values()))
    keys = [k for k in METRICS if k in first]
    print(f"\n## {title}")
    print("| size | method | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 2) + "|")
    for s in sizes:
        for m in [m for m in METHODS if m in rows[s]]:
            vals = " | ".join(f"{rows[s][m][k]:.3f}" for k in keys)
            print(f"| {s} | {m} | {vals} |")


def mean_rows(all_rows: list[dict]) -> dict:
    sizes = sorted(all_rows[0])
    out = {}
    for s in sizes:
        out[s] = {}
        for m in [m for m in METHODS if m in all_rows[0][s]]:
            keys = set.intersection(*(set(r[s][m]) for r in all_rows))
            out[s][m] = {k: float(np.mean([r[s][m][k] for r in all_rows])) for k in keys}
    return out


def plot(rows: dict, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = sorted(rows)
    keys = [k for k in METRICS if k in next(iter(rows[sizes[0]].values()))]
    fig, axes = plt.subplots(1, len(keys), figsize=(3.6 * len(keys), 3.2), squeeze=False)
    for ax, k in zip(axes[0], keys, strict=True):
        for m, style in zip(METHODS, ("o-", "d-", "s--", "^:", "v-."), strict=True):
            if m not in rows[sizes[0]]:
                continue
            ax.plot(sizes, [rows[s][m][k] for s in sizes], style, label=m)
        ax.set_xlabel("superpixel size (px)")
        ax.set_title(k.replace("_", " "))
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("paths", nargs="*", help="light-field folders with disparity ground truth")
    ap.add_argument("--synthetic", type=int, nargs="*", default=[], help="synthetic scene seeds")
    ap.add_argument("--size-px", type=int, default=128, help="synthetic view size (pixels)")
    ap.add_argument("--scale", type=float, default=None, help="spatial scale of real folders")
    ap.add_argument("--sizes", type=int, nargs="+", default=[15, 20, 25, 30, 35, 40])
    ap.add_argument("--cache", default=None, help="folder caching edges and Ch. 6 disparity")
    ap.add_argument(
        "--methods", nargs="+", default=list(METHODS), choices=METHODS, help="methods to run"
    )
    ap.add_argument("--plot", default=None, help="PNG path of the Fig. 5.4-style plot")
    ap.add_argument("--json", default=None, help="write all numbers to this JSON file")
    ap.add_argument(
        "--set",
        nargs="*",
        default=[],
        help="SuperpixelConfig overrides, e.g. weight_d=60 centre_first=False slant_tol=0",
    )
    args = ap.parse_args()
    if not args.paths and not args.synthetic:
        ap.error("give light-field folders and/or --synthetic seeds")
    config_kw = {}
    for item in args.set:
        k, v = item.split("=", 1)
        if v in ("True", "False"):
            config_kw[k] = v == "True"
        else:
            config_kw[k] = float(v) if "." in v or "e" in v else int(v)
    results = {}
    for name, lf, ids in _scenes(args):
        t0 = time.perf_counter()
        results[name] = run_scene(
            lf, ids, args.sizes, config_kw, cache=args.cache, methods=args.methods
        )
        print_table(f"{name} ({time.perf_counter() - t0:.0f} s)", results[name])
    mean = mean_rows(list(results.values()))
    if len(results) > 1:
        print_table("mean over scenes", mean)
    if args.plot:
        plot(mean, args.plot, " + ".join(results))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"scenes": results, "mean": mean}, f, indent=1, default=float)


if __name__ == "__main__":
    main()
