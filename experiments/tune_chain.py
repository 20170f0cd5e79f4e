"""Gradient-based tuning of the chain's hyperparameters, scored on a held-out scene.

`mvedge_jax.pipeline.tune` differentiates the supervised L1 error of every view through the
whole chain (`estimate_disparity_arrays`: edges → surface vectors → centre diffusion →
sharpening → propagation) and takes Adam steps on the chosen fields. The hyperparameters are
tuned on ``--train`` scenes and scored, before and after, on ``--eval`` scenes never seen
while tuning (full light field at the crop size, the same default config for all). The tuned
config is written as TOML (``--out-config``), ready for ``mvedge depth --config``.

Scenes: ``synthetic:<seed>`` (`mvedge_jax.synthetic.make_scene`, exact GT in every view) or an
HCI 4D folder (name under ``$MVEDGE_DATA/hci4d/*/`` or a path; centre-view GT). Light fields
are downscaled by ``--scale`` and cropped to the central ``--size`` pixels so that a step
takes seconds on a CPU; errors are in the pixels of the cropped light field.

Example::

    python experiments/tune_chain.py --train synthetic:1 synthetic:2 --eval synthetic:3 \\
        --fields reconstruct.centre.omega surface.gradient_sigma reconstruct.epi.c --steps 10
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

import numpy as np

from mvedge_jax.io import load_light_field
from mvedge_jax.lightfield import LightField
from mvedge_jax.metrics import depth_metrics
from mvedge_jax.pipeline import (
    PipelineConfig,
    config_to_toml,
    estimate_disparity,
    get_path,
    hyperparameter_paths,
    smooth_config,
    tune,
)
from mvedge_jax.synthetic import make_scene

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MVEDGE_DATA", ROOT.parent / "shared" / "data"))


def crop_centre(lf: LightField, size: int) -> LightField:
    """The central ``size``×``size`` pixels of every view (and of the ground truth)."""
    H, W = lf.size
    y0, x0 = (H - size) // 2, (W - size) // 2
    cut = lambda a: None if a is None else a[..., y0 : y0 + size, x0 : x0 + size]  # noqa: E731
    views = lf.views[..., y0 : y0 + size, x0 : x0 + size, :]
    return dataclasses.replace(
        lf, views=views, gt_disparity=cut(lf.gt_disparity), gt_mask=cut(lf.gt_mask)
    )


def load_scene(name: str, size: int, scale: float | None):
    if name.startswith("synthetic:"):
        return make_scene(int(name.split(":")[1]), grid=(5, 5), size=(size, size))
    path = Path(name)
    if not path.exists():
        matches = sorted(DATA.glob(f"hci4d/*/{name}"))
        if not matches:
            raise SystemExit(f"scene {name!r} not found under {DATA / 'hci4d'}")
        path = matches[0]
    return crop_centre(load_light_field(path, scale=scale), size)


def score(lf, config) -> dict:
    result = estimate_disparity(lf, config)
    rc, cc = lf.centre_index
    return depth_metrics(
        np.asarray(result.disparity[rc, cc]), lf.gt_disparity[rc, cc], mask=lf.gt_mask[rc, cc]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", nargs="+", default=["synthetic:1", "synthetic:2"])
    parser.add_argument("--eval", nargs="+", default=["synthetic:3"])
    parser.add_argument(
        "--fields",
        nargs="+",
        default=["reconstruct.centre.omega", "surface.gradient_sigma", "reconstruct.epi.c"],
        help=f"differentiable fields, from: {' '.join(hyperparameter_paths(differentiable=True))}",
    )
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--lr", type=float, default=0.1)
    parser.add_argument("--size", type=int, default=48)
    parser.add_argument("--scale", type=float, default=None)
    parser.add_argument("--smooth", action="store_true", help="tune the smooth_config chain")
    parser.add_argument("--out-config", type=Path, default=None)
    args = parser.parse_args()

    config = smooth_config() if args.smooth else PipelineConfig()
    train = [load_scene(n, args.size, args.scale) for n in args.train]
    held_out = [load_scene(n, args.size, args.scale) for n in args.eval]

    def progress(step, rec):
        vals = " ".join(f"{p.split('.')[-1]}={rec[p]:.4g}" for p in args.fields)
        print(f"step {step:3d}  loss {rec['loss']:.5f}  |g| {rec['grad_norm']:.3g}  {vals}")

    t0 = time.perf_counter()
    tuned, hist = tune(
        config,
        train,
        fields=args.fields,
        steps=args.steps,
        learning_rate=args.lr,
        callback=progress,
    )
    print(
        f"tuned in {time.perf_counter() - t0:.1f} s; "
        f"final train loss {float(hist['final_loss']):.5f}"
    )
    print()
    print(
        f"{'scene':<20} {'role':<6} {'MSE×100 before':>15} {'after':>8} "
        f"{'BP.07 before':>13} {'after':>8}"
    )
    for role, scenes in (("train", train), ("eval", held_out)):
        for lf in scenes:
            b, a = score(lf, config), score(lf, tuned)
            print(
                f"{lf.name:<20} {role:<6} {b['mse_x100']:>15.3f} {a['mse_x100']:>8.3f} "
                f"{b['badpix_0.07']:>13.2f} {a['badpix_0.07']:>8.2f}"
            )
    print()
    for p in args.fields:
        print(f"{p:<32} {float(get_path(config, p)):>10.4g} -> {float(get_path(tuned, p)):.4g}")
    if args.out_config:
        args.out_config.write_text(config_to_toml(tuned))
        print(f"wrote {args.out_config}")


if __name__ == "__main__":
    main()
