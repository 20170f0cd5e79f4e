"""Surface-vector accuracy on scenes with ground truth (thesis Ch. 4.2).

Usage:
    python experiments/bench_surface.py SCENE_DIR... [--json OUT.json] [--scale S]
        [--points detected|gt|both]

For every scene: take edge points — ``detected``: `mvedge_jax.edges.detect_edges`; ``gt``:
pixels whose centre-view CIELAB/100 gradient exceeds 0.08, labelled with the GT disparity at
the pixel — compute surface vectors, and score the side each point's label was assigned to
against the ground truth. A point is on a depth edge when the centre-view GT in its 3×3
neighbourhood spans more than 0.2 px of disparity; its true side is the one (p + 2n or
p − 2n) whose GT disparity is nearer its label. Also reports, for texture-edge points (GT
span < 0.05), the fraction whose depth-edge confidence (the map, sampled at the point) and
whose λ_e are below the depth-edge points' median (a good confidence separates the two).
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

from mvedge_jax.edges import EdgeConfig, EdgeSet, detect_edges  # noqa: E402
from mvedge_jax.io import load_light_field  # noqa: E402
from mvedge_jax.lightfield import rgb_to_lab  # noqa: E402
from mvedge_jax.surface import SurfaceConfig, surface_vectors  # noqa: E402


def gt_edge_set(centre: np.ndarray, gt: np.ndarray, threshold: float = 0.08) -> EdgeSet:
    """Points at strong centre-view colour edges, labelled with the GT disparity there."""
    import jax.numpy as jnp

    lab = np.asarray(rgb_to_lab(jnp.asarray(centre))) / 100.0
    gx = np.zeros(lab.shape[:2])
    gy = np.zeros(lab.shape[:2])
    gx[:, 1:-1] = np.linalg.norm(lab[:, 2:] - lab[:, :-2], axis=-1) / 2
    gy[1:-1] = np.linalg.norm(lab[2:] - lab[:-2], axis=-1) / 2
    ys, xs = np.nonzero(np.hypot(gx, gy) > threshold)
    n = xs.size
    empty = EdgeSet.empty(n)
    return EdgeSet(
        x=jnp.asarray(xs, jnp.float32),
        y=jnp.asarray(ys, jnp.float32),
        disparity=jnp.asarray(gt[ys, xs], jnp.float32),
        confidence=jnp.ones(n, jnp.float32),
        visible=jnp.ones(n, bool),
        lab=empty.lab,
        direction=empty.direction,
        intercepts=empty.intercepts,
        valid=jnp.ones(n, bool),
        n_dropped=empty.n_dropped,
    )


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
    lam_e = np.asarray(surf.step_response)[v]
    conf = np.asarray(surf.depth_edge_confidence)[yi, xi]

    def below(score):
        if not depth.any() or not texture.any():
            return None
        return float(np.mean(score[texture] < np.median(score[depth])))

    return {
        "n_points": int(v.sum()),
        "n_depth_edge_points": int(depth.sum()),
        "n_texture_edge_points": int(texture.sum()),
        "side_accuracy": float(np.mean(chosen[depth] == truth[depth])) if depth.any() else None,
        "texture_conf_below_depth_median": below(conf),
        "texture_lambda_e_below_depth_median": below(lam_e),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--json")
    ap.add_argument("--scale", type=float, default=None)
    ap.add_argument("--points", choices=("detected", "gt", "both"), default="both")
    args = ap.parse_args(argv)
    kinds = ("detected", "gt") if args.points == "both" else (args.points,)
    rows = []
    print(
        f"{'scene':<12}{'points':>9}{'n':>8}{'depth-edge':>11}{'side acc.':>10}"
        f"{'conf<med':>9}{'λe<med':>8}{'s':>7}"
    )
    fn = jax.jit(surface_vectors)
    for path in args.scenes:
        lf = load_light_field(path, scale=args.scale)
        if lf.centre_gt is None:
            print(f"{lf.name:<12} (no ground truth, skipped)")
            continue
        gt = np.asarray(lf.centre_gt)
        for kind in kinds:
            if kind == "detected":
                edges = detect_edges(lf, EdgeConfig())
            else:
                edges = gt_edge_set(np.asarray(lf.centre_view), gt)
            jax.block_until_ready(fn(edges, lf.centre_view, SurfaceConfig()))
            t0 = time.perf_counter()
            surf = jax.block_until_ready(fn(edges, lf.centre_view, SurfaceConfig()))
            secs = time.perf_counter() - t0
            row = {"scene": lf.name, "points": kind, **side_scores(edges, surf, gt)}
            row["seconds"] = secs
            rows.append(row)
            print(
                f"{lf.name:<12}{kind:>9}{row['n_points']:>8}{row['n_depth_edge_points']:>11}"
                f"{row['side_accuracy']:>10.3f}{row['texture_conf_below_depth_median']:>9.3f}"
                f"{row['texture_lambda_e_below_depth_median']:>8.3f}{secs:>7.2f}",
                flush=True,
            )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
