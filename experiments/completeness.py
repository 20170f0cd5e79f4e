"""Completeness of the differentiable edge model (thesis Sec. 7.2.3, Fig. 7.10–7.11).

Encode a scene's ground-truth disparity as a sparse set of edge points, render + diffuse them
(eqs 7.2–7.14), optimise all point and smoothness parameters against the ground truth with the
supervised L1 loss (block-coordinate Adam), and report how well the dense result reproduces
the ground truth (centre view, all pixels).

Encoding (``--select``): points sit at pixel centres, labelled with the GT disparity there:

* ``image``  — the N pixels of strongest image gradient |∇I| (multi-view edges are image edges);
* ``depth``  — the N pixels of largest |Δ GT| (where the disparity is not locally linear:
  depth edges and creases, where a diffusion needs labels);
* ``mixed``  — the N largest of ``max(|ΔGT| / p95(|ΔGT|), |∇I| / p95(|∇I|))`` (default).

Example::

    .venv/bin/python experiments/completeness.py ../shared/data/hci4d/stratified/backgammon \\
        ../shared/data/hci4d/additional/antinous --json out.json
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import click
import cv2
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from mvedge_jax.diff import (
    ModelConfig,
    OptimizeConfig,
    RenderConfig,
    image_gradient_magnitude,
    initial_params,
    optimize,
    predict,
)
from mvedge_jax.io import read_pfm


def _laplacian(a: np.ndarray) -> np.ndarray:
    p = np.pad(a, 1, mode="edge")
    return p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:] - 4 * a


def encode(img: np.ndarray, gt: np.ndarray, n: int, select: str):
    """Pixel positions ``(n, 2)`` and GT labels ``(n,)`` of the encoding."""
    mag = np.asarray(image_gradient_magnitude(img))
    lap = np.abs(_laplacian(gt))
    if select == "image":
        score = mag
    elif select == "depth":
        score = lap
    else:
        score = np.maximum(
            lap / max(np.percentile(lap, 95), 1e-12), mag / max(np.percentile(mag, 95), 1e-12)
        )
    idx = np.argsort(score.ravel(), kind="stable")[::-1][:n]
    yy, xx = np.unravel_index(idx, gt.shape)
    return np.stack([xx, yy], 1).astype(np.float32), gt[yy, xx].astype(np.float32)


def metrics(d: np.ndarray, gt: np.ndarray) -> dict[str, float]:
    err = d - gt
    return {
        "mse_x100": float(100 * np.mean(err**2)),
        "badpix_0.01": float(100 * np.mean(np.abs(err) > 0.01)),
        "badpix_0.03": float(100 * np.mean(np.abs(err) > 0.03)),
        "badpix_0.07": float(100 * np.mean(np.abs(err) > 0.07)),
        "q25_x100": float(100 * np.percentile(np.abs(err), 25)),
    }


def read_scene(folder: Path):
    centre = folder / "input_Cam040.png"
    gt_path = folder / "gt_disp_lowres.pfm"
    for p in (centre, gt_path):
        if not p.is_file():
            raise click.ClickException(f"missing {p}")
    img = cv2.imread(str(centre), cv2.IMREAD_COLOR)[..., ::-1].astype(np.float32) / 255.0
    return np.ascontiguousarray(img), np.asarray(read_pfm(gt_path), np.float32)


def _levels(text: str) -> tuple[tuple[int, float], ...]:
    """``"48:1,96:0.35"`` → ``((48, 1.0), (96, 0.35))``."""
    try:
        return tuple((int(c), float(f)) for c, f in (p.split(":") for p in text.split(",")))
    except ValueError as err:
        raise click.BadParameter(f"expected capacity:fraction,...; got {text!r}") from err


@click.command()
@click.argument(
    "scene_dirs", nargs=-1, required=True, type=click.Path(file_okay=False, exists=True)
)
@click.option("--points", default=50000, show_default=True, help="points per scene")
@click.option(
    "--select", type=click.Choice(["mixed", "image", "depth"]), default="mixed", show_default=True
)
@click.option("--iterations", default=13, show_default=True, help="Adam steps per block and pass")
@click.option("--passes", default=5, show_default=True)
@click.option(
    "--density",
    default=0.1,
    show_default=True,
    help="ρ of the transmittance model (all encoded points are visible: little occlusion)",
)
@click.option("--label-weight", default=100.0, show_default=True, help="data-term factor")
@click.option(
    "--label-mix", type=click.Choice(["weight", "opacity"]), default="weight", show_default=True
)
@click.option("--depth-samples", default=8, show_default=True, help="0 = exact integral")
@click.option(
    "--tile-levels",
    default="48:1,96:0.4,200:0.2",
    show_default=True,
    help="capacity:fraction of tiles, comma separated (RenderConfig.tile_levels)",
)
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
@click.option(
    "--save-dir",
    type=click.Path(file_okay=False),
    default=None,
    help="write the optimised disparity maps (.npy) here",
)
def main(
    scene_dirs,
    points,
    select,
    iterations,
    passes,
    density,
    label_mix,
    label_weight,
    depth_samples,
    tile_levels,
    json_path,
    save_dir,
):
    model = ModelConfig(
        render=RenderConfig(
            density=density,
            label_mix=label_mix,
            depth_samples=depth_samples,
            tile_levels=_levels(tile_levels),
        ),
        label_weight=label_weight,
    )
    cfg = OptimizeConfig(model=model, iterations=iterations, passes=passes)
    results = {}
    header = (
        f"{'scene':<14}{'points':>8}{'MSE×100 0':>11}{'MSE×100':>10}"
        f"{'BP0.07 0':>10}{'BP0.07':>9}{'s/step':>8}"
    )
    print(header)
    for folder in scene_dirs:
        folder = Path(folder)
        name = folder.name
        img, gt = read_scene(folder)
        pos, lab = encode(img, gt, points, select)
        p0 = initial_params(pos, lab, img, model)
        t0 = time.perf_counter()
        params, hist = optimize(p0, img, None, None, cfg, target_disparity=jnp.asarray(gt))
        wall = time.perf_counter() - t0
        d = hist["disparity"]
        d0 = np.asarray(eqx.filter_jit(predict)(p0, model).disparity)
        m0, m = metrics(d0, gt), metrics(d, gt)
        results[name] = {
            **m,
            "initial": m0,
            "points": int(len(lab)),
            "select": select,
            "steps": int(len(hist["loss"])),
            "wall_seconds": wall,
            "mean_step_seconds": float(np.mean(hist["seconds"][1:]))
            if len(hist["seconds"]) > 1
            else None,
            "max_overflow": int(hist["overflow"].max()) if len(hist["overflow"]) else 0,
            "mse_x100_history": [float(v) for v in hist["mse_x100"]],
        }
        r = results[name]
        print(
            f"{name:<14}{r['points']:>8}{m0['mse_x100']:>11.3f}{m['mse_x100']:>10.3f}"
            f"{m0['badpix_0.07']:>10.2f}{m['badpix_0.07']:>9.2f}"
            f"{r['mean_step_seconds'] or 0:>8.2f}",
            flush=True,
        )
        if save_dir:
            os.makedirs(save_dir, exist_ok=True)
            np.save(Path(save_dir) / f"{name}_disparity.npy", d)
    out = {
        "config": {
            "points": points,
            "select": select,
            "iterations": iterations,
            "passes": passes,
            "density": density,
            "label_mix": label_mix,
            "label_weight": label_weight,
            "depth_samples": depth_samples,
            "tile_levels": tile_levels,
        },
        "scenes": results,
    }
    if json_path:
        Path(json_path).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
