"""Where the synthetic scenes' error is, by sub-pixel coverage; and what no method can know.

    python experiments/mixed_pixels.py [--scenes default,thin,...] [--supersample 2,3]
        [--json OUT]

1. For every synthetic scene (the default scene at its own render; the variants of
   `mvedge_jax.synthetic.VARIANTS` at each ``--supersample``), the whole chain
   (`estimate_disparity`, default config) runs once and every view's squared error is split
   by the coverage of the pixel's ground-truth surface (`render_coverage`: the share of the
   pixel's colour samples that see the surface at its centre): ``inside`` (1), ``majority``
   (between 0.5 and 1), ``tie`` (exactly 0.5: the two surfaces mixed half and half, so which
   one the centre sees is not in the pixel's colour) and ``minority`` (below 0.5: corners and
   junctions). Printed per scene: MSE×100 over all views, the worst view's, the centre view's,
   and the all-views MSE×100 that each class contributes, with its share of the pixels.
2. The textureless variant's floor is one colour and its outline does not depend on its
   slope: re-rendered with the floor's slope (0.012 per pixel) set to 0 and to 0.024 (same
   disparity at its top edge), every view is bit-identical. Any method then gives one map for
   the three scenes, and for two scenes with ground truths ``g1``, ``g2`` and one map ``m``,
   ``max(MSE(m, g1), MSE(m, g2)) >= MSE(g1, g2) / 4``. Printed: the largest image difference
   and the MSE×100 between the ground truths.
3. The same maps' squared error split by what the centre view sees (`centre_visibility`):
   ``seen`` (the pixel's surface point is in the centre view: the projection of the centre
   map can carry it), ``occluded`` (inside the centre frame but behind a nearer surface
   there: a disocclusion) and ``outside`` (beyond the centre frame). Printed per scene: each
   class's contribution to the all-views MSE×100 (and its share of the pixels, %), the
   worst view with its own split, and how many of its pixels hold half and 90 % of its
   squared error.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from mvedge_jax.pipeline import PipelineConfig, estimate_disparity
from mvedge_jax.synthetic import (
    VARIANTS,
    default_light_field,
    default_surfaces,
    render_coverage,
    render_surfaces,
    variant_scene,
    variant_surfaces,
)

CLASSES = {
    "inside": lambda c: c == 1.0,
    "majority": lambda c: (c > 0.5) & (c < 1.0),
    "tie": lambda c: c == 0.5,
    "minority": lambda c: c < 0.5,
}
DEFAULT_SUPERSAMPLE = 3  # `default_light_field`
VISIBILITY = ("seen", "occluded", "outside")
# Largest difference (pixels per view step) between a pixel's ground truth and that of a
# centre-view pixel next to where it lands for the centre view to see the same surface.
VISIBILITY_TOLERANCE = 0.3


def split_by_coverage(d: np.ndarray, gt: np.ndarray, cov: np.ndarray) -> dict:
    """All-views MSE×100, worst and centre view, and each coverage class's contribution to
    the all-views MSE×100 (and its share of the pixels, %), of maps ``(U, V, H, W)``."""
    e = (d - gt) ** 2
    per_view = 100 * e.mean(axis=(2, 3))
    U, V = per_view.shape
    out = {
        "all": float(per_view.mean()),
        "worst": float(per_view.max()),
        "centre": float(per_view[U // 2, V // 2]),
        "badpix07": float(100 * np.mean(np.abs(d - gt) > 0.07)),
    }
    for name, test in CLASSES.items():
        m = test(cov)
        out[name] = (float(100 * e[m].sum() / e.size), float(100 * m.mean()))
    return out


def centre_visibility(gt: np.ndarray) -> np.ndarray:
    """Which pixels of every view the centre view sees, from the ground truth ``(U, V, H, W)``.

    The point of pixel ``x`` of view ``(r, c)``, of disparity ``g``, lies at ``x + (r − rc,
    c − cc)·g`` (row, column) in the centre view (the SPEC's sign). Returns ``(U, V, H, W)``
    int8: 0 (``seen``) where one of the four centre pixels around that position holds a
    ground truth within `VISIBILITY_TOLERANCE` of ``g``, 2 (``outside``) where the position
    lies more than half a pixel beyond the centre frame, 1 (``occluded``) elsewhere.
    """
    U, V, H, W = gt.shape
    centre = gt[U // 2, V // 2]
    yy, xx = np.mgrid[0:H, 0:W]
    out = np.empty(gt.shape, np.int8)
    for r in range(U):
        for c in range(V):
            g = gt[r, c]
            fy, fx = yy + (r - U // 2) * g, xx + (c - V // 2) * g
            seen = np.zeros((H, W), bool)
            for oy in (0, 1):
                for ox in (0, 1):
                    ys, xs = np.floor(fy).astype(int) + oy, np.floor(fx).astype(int) + ox
                    ok = (ys >= 0) & (ys < H) & (xs >= 0) & (xs < W)
                    near = np.abs(centre[np.clip(ys, 0, H - 1), np.clip(xs, 0, W - 1)] - g)
                    seen |= ok & (near < VISIBILITY_TOLERANCE)
            beyond = (fy < -0.5) | (fy > H - 0.5) | (fx < -0.5) | (fx > W - 0.5)
            out[r, c] = np.where(seen, 0, np.where(beyond, 2, 1))
    return out


def split_by_visibility(d: np.ndarray, gt: np.ndarray) -> dict:
    """Each `VISIBILITY` class's contribution to the all-views MSE×100 (and its share of the
    pixels, %) of maps ``(U, V, H, W)``; the worst view, its MSE×100 split the same way, and
    how many of its pixels hold half and 90 % of its squared error."""
    e = (d - gt) ** 2
    vis = centre_visibility(gt)
    U, V = gt.shape[:2]
    worst = np.unravel_index(np.argmax(e.mean(axis=(2, 3))), (U, V))
    ew, vw = e[worst], vis[worst]
    ranked = np.cumsum(np.sort(ew.ravel())[::-1]) / max(float(ew.sum()), 1e-30)
    out = {"worst_view": [int(i) for i in worst]}
    for k, name in enumerate(VISIBILITY):
        m = vis == k
        out[name] = (float(100 * e[m].sum() / e.size), float(100 * m.mean()))
        out[f"worst_{name}"] = float(100 * ew[vw == k].sum() / ew.size)
    out["worst_pixels_half"] = int(np.searchsorted(ranked, 0.5) + 1)
    out["worst_pixels_90"] = int(np.searchsorted(ranked, 0.9) + 1)
    return out


def scenes(names: list[str], supersamples: list[int]):
    """``(label, light field, coverage)`` of each scene and supersampling."""
    for name in names:
        if name == "default":
            lf = default_light_field()
            U, V, H, W = lf.gt_disparity.shape
            cov = render_coverage(
                default_surfaces(), grid=(U, V), size=(H, W), supersample=DEFAULT_SUPERSAMPLE
            )
            yield f"default (ss {DEFAULT_SUPERSAMPLE})", lf, cov
            continue
        for ss in supersamples:
            lf = variant_scene(name, supersample=ss)
            U, V, H, W = lf.gt_disparity.shape
            cov = render_coverage(
                variant_surfaces(name, grid=(U, V), size=(H, W)),
                grid=(U, V),
                size=(H, W),
                supersample=ss,
            )
            yield f"{name} (ss {ss})", lf, cov


def textureless_twins(size=(128, 128), grid=(9, 9)) -> list[dict]:
    """The textureless variant against itself with the floor's slope changed (point 2)."""
    surfaces = variant_surfaces("textureless", grid=grid, size=size)
    floor = surfaces[1]
    a, b, c = floor.plane
    top = floor.centre[1] - floor.half_size[1]  # the floor's top edge (centre-view Y)
    base = render_surfaces(surfaces, grid=grid, size=size, supersample=3)
    rows = []
    for slope in (0.0, 2 * c):
        twin = list(surfaces)
        twin[1] = dataclasses.replace(floor, plane=(a + (c - slope) * top, b, slope))
        other = render_surfaces(twin, grid=grid, size=size, supersample=3)
        g1, g2 = np.asarray(base.gt_disparity), np.asarray(other.gt_disparity)
        per_view = 100 * np.mean((g1 - g2) ** 2, axis=(2, 3))
        U, V = per_view.shape
        rows.append(
            {
                "slope": (float(c), float(slope)),
                "max_image_difference": float(
                    np.abs(np.asarray(base.views) - np.asarray(other.views)).max()
                ),
                "gt_mse100_all": float(per_view.mean()),
                "gt_mse100_centre": float(per_view[U // 2, V // 2]),
            }
        )
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=",".join(("default", *VARIANTS)))
    ap.add_argument("--supersample", default="2,3")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    names = args.scenes.split(",")
    supersamples = [int(s) for s in args.supersample.split(",")]
    results = {}
    print(
        "| scene | all views | worst view | centre | BadPix(0.07) | "
        + " | ".join(f"{k} (% px)" for k in CLASSES)
        + " |"
    )
    print("|---" * (5 + len(CLASSES)) + "|")
    for label, lf, cov in scenes(names, supersamples):
        t = time.perf_counter()
        d = np.asarray(estimate_disparity(lf, PipelineConfig()).disparity)
        r = split_by_coverage(d, np.asarray(lf.gt_disparity), np.asarray(cov))
        r["seconds"] = time.perf_counter() - t
        r["visibility"] = split_by_visibility(d, np.asarray(lf.gt_disparity))
        results[label] = r
        cells = " | ".join(f"{r[k][0]:.3f} ({r[k][1]:.2f})" for k in CLASSES)
        print(
            f"| {label} | {r['all']:.3f} | {r['worst']:.3f} | {r['centre']:.3f} | "
            f"{r['badpix07']:.2f} | {cells} |",
            flush=True,
        )
    print(
        "\nBy what the centre view sees (all views; then the worst view):\n"
        "| scene | "
        + " | ".join(f"{k} (% px)" for k in VISIBILITY)
        + " | worst view | "
        + " / ".join(VISIBILITY)
        + " | pixels holding half / 90 % of it |"
    )
    print("|---" * (len(VISIBILITY) + 4) + "|")
    for label, r in results.items():
        v = r["visibility"]
        cells = " | ".join(f"{v[k][0]:.3f} ({v[k][1]:.2f})" for k in VISIBILITY)
        worst = " / ".join(f"{v[f'worst_{k}']:.3f}" for k in VISIBILITY)
        print(
            f"| {label} | {cells} | {tuple(v['worst_view'])} {r['worst']:.3f} | {worst} | "
            f"{v['worst_pixels_half']} / {v['worst_pixels_90']} |"
        )
    if "textureless" in names:
        twins = textureless_twins()
        results["textureless_twins"] = twins
        print("\nTextureless floor slope (per pixel) changed, same top edge:")
        for r in twins:
            print(
                f"  {r['slope'][0]:g} -> {r['slope'][1]:g}: largest image difference "
                f"{r['max_image_difference']:.3g}; MSE×100 between the ground truths "
                f"{r['gt_mse100_all']:.3f} (all views), {r['gt_mse100_centre']:.3f} (centre); "
                f"no map scores below {r['gt_mse100_all'] / 4:.3f} on both"
            )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
