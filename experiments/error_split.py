"""Where the Ch. 6 error is: split by region and by stage with oracle substitutions.

Usage:
    python experiments/error_split.py [SCENE ...] [--cache DIR] [--json OUT.json]
    python experiments/error_split.py [SCENE ...] --components [--json OUT.json]

SCENE: ``backgammon``, ``antinous`` (full resolution from ``$MVEDGE_DATA``), ``default`` (the
synthetic default scene) or a synthetic variant (``textureless``, ``slanted``, ``thin``,
``wide``, ``glossy``; 9×9×128²); default: all of them. The default `PipelineConfig` is used
throughout.

Regions of the centre view (from its ground truth and colour):

- ``edge``: within 3 px (7×7 window) of a depth discontinuity, a 4-neighbour GT step
  ``|Δgt| > 0.1`` px per view step;
- ``textureless``: not ``edge``, and the CIELAB gradient magnitude (Gaussian σ = 1, Sobel,
  Euclidean over channels; CIELAB units per pixel) stays below 2 within 3 px: no colour edge
  an edge detector could find nearby (`oracle_edges`' threshold);
- ``smooth``: the rest (textured interiors of surfaces).

Stages, each a centre-view map (rows of the table):

1. ``detected``: the pipeline's edges and surface vectors → centre diffusion (eq 6.1);
   ``+sharpen``: after the sharpening (`sharpen`: photo-consistent snapping, boundary matte,
   weighted median); ``+propagate``: the pipeline's final centre view (mean of its row and
   column EPI inpainting).
2. ``GT sides``: detected points and labels, each surface vector turned to the side whose GT
   (1.5 px away) is closer to the label (on texture edges both sides have about the same GT
   and the turn changes little) → diffusion / +sharpen. The printed wrong-side share counts
   the points at depth edges only (GT on the two sides differs by more than 0.1).
3. ``GT labels``: detected points and sides, each visible point's label replaced by the GT
   1.5 px from it on its side → diffusion / +sharpen.
4. ``oracle``: `oracle_edges` (points from the colour gradient, GT labels and sides, GT
   depth-edge confidence) → diffusion / +sharpen: the interpolation ceiling.
5. ``GT +sharpen``: the ground-truth map itself sharpened: what the sharpening costs a
   perfect map.

Reading the table: ``detected`` − ``GT labels`` is what label errors of the edge stage cost;
``detected`` − ``GT sides`` what wrong surface sides cost; ``oracle`` is what diffusion from
edge samples achieves with a perfect edge model; the ``+sharpen`` and ``+propagate`` rows
show what those steps add or remove; where ``GT +sharpen`` is about as high as a
``+sharpen`` row, or higher, the sharpening, not its input, sets that score. Also printed:
the share of visible edge points whose label is off by more than 0.07 (and 0.3) from the GT
on their side.

``--components``: instead, the ground-truth centre map through `sharpen` with every
component on, each one off and each one alone (photo-consistent snapping, boundary matte,
plane sweep, weighted median): which step sets the floor of ``GT +sharpen``. Rows: MSE×100
of the frame and of the ``edge`` region, BadPix(0.07) of the frame.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pickle
import sys
import time
from pathlib import Path

import cv2
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import ndimage

jax.config.update(
    "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

from mvedge_jax.io import load_light_field  # noqa: E402
from mvedge_jax.lightfield import rgb_to_lab  # noqa: E402
from mvedge_jax.metrics import depth_metrics  # noqa: E402
from mvedge_jax.pipeline import PipelineConfig, estimate_disparity  # noqa: E402
from mvedge_jax.reconstruct import (  # noqa: E402
    ReconstructConfig,
    SharpenConfig,
    centre_disparity,
    centre_seeds,
    sharpen,
)
from mvedge_jax.reconstruct._oracle import oracle_edges  # noqa: E402
from mvedge_jax.synthetic import VARIANTS, default_light_field, variant_scene  # noqa: E402

DATA = Path(os.environ.get("MVEDGE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
REAL = {"backgammon": "hci4d/stratified/backgammon", "antinous": "hci4d/additional/antinous"}
SCENES = ("backgammon", "antinous", "default", *VARIANTS)
REGIONS = ("all", "edge", "smooth", "textureless")
EDGE_STEP = 0.1  # px per view step
EDGE_RADIUS = 3  # px
TEXTURE_GRAD = 2.0  # CIELAB units per pixel
SIDE_DIST = 1.5  # px


def load_scene(name: str, seed: int = 0):
    """The light field of a scene name of `SCENES`; ``seed`` is the texture seed of the
    synthetic variants (`variant_scene`; for ``"wide"`` also its layout). The real scenes and
    the synthetic default scene have one rendering and ignore it."""
    if name in REAL:
        return load_light_field(DATA / REAL[name])
    if name == "default":
        return default_light_field()
    lf = variant_scene(name, seed)
    return lf if seed == 0 else dataclasses.replace(lf, name=f"{lf.name}-s{seed}")


def colour_gradient(img: np.ndarray) -> np.ndarray:
    """CIELAB gradient magnitude ``(H, W)`` (σ = 1 blur, Sobel/8, Euclidean over channels)."""
    lab = cv2.GaussianBlur(np.asarray(rgb_to_lab(jnp.asarray(img))), (0, 0), 1.0)
    gx = np.stack([cv2.Sobel(lab[..., c], cv2.CV_32F, 1, 0, ksize=3) / 8 for c in range(3)], -1)
    gy = np.stack([cv2.Sobel(lab[..., c], cv2.CV_32F, 0, 1, ksize=3) / 8 for c in range(3)], -1)
    return np.sqrt((gx**2 + gy**2).sum(-1))


def regions(gt: np.ndarray, img: np.ndarray) -> dict[str, np.ndarray]:
    """The ``all``/``edge``/``smooth``/``textureless`` masks of the module docstring."""
    jump = np.zeros(gt.shape, np.uint8)
    dx = np.abs(np.diff(gt, axis=1)) > EDGE_STEP
    dy = np.abs(np.diff(gt, axis=0)) > EDGE_STEP
    jump[:, 1:] |= dx
    jump[:, :-1] |= dx
    jump[1:] |= dy
    jump[:-1] |= dy
    k = np.ones((2 * EDGE_RADIUS + 1,) * 2, np.uint8)
    edge = cv2.dilate(jump, k) > 0
    near_colour = cv2.dilate((colour_gradient(img) >= TEXTURE_GRAD).astype(np.uint8), k) > 0
    textureless = ~edge & ~near_colour
    return {
        "all": np.ones(gt.shape, bool),
        "edge": edge,
        "smooth": ~edge & ~textureless,
        "textureless": textureless,
    }


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return ndimage.map_coordinates(img.astype(np.float32), [y, x], order=1, mode="nearest")


def side_oracles(edges, surface, gt: np.ndarray):
    """``(edges with GT labels, surface with GT sides, label error stats)`` (see module doc)."""
    x, y = np.asarray(edges.x), np.asarray(edges.y)
    off = np.asarray(surface.offset)
    lab = np.asarray(edges.disparity)
    use = np.asarray(edges.valid) & np.asarray(edges.visible)
    g_fwd = _bilinear(gt, x + SIDE_DIST * off[:, 0], y + SIDE_DIST * off[:, 1])
    g_bwd = _bilinear(gt, x - SIDE_DIST * off[:, 0], y - SIDE_DIST * off[:, 1])
    new_lab = np.where(use, g_fwd, lab).astype(np.float32)
    flip = use & (np.abs(g_bwd - lab) < np.abs(g_fwd - lab))
    at_depth_edge = use & (np.abs(g_fwd - g_bwd) > EDGE_STEP)
    new_off = np.where(flip[:, None], -off, off).astype(np.float32)
    err = np.abs(lab - g_fwd)[use]
    stats = {
        "points": int(use.sum()),
        "label_err>0.07_%": float(100 * np.mean(err > 0.07)),
        "label_err>0.3_%": float(100 * np.mean(err > 0.3)),
        "depth_edge_points": int(at_depth_edge.sum()),
        "wrong_side_%": float(100 * (flip & at_depth_edge).sum() / max(1, at_depth_edge.sum())),
    }
    gt_labels = eqx.tree_at(lambda e: e.disparity, edges, jnp.asarray(new_lab))
    gt_sides = eqx.tree_at(lambda s: s.offset, surface, jnp.asarray(new_off))
    return gt_labels, gt_sides, stats


def run_pipeline(lf, config: PipelineConfig, cache: Path | None) -> dict:
    """The pipeline's edges, surface and centre maps (cached by scene name)."""
    path = cache / f"{lf.name}.pkl" if cache else None
    if path and path.is_file():
        return pickle.loads(path.read_bytes())
    r = estimate_disparity(lf, config)
    rc, cc = lf.centre_index
    out = {
        "final": np.asarray(r.disparity[rc, cc]),
        "centre": np.asarray(r.reconstruction.centre),
        "sharp": np.asarray(r.reconstruction.centre_sharp),
        "edges": jax.tree.map(np.asarray, r.edges),
        "surface": jax.tree.map(np.asarray, r.surface),
    }
    if path:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(out))
    return out


