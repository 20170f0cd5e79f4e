"""Where the self-similarity error of ours and the k-means baseline comes from.

For each scene and size, ours (`superpixels` with the Ch. 6 disparity, the default) and the
k-means baseline with the same disparity, the self-similarity error (SSE, px, the metric's
own definition: per superpixel the mean distance of its per-view centroids, projected into
the centre view with the ground truth, from their mean; mean over superpixels) split by
centre-view superpixel, and recomputed with parts of the labels or pixels substituted:

- ``border`` / ``inner``: superpixels touching / not touching the centre view's image
  border; ``mean`` is the mean over those superpixels, ``share`` their sum over the number of
  all superpixels (the two shares add up to the SSE);
- ``GT-projected``: the centre labels forward-projected with the ground-truth centre
  disparity (exact projection; pixels it does not reach keep the method's label): what the
  centre partition alone gives;
- ``core``: only pixels whose centre-view point stays inside the image in every view (the
  frame's effect removed);
- ``strip``: pixels whose ground-truth point lies outside the centre view (newly visible at
  the frame; NaN and ignored where only a centre-view ground truth exists); the share
  labelled with the centre label at the nearest inside point, and the SSE with all of them
  relabelled so;
- ``fill``: pixels inside the centre view's frame that the GT projection of the centre
  labels does not reach (disocclusions); the SSE without them;
- the superpixels with the largest error: centre area (px), border, ground-truth disparity
  range inside (px/view), the smallest fraction of their centre pixels the GT projection
  keeps in any view, area over border length (px, the extent away from the border).

Usage:
    PYTHONPATH=. python experiments/superpixels_sse_split.py --synthetic 1 --sizes 20 \
        --cache /tmp/sp_cache
    PYTHONPATH=. python experiments/superpixels_sse_split.py \
        ../shared/data/hci4d/additional/antinous --scale 0.5 --sizes 40 --cache /tmp/sp_cache
"""

from __future__ import annotations

import argparse

import numpy as np


def _per_superpixel(sp, n, px, py, mask):
    """``(n,)`` SSE per superpixel of compact labels ``sp (U, V, H, W)`` over ``mask`` pixels
    whose centre-view coordinates are ``px, py`` (0 for a superpixel absent from ``mask``)."""
    from mvedge_jax.metrics._superpixel import _centroid_deviation

    dev, nv = _centroid_deviation(sp, n, px, py, mask)
    return dev / np.maximum(nv, 1)


