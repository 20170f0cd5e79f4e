"""Surface-vector accuracy on scenes with ground truth (thesis Ch. 4.2).

Usage:
    python experiments/bench_surface.py SCENE_DIR... [--json OUT.json] [--scale S]

For every scene: detect the multi-view edges, compute surface vectors, and score the side each
point's label was assigned to against the ground truth. A point is on a depth edge when the
centre-view GT in its 3×3 neighbourhood spans more than 0.2 px of disparity; its true side is
the one (p + 2n or p − 2n) whose GT disparity is nearer its label. Also reports the fraction of
texture-edge points (GT span < 0.05) whose depth-edge confidence is below the depth-edge
points' median (a good confidence separates the two).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update(
    "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)

import numpy as np  # noqa: E402
from scipy.ndimage import maximum_filter, minimum_filter  # noqa: E402

from mvedge_jax.edges import EdgeConfig, detect_edges  # noqa: E402
from mvedge_jax.io import load_light_field  # noqa: E402
from mvedge_jax.surface import SurfaceConfig, surface_vectors  # noqa: E402


def side_scores(edges, surf, gt: np.ndarray) -> dict:
    """Side accuracy and confidence separation of a surface result against the GT."""
    H, W = gt.shape
    v = np.asarray(edges.valid)
    x, y = np.asarray(edges.x)[v], np.asarray(edges.y)[v]
    d = np.asarray(edges.disparity)[v]
    n = np.asarray(surf.normal)[v]
    off = np.asarray(surf.offset)[v]
    xi = np.clip(np.round(x).astype(int), 0, W - 1)
    yi = np.clip(np.round(y).astype(int), 0, H - 1)
    span = (maximum_filter(gt, 3) - minimum_filter(gt, 3))[yi, xi]

    def at(sign):
        px = np.clip(np.round(x + sign * 2 * n[:, 0]).astype(int), 0, W - 1)
        py = np.clip(np.round(y + sign * 2 * n[:, 1]).astype(int), 0, H - 1)
        return gt[py, px]

    truth = np.where(np.abs(at(1) - d) <= np.abs(at(-1) - d), 1.0, -1.0)
    chosen = np.sign(np.sum(off * n, axis=1))
    depth = span > 0.2
    texture = span < 0.05
    conf = np.asarray(surf.step_response)[v]
    med = np.median(conf[depth]) if depth.any() else np.nan
    return {
        "n_points": int(v.sum()),
        "n_depth_edge_points": int(depth.sum()),
        "side_accuracy": float(np.mean(chosen[depth] == truth[depth])) if depth.any() else None,
        "texture_below_depth_median": float(np.mean(conf[texture] < med)) if depth.any() else None,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--json")
    ap.add_argument("--scale", type=float, default=None)
    args = ap.parse_args(argv)
    rows = []
    print(f"{'scene':<14}{'points':>8}{'depth-edge':>11}{'side acc.':>10}{'tex<med':>9}{'s':>7}")
    for path in args.scenes:
        lf = load_light_field(path, scale=args.scale)
        if lf.centre_gt is None:
            print(f"{lf.name:<14} (no ground truth, skipped)")
            continue
        edges = detect_edges(lf, EdgeConfig())
        fn = jax.jit(surface_vectors)
        jax.block_until_ready(fn(edges, lf.centre_view, SurfaceConfig()))
        t0 = time.perf_counter()
        surf = jax.block_until_ready(fn(edges, lf.centre_view, SurfaceConfig()))
        secs = time.perf_counter() - t0
        row = {"scene": lf.name, **side_scores(edges, surf, np.asarray(lf.centre_gt))}
        row["seconds"] = secs
        rows.append(row)
        print(
            f"{lf.name:<14}{row['n_points']:>8}{row['n_depth_edge_points']:>11}"
            f"{row['side_accuracy']:>10.3f}{row['texture_below_depth_median']:>9.3f}{secs:>7.2f}"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