@eqx.filter_jit
def diffuse_centre(views, edges, surface, config: ReconstructConfig):
    """The centre diffusion of `reconstruct` (eq 6.1, with `centre_seeds` when
    ``config.seeds.steps > 0``) for the given edges and surface."""
    centre = views[views.shape[0] // 2, views.shape[1] // 2]
    seeds = centre_seeds(views, edges, surface, config) if config.seeds.steps else None
    return centre_disparity(edges, surface, centre, config, seeds)


def split_scene(lf, config: PipelineConfig, cache: Path | None) -> dict:
    """Rows ``{stage: {region: MSE×100, "bp07": BadPix(0.07) over all}}`` and label stats."""
    rc, cc = lf.centre_index
    views = lf.views
    img = np.asarray(lf.centre_view)
    gt = np.asarray(lf.gt_disparity[rc, cc])
    masks = regions(gt, img)
    base = run_pipeline(lf, config, cache)
    edges = jax.tree.map(jnp.asarray, base["edges"])
    surface = jax.tree.map(jnp.asarray, base["surface"])
    rcfg = config.reconstruct
    maps = {
        "detected": base["centre"],
        "detected +sharpen": base["sharp"],
        "detected +propagate": base["final"],
    }
    gt_labels, gt_sides, stats = side_oracles(edges, surface, gt)
    o_edges, o_surface = oracle_edges(img, gt, grid=lf.grid)
    for label, (e, s) in {
        "GT sides": (edges, gt_sides),
        "GT labels": (gt_labels, surface),
        "oracle": (o_edges, o_surface),
    }.items():
        c = np.asarray(diffuse_centre(views, e, s, rcfg))
        maps[label] = c
        maps[f"{label} +sharpen"] = np.asarray(sharpen(views, c, rcfg))
    maps["GT +sharpen"] = np.asarray(sharpen(views, jnp.asarray(gt), rcfg))
    rows = {}
    for stage, m in maps.items():
        row = {r: depth_metrics(m, gt, masks[r])["mse_x100"] for r in REGIONS}
        row["bp07"] = depth_metrics(m, gt)["badpix_0.07"]
        rows[stage] = row
    share = {r: float(100 * masks[r].mean()) for r in REGIONS}
    return {"scene": lf.name, "rows": rows, "region_share_%": share, "labels": stats}


#: The sharpening's components: name → (field of `SharpenConfig`, its value when off).
COMPONENTS = {
    "snapping": ("refine", False),
    "matte": ("matte", False),
    "plane sweep": ("sweep_steps", 0),
    "weighted median": ("enabled", False),
}


def component_configs(config: SharpenConfig) -> dict[str, SharpenConfig]:
    """``config`` as given (``"all on"``), with each component of `COMPONENTS` off
    (``"<name> off"``) and with each one alone (``"<name> alone"``, the others off)."""
    on = {field: getattr(config, field) for field, _ in COMPONENTS.values()}
    off = dict(COMPONENTS.values())
    out = {"all on": config}
    for name, (field, value) in COMPONENTS.items():
        out[f"{name} off"] = dataclasses.replace(config, **{field: value})
    for name, (field, _) in COMPONENTS.items():
        out[f"{name} alone"] = dataclasses.replace(config, **{**off, field: on[field]})
    return out


def component_split(lf, config: PipelineConfig) -> dict:
    """Rows ``{setting: {"all", "edge": MSE×100, "bp07": BadPix(0.07)}}`` of the scene's
    ground-truth centre map sharpened with each `component_configs` setting."""
    rc, cc = lf.centre_index
    gt = np.asarray(lf.gt_disparity[rc, cc])
    edge = regions(gt, np.asarray(lf.centre_view))["edge"]
    rows = {}
    for name, sc in component_configs(config.reconstruct.sharpen).items():
        rcfg = dataclasses.replace(config.reconstruct, sharpen=sc)
        m = np.asarray(sharpen(lf.views, jnp.asarray(gt), rcfg))
        frame = depth_metrics(m, gt)
        rows[name] = {
            "all": frame["mse_x100"],
            "edge": depth_metrics(m, gt, edge)["mse_x100"],
            "bp07": frame["badpix_0.07"],
        }
    return {"scene": lf.name, "components": rows}


def print_components(res: dict) -> None:
    print(f"{res['scene']}: ground truth sharpened (MSE×100 all / edge, BadPix(0.07) all)")
    for name, row in res["components"].items():
        print(f"  {name:<22}{row['all']:>9.3f}{row['edge']:>9.3f}{row['bp07']:>8.2f}")
    sys.stdout.flush()


def print_table(results: list[dict]) -> None:
    head = f"{'scene':<22}{'stage':<22}" + "".join(f"{r:>12}" for r in REGIONS) + f"{'BP.07':>8}"
    print("MSE×100 of the centre view by region (share of pixels in brackets); BadPix(0.07) all")
    print(head)
    print("-" * len(head))
    for res in results:
        sh = res["region_share_%"]
        print(f"{res['scene']:<22}{'(share %)':<22}" + "".join(f"{sh[r]:>12.1f}" for r in REGIONS))
        for stage, row in res["rows"].items():
            print(
                f"{'':<22}{stage:<22}"
                + "".join(f"{row[r]:>12.3f}" for r in REGIONS)
                + f"{row['bp07']:>8.2f}"
            )
        st = res["labels"]
        print(
            f"{'':<22}labels: {st['points']} visible points, "
            f"{st['label_err>0.07_%']:.1f}% off > 0.07, {st['label_err>0.3_%']:.1f}% off > 0.3, "
            f"{st['wrong_side_%']:.1f}% of the {st['depth_edge_points']} at depth edges on the "
            "wrong side"
        )
        sys.stdout.flush()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("scenes", nargs="*", help=f"scenes among {', '.join(SCENES)} (default: all)")
    ap.add_argument("--cache", help="folder for the pipeline results per scene (reused)")
    ap.add_argument("--json", help="write the results as JSON")
    ap.add_argument(
        "--components",
        action="store_true",
        help="sharpen the ground truth with each component off and alone instead",
    )
    args = ap.parse_args(argv)
    if args.components and args.cache:
        ap.error("--cache holds the pipeline's results, which --components does not use")
    unknown = set(args.scenes) - set(SCENES)
    if unknown:
        ap.error(f"unknown scenes {sorted(unknown)}; use {', '.join(SCENES)}")
    cache = Path(args.cache) if args.cache else None
    config = PipelineConfig()
    results = []
    for name in args.scenes or SCENES:
        t0 = time.perf_counter()
        if args.components:
            res = component_split(load_scene(name), config)
            print_components(res)
        else:
            res = split_scene(load_scene(name), config, cache)
            print_table([res])
        res["seconds"] = time.perf_counter() - t0
        results.append(res)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