def split(labels, gt, gt_centre) -> dict:
    """The numbers listed in the module docstring for ``labels (U, V, H, W)`` int, with the
    per-view ground truth ``gt (U, V, H, W)`` (NaN unknown) and ``gt_centre (H, W)`` (px per
    view step)."""
    import jax.numpy as jnp

    from mvedge_jax.metrics._superpixel import _centre_coordinates, _compact
    from mvedge_jax.superpixels._superpixels import _project_centre, _view_offsets

    U, V, H, W = labels.shape
    sp, n = _compact(np.asarray(labels))
    sp = sp.astype(np.int64)
    ok = np.isfinite(gt)
    d = np.where(ok, gt, 0.0)
    px, py = _centre_coordinates(gt)
    out = ok & ((px < -0.5) | (px > W - 0.5) | (py < -0.5) | (py > H - 0.5))
    a = (U // 2) * np.abs(d)
    core = ok & (px - a >= -0.5) & (px + a <= W - 0.5) & (py - a >= -0.5) & (py + a <= H - 0.5)
    c = sp[U // 2, V // 2]
    proj, _ = _project_centre(
        jnp.asarray(c, jnp.int32),
        jnp.asarray(gt_centre, jnp.float32),
        jnp.asarray(_view_offsets(U, V)),
    )
    proj = np.asarray(proj).reshape(sp.shape)
    reached = proj >= 0
    ideal = np.where(reached, proj, sp)
    cy = np.clip(np.rint(py), 0, H - 1).astype(np.int64)
    cx = np.clip(np.rint(px), 0, W - 1).astype(np.int64)
    canon = np.where(out, c[cy, cx], sp)
    fill = ok & ~reached & ~out
    dev = _per_superpixel(sp, n, px, py, ok)
    area = np.bincount(c.ravel(), minlength=n)
    blen = np.zeros(n)
    for e in (c[0], c[-1], c[:, 0], c[:, -1]):
        blen += np.bincount(e, minlength=n)
    border = blen > 0
    inner = (area > 0) & ~border
    rng = np.array([np.ptp(gt_centre[c == i]) if area[i] else 0.0 for i in range(n)])
    kept = np.stack(
        [np.bincount(p.ravel(), minlength=n + 1)[1:] for p in proj.reshape(U * V, -1) + 1]
    )
    frac = kept.min(0) / np.maximum(area, 1)

    def parts(v):
        return dict(
            sse=float(v.mean()),
            border_mean=float(v[border].mean()),
            inner_mean=float(v[inner].mean()),
            border_share=float(v[border].sum() / n),
            inner_share=float(v[inner].sum() / n),
        )

    top = np.argsort(-dev)[:4]
    return dict(
        n=int(n),
        n_border=int(border.sum()),
        area_border=float(area[border].mean()),
        area_inner=float(area[inner].mean()),
        extent_border=float((area[border] / blen[border]).mean()),
        method=parts(dev),
        gt_projected=parts(_per_superpixel(ideal, n, px, py, ok)),
        core=parts(_per_superpixel(sp, n, px, py, core)),
        strip_pixels=int(out.sum()),
        strip_canonical_share=float((sp[out] == canon[out]).mean()) if out.any() else float("nan"),
        strip_relabelled=parts(_per_superpixel(canon, n, px, py, ok)),
        fill_share=float(fill.sum() / ok.sum()),
        without_fill=parts(_per_superpixel(sp, n, px, py, ok & ~fill)),
        worst=[
            dict(
                error=float(dev[i]),
                area=int(area[i]),
                border=bool(border[i]),
                gt_range=float(rng[i]),
                visible_min=float(frac[i]),
                extent=float(area[i] / blen[i]) if border[i] else float("nan"),
            )
            for i in top
        ],
    )


def _print(name, s):
    def row(k):
        p = s[k]
        return (
            f"{p['sse']:.3f} (border {p['border_mean']:.3f} / inner {p['inner_mean']:.3f}; "
            f"shares {p['border_share']:.3f} + {p['inner_share']:.3f})"
        )

    print(
        f"  {name}: n={s['n']} border n={s['n_border']}, area border/inner "
        f"{s['area_border']:.0f}/{s['area_inner']:.0f} px, "
        f"border extent {s['extent_border']:.1f} px"
    )
    for k in ("method", "gt_projected", "core", "strip_relabelled", "without_fill"):
        print(f"    {k:17s} SSE {row(k)}")
    print(
        f"    strip px {s['strip_pixels']} (canonical {s['strip_canonical_share']:.3f}), "
        f"fill share {s['fill_share']:.3f}"
    )
    for w in s["worst"]:
        print(
            f"    worst: error {w['error']:.2f} area {w['area']} border {w['border']} GT range "
            f"{w['gt_range']:.2f} visible min {w['visible_min']:.2f} extent {w['extent']:.1f}"
        )


def main() -> None:
    import sys

    sys.path.insert(0, "experiments")
    from superpixels_ch5 import _estimate, _scenes

    from mvedge_jax.metrics._superpixel import _project_centre_gt
    from mvedge_jax.superpixels import SuperpixelConfig, kmeans_superpixels, superpixels

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("paths", nargs="*")
    ap.add_argument("--synthetic", type=int, nargs="*", default=[])
    ap.add_argument("--size-px", type=int, default=128)
    ap.add_argument("--scale", type=float, default=None)
    ap.add_argument("--sizes", type=int, nargs="+", default=[20])
    ap.add_argument("--cache", default=None)
    args = ap.parse_args()
    for name, lf, _ in _scenes(args):
        edges, offset, disparity = _estimate(lf, args.cache)
        U, V = lf.grid
        gt = np.asarray(lf.gt_disparity, np.float64)
        gt_c = gt[U // 2, V // 2]
        if lf.gt_mask is not None and not np.asarray(lf.gt_mask).all():
            gt = _project_centre_gt(gt_c)
        for size in args.sizes:
            cfg = SuperpixelConfig(size=float(size))
            print(f"{name} size {size}")
            ours = superpixels(lf, cfg, edges=edges, surface_offset=offset, disparity=disparity)
            _print("ours", split(np.asarray(ours.labels), gt, gt_c))
            # the thesis' baseline: SLIC's seed grid only
            base_cfg = SuperpixelConfig(size=float(size), seed_candidates=1)
            km = kmeans_superpixels(lf, np.asarray(disparity[U // 2, V // 2]), base_cfg)
            _print("k-means (our d)", split(np.asarray(km.labels), gt, gt_c))


if __name__ == "__main__":
    main()
