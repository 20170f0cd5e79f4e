"""How far the photo-consistent disparity lies from the ground truth (a bound for any method
that matches colours, thesis Ch. 7's self-supervised loss included).

Usage:
    python experiments/photo_consistency.py SCENE_DIR... [--span 0.4] [--step 0.02]
        [--aggregate 2] [--disparity CENTRE.pfm] [--png OUT.png] [--json OUT.json]

For every GT scene: for each offset ``δ`` in ``[-span, span]`` the centre view's
occlusion-aware colour cost against the 16 other cross-hair views is evaluated with the
hypothesis ``GT + δ`` (`mvedge_jax.reconstruct.photo_cost`: half-plane means, averaged over a
colour-weighted ``(2 aggregate + 1)²`` window; the hypothesis follows the GT surface, so
slanted surfaces are matched correctly). ``δ*`` is the offset of the smallest cost. Away
from depth edges (GT span > 0.5 px in a 7×7 window; a steep floor spans 0.4), a pixel whose
``|δ*| > 0.07`` is one
where colour matching prefers a disparity that BadPix(0.07) counts as wrong. The table
gives, per band of rows (eighths of the image), the median ``δ*`` and that fraction;
``--disparity`` adds the BadPix(0.07) of a centre-view map in the same band and the share of
its bad pixels where ``|δ*| > 0.07``. ``--png`` writes ``δ*`` as a colour map (blue:
colours prefer farther than GT, red: nearer).

Measured (session 5, 2-core CPU, ``--disparity`` the ``--optimize`` centre map): on
antinous the bottom eighth of the image (the steeply slanted floor) has a median ``δ*`` of
−0.04 and ``|δ*| > 0.07`` at 47% of its pixels (16–26% in the other eighths, where it is
noise of textureless parts, median 0); the ``--optimize`` map has BadPix(0.07) 49% there,
and 65% of those bad pixels are ones where colours prefer the wrong value.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax

jax.config.update(
    "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.ndimage import maximum_filter, minimum_filter  # noqa: E402

from mvedge_jax.io import load_light_field, read_pfm  # noqa: E402
from mvedge_jax.pipeline import cross_hair_others  # noqa: E402
from mvedge_jax.reconstruct import photo_cost  # noqa: E402

BAD = 0.07


def photo_optimal_offset(lf, deltas: np.ndarray, aggregate: int) -> np.ndarray:
    """``(H, W)`` offset ``δ*`` from the GT of the smallest colour cost (centre view)."""
    views, offsets = cross_hair_others(lf.views)
    gt = jnp.asarray(lf.centre_gt, jnp.float32)
    ref = lf.centre_view

    @jax.jit
    def best(deltas):
        def one(carry, delta):
            cost = photo_cost(gt + delta, ref, views, offsets, aggregate=aggregate)
            better = cost < carry[0]
            return (jnp.where(better, cost, carry[0]), jnp.where(better, delta, carry[1])), None

        init = (jnp.full(gt.shape, jnp.inf), jnp.zeros(gt.shape))
        return jax.lax.scan(one, init, deltas)[0][1]

    return np.asarray(best(jnp.asarray(deltas, jnp.float32)))


def band_table(lf, delta: np.ndarray, disparity: np.ndarray | None) -> list[dict]:
    """Per eighth of the rows (and ``all``): pixels away from depth edges, median ``δ*``,
    fraction ``|δ*| > 0.07``, and for ``disparity`` its BadPix(0.07) and the share of its bad
    pixels with ``|δ*| > 0.07``."""
    gt = np.asarray(lf.centre_gt)
    mask = (
        np.asarray(lf.centre_gt_mask) if lf.centre_gt_mask is not None else np.ones_like(gt, bool)
    )
    span = maximum_filter(gt, size=7) - minimum_filter(gt, size=7)
    use = mask & (span <= 0.5)
    off = np.abs(delta) > BAD
    H = gt.shape[0]
    edges = np.linspace(0, H, 9).round().astype(int)
    bands = [(f"rows {a}-{b - 1}", slice(a, b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    rows = []
    for name, sl in [*bands, ("all", slice(0, H))]:
        region = np.zeros_like(use)
        region[sl] = True
        region &= use
        row = {
            "band": name,
            "pixels": int(region.sum()),
            "median_offset": float(np.median(delta[region])) if region.any() else float("nan"),
            "photo_off_pct": float(100 * off[region].mean()) if region.any() else float("nan"),
        }
        if disparity is not None and region.any():
            bad = np.abs(disparity - gt) > BAD
            row["badpix_0.07"] = float(100 * bad[region].mean())
            nbad = int((bad & region).sum())
            row["bad_photo_off_pct"] = (
                float(100 * off[bad & region].mean()) if nbad else float("nan")
            )
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("scenes", nargs="+", type=Path)
    ap.add_argument("--span", type=float, default=0.4, help="largest |δ| tried (pixels/view)")
    ap.add_argument("--step", type=float, default=0.02, help="δ step")
    ap.add_argument("--aggregate", type=int, default=2, help="cost window radius (pixels)")
    ap.add_argument("--disparity", type=Path, help="centre-view PFM to score (one scene)")
    ap.add_argument("--png", type=Path, help="write δ* as a colour map (one scene)")
    ap.add_argument("--json", type=Path, help="write the tables as JSON")
    args = ap.parse_args()
    if args.span <= 0 or args.step <= 0 or args.step > args.span:
        ap.error("need 0 < --step <= --span")
    if (args.disparity or args.png) and len(args.scenes) != 1:
        ap.error("--disparity and --png take one scene")
    deltas = np.arange(-args.span, args.span + 0.5 * args.step, args.step)
    out = {}
    for folder in args.scenes:
        lf = load_light_field(folder)
        if lf.centre_gt is None:
            raise SystemExit(f"{folder}: no ground truth; this experiment needs it")
        disparity = None
        if args.disparity is not None:
            disparity = read_pfm(args.disparity)
            if disparity.shape != tuple(lf.size):
                raise SystemExit(
                    f"{args.disparity}: shape {disparity.shape}, the scene is {tuple(lf.size)}"
                )
        delta = photo_optimal_offset(lf, deltas, args.aggregate)
        rows = band_table(lf, delta, disparity)
        out[lf.name] = rows
        print(f"\n{lf.name}: photo-optimal offset δ* from the GT (away from depth edges)")
        head = f"{'band':<14} {'pixels':>7} {'median δ*':>10} {'|δ*|>0.07':>10}"
        if disparity is not None:
            head += f" {'BadPix.07':>10} {'of bad: |δ*|>0.07':>18}"
        print(head)
        for r in rows:
            line = (
                f"{r['band']:<14} {r['pixels']:>7d} {r['median_offset']:>+10.3f} "
                f"{r['photo_off_pct']:>9.1f}%"
            )
            if "badpix_0.07" in r:
                line += f" {r['badpix_0.07']:>9.1f}% {r['bad_photo_off_pct']:>17.1f}%"
            print(line)
        if args.png is not None:
            import cv2

            t = np.clip(delta / (2 * BAD), -1.0, 1.0)
            img = np.zeros(delta.shape + (3,), np.uint8)
            img[..., 2] = (255 * np.maximum(t, 0)).astype(np.uint8)
            img[..., 0] = (255 * np.maximum(-t, 0)).astype(np.uint8)
            if not cv2.imwrite(str(args.png), img):
                raise SystemExit(f"could not write {args.png}")
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
