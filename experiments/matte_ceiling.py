"""How often the boundary matte puts an occlusion-boundary pixel on its ground-truth side, and
how often it could.

    python experiments/matte_ceiling.py [--scenes slanted,thin,wide,...] [--json OUT]

For every synthetic scene (the default scene and the variants of
`mvedge_jax.synthetic.VARIANTS`, 3×3 colour samples per pixel) the whole chain
(`estimate_disparity`, default config) runs once. On the centre view, the *boundary pixels*
are those whose colour mixes two surfaces (`render_coverage` < 1) on a ground-truth
discontinuity (5×5 range of the GT above 0.3 px per view step); a pixel's *side* is whether
its value lies above the mid-range of the GT's 5×5 window (foreground) or not, and it is on
its GT side when that agrees with the GT's own side. Printed per scene, the share (%) of the
boundary pixels on their GT side:

* ``refined``: the map `boundary_matte` receives in `sharpen` (the diffused centre map after
  the photo-consistent snapping; the matte, the plane sweep and the weighted median off);
* ``matte``: that map after `boundary_matte` with the config's settings (linear light);
* ``matte σ 0.7``: the same with the window's distance scale 0.7 px instead of the default;
* ``GT → matte``: `boundary_matte` applied to the ground-truth map itself, whose every
  boundary pixel starts on its side: the matte's own ceiling, with a perfect split of the
  window into the two surfaces (what it moves is its two-colour model's error: texture next
  to the edge biases the window's mean colours);
* ``final``: the chain's centre view;
* ``edge geometry``: a rule that does not use the colour mixture. Every detected edge point
  visible in the centre view whose surface vector points along its EPI's spatial axis
  (component above 0.3) marks the pixel it lies in; that pixel is put on the point's side
  (foreground) iff the pixel centre lies on the side the surface vector points to. Scored
  on the boundary pixels the rule reaches (``n``), next to the matte's share on the same
  pixels.

Also printed: the number of boundary pixels and the centre view's MSE×100.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from scipy.ndimage import maximum_filter, minimum_filter

from mvedge_jax.lightfield import srgb_to_linear
from mvedge_jax.pipeline import PipelineConfig, estimate_disparity
from mvedge_jax.reconstruct import sharpen
from mvedge_jax.reconstruct._reconstruct import _matte
from mvedge_jax.synthetic import VARIANTS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mixed_pixels import scenes  # noqa: E402


def matte(d: np.ndarray, guide, config, sigma: float | None = None) -> np.ndarray:
    """`boundary_matte` of ``d`` as `sharpen` runs it with ``config`` (a `ReconstructConfig`),
    optionally with another distance scale ``sigma``."""
    if sigma is not None:
        config = dataclasses.replace(
            config, sharpen=dataclasses.replace(config.sharpen, matte_sigma=sigma)
        )
    sc = config.sharpen
    return np.asarray(
        _matte(jnp.asarray(d, jnp.float32), guide, config, sc.matte_jump, sc.matte_snap)
    )


def edge_geometry_sides(edges, surface, shape) -> tuple[np.ndarray, np.ndarray]:
    """``(reached, foreground)`` ``(H, W)`` bool maps of the edge-geometry rule (module doc)."""
    H, W = shape
    x, y = np.asarray(edges.x), np.asarray(edges.y)
    axis = np.asarray(edges.direction)  # 0: horizontal EPI (x), 1: vertical EPI (y)
    off = np.asarray(surface.offset)
    use = np.array(edges.valid & edges.visible)
    along = np.take_along_axis(off, axis[:, None], 1)[:, 0]
    use &= np.abs(along) > 0.3
    col, row = np.round(x).astype(int), np.round(y).astype(int)
    use &= (col >= 0) & (col < W) & (row >= 0) & (row < H)
    pos = np.where(axis == 0, x, y)
    centre = np.where(axis == 0, col, row)
    fg = (centre - pos) * np.sign(along) > 0
    reached = np.zeros((H, W), bool)
    foreground = np.zeros((H, W), bool)
    reached[row[use], col[use]] = True
    foreground[row[use], col[use]] = fg[use]
    return reached, foreground


def score(name: str, config: PipelineConfig) -> dict:
    """The shares of the module doc for one scene."""
    ((_, lf, coverage),) = scenes([name], [3])
    U, V, H, W = lf.gt_disparity.shape
    u, v = U // 2, V // 2
    result = estimate_disparity(lf, config)
    rc = config.reconstruct
    refine_only = dataclasses.replace(
        rc, sharpen=dataclasses.replace(rc.sharpen, matte=False, sweep_steps=0, enabled=False)
    )
    views = jnp.asarray(lf.views)
    refined = np.asarray(sharpen(views, result.reconstruction.centre, refine_only))
    guide = srgb_to_linear(views[u, v])
    gt = np.asarray(lf.gt_disparity)[u, v]
    cov = np.asarray(coverage)[u, v]
    lo = minimum_filter(gt, 5, mode="nearest")
    hi = maximum_filter(gt, 5, mode="nearest")
    mid = 0.5 * (lo + hi)
    boundary = (cov < 1.0) & (hi - lo > 0.3)
    truth = gt > mid

    def share(d, where=boundary):
        return float(100 * np.mean(((d > mid) == truth)[where])) if where.any() else float("nan")

    matted = matte(refined, guide, rc)
    final = np.asarray(result.disparity)[u, v]
    reached, foreground = edge_geometry_sides(result.edges, result.surface, (H, W))
    reached &= boundary
    return {
        "boundary_pixels": int(boundary.sum()),
        "refined": share(refined),
        "matte": share(matted),
        "matte_sigma_0.7": share(matte(refined, guide, rc, sigma=0.7)),
        "gt_matte": share(matte(gt, guide, rc)),
        "final": share(final),
        "edge_geometry_n": int(reached.sum()),
        "edge_geometry": float(100 * np.mean((foreground == truth)[reached])),
        "matte_on_those": share(matted, reached),
        "centre_mse100": float(100 * np.mean((final - gt) ** 2)),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=",".join(("default", *VARIANTS)))
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    config = PipelineConfig()
    print(
        "| scene | boundary px | refined | matte | matte σ 0.7 | GT → matte | final | "
        "edge geometry (n) | matte on those | centre MSE×100 |"
    )
    print("|---" * 10 + "|")
    results = {}
    for name in args.scenes.split(","):
        t = time.perf_counter()
        r = score(name, config)
        r["seconds"] = time.perf_counter() - t
        results[name] = r
        print(
            f"| {name} | {r['boundary_pixels']} | {r['refined']:.1f} | {r['matte']:.1f} | "
            f"{r['matte_sigma_0.7']:.1f} | {r['gt_matte']:.1f} | {r['final']:.1f} | "
            f"{r['edge_geometry']:.1f} ({r['edge_geometry_n']}) | {r['matte_on_those']:.1f} | "
            f"{r['centre_mse100']:.3f} |",
            flush=True,
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)


if __name__ == "__main__":
    main()
