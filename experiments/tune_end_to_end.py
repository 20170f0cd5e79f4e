"""End-to-end gradient-based tuning of detector and diffusion hyperparameters (issue #6, item 7).

A supervised L1 depth loss is back-propagated through the diffusion (custom-VJP Poisson
solve), the transmittance splatting and the soft multi-view edge detector to a few continuous
hyperparameters (`mvedge_jax.diff.EndToEndParams`: softmax temperature, pre-blur σ, data and
smoothness weight scales, the image-edge factor of the smoothness, the exponents of the
per-point label weight, the direction-mixing gain and bias). They are tuned with Adam on ONE
scene (``--train``) and scored on ANOTHER (``--eval``, never seen while tuning); the script
prints MSE×100 and BadPix(0.07) before and after on both, the hyperparameters before and
after and the loss curve, and writes everything to ``--json``.

Scenes are HCI 4D folders under ``$MVEDGE_DATA`` (default ``../shared/data``): a name is
looked up as ``hci4d/*/<name>``; a path is used as it is. To keep one step at a few seconds
on a CPU the light fields are optionally downscaled (``--scale``) and then cropped to the
central ``--size``×``--size`` pixels. Errors are reported in the disparity units of the
original resolution (maps and ground truth divided by ``--scale``), over the crop.

For reference, the table also shows the hard detector's own labels (`detect_edges`: variance
search, trilateral filter) diffused by the same model at its default weights ("hard").

Example::

    .venv/bin/python experiments/tune_end_to_end.py --train backgammon --eval antinous \\
        --steps 60 --size 192 --json scratch/tune/tune.json
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import click
import equinox as eqx
import jax
import numpy as np

from mvedge_jax.diff import (
    HPARAM_NAMES,
    EndToEndConfig,
    EndToEndParams,
    EndToEndScene,
    evaluate_scene,
    initial_params,
    predict,
    prepare_scene,
    tune,
)
from mvedge_jax.io import load_light_field
from mvedge_jax.lightfield import LightField
from mvedge_jax.metrics import depth_metrics

_ROOT = Path(__file__).resolve().parents[1]


def data_root() -> Path:
    return Path(os.environ.get("MVEDGE_DATA", _ROOT.parent / "shared" / "data"))


def find_scene(name: str) -> Path:
    """A scene folder from a name (``hci4d/*/<name>`` under the data root) or a path."""
    p = Path(name)
    if p.is_dir():
        return p
    hits = sorted(data_root().glob(f"hci4d/*/{name}"))
    if not hits:
        raise click.ClickException(f"scene {name!r} not found under {data_root()}/hci4d/*/")
    return hits[0]


def crop_light_field(lf: LightField, size: int | None) -> LightField:
    """The central ``size × size`` pixels of every view (and of the ground truth)."""
    H, W = lf.size
    if size is None or (size >= H and size >= W):
        return lf
    s_h, s_w = min(size, H), min(size, W)
    y0, x0 = (H - s_h) // 2, (W - s_w) // 2

    def crop(a):
        return None if a is None else a[:, :, y0 : y0 + s_h, x0 : x0 + s_w]

    return LightField(
        views=crop(lf.views),
        view_mask=lf.view_mask,
        gt_disparity=crop(lf.gt_disparity),
        gt_mask=crop(lf.gt_mask),
        name=lf.name,
        source=lf.source,
        disparity_range=lf.disparity_range,
    )


def load_scene(name: str, scale: float, size: int | None) -> tuple[LightField, EndToEndScene]:
    lf = load_light_field(find_scene(name), scale=None if scale == 1.0 else scale)
    lf = crop_light_field(lf, size)
    if lf.centre_gt is None:
        raise click.ClickException(f"scene {name!r} has no ground-truth disparity")
    return lf, prepare_scene(lf)


def scene_metrics(d, scene: EndToEndScene, scale: float) -> dict[str, float]:
    """SPEC §7 metrics of a centre disparity, in original-resolution disparity units."""
    return depth_metrics(
        np.asarray(d) / scale, np.asarray(scene.target) / scale, np.asarray(scene.target_mask)
    )


def hard_reference(scene: EndToEndScene, config: EndToEndConfig):
    """The hard detector's labels diffused by the same model at its default weights."""
    p0 = initial_params(scene.points, scene.hard_label, scene.centre, config.model)
    return eqx.filter_jit(predict)(p0, config.model).disparity


def _fmt_row(label, m):
    return f"{label:<28}{m['mse_x100']:>10.3f}{m['badpix_0.07']:>10.2f}{m['q25_x100']:>10.2f}"


@click.command()
@click.option("--train", "train_name", default="backgammon", show_default=True)
@click.option("--eval", "eval_name", default="antinous", show_default=True)
@click.option("--steps", default=60, show_default=True, help="Adam steps")
@click.option("--lr", default=0.1, show_default=True, help="Adam learning rate")
@click.option("--size", default=192, show_default=True, help="central crop, pixels (0 = none)")
@click.option(
    "--scale", default=1.0, show_default=True, help="spatial downscale before the crop, (0, 1]"
)
@click.option("--loss", type=click.Choice(["l1", "mse"]), default="l1", show_default=True)
@click.option(
    "--temperature",
    type=click.Choice(["relative", "absolute"]),
    default="relative",
    show_default=True,
    help="softmax temperature relative to each pixel's largest response, or absolute",
)
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
def main(train_name, eval_name, steps, lr, size, scale, loss, temperature, json_path):
    if train_name == eval_name:
        raise click.ClickException("--train and --eval must be different scenes")
    if not 0 < scale <= 1:
        raise click.ClickException(f"--scale must be in (0, 1]; got {scale}")
    size = size or None
    config = EndToEndConfig(loss=loss, temperature=temperature)
    t0 = time.perf_counter()
    scenes = {}
    for role, name in (("train", train_name), ("eval", eval_name)):
        lf, scene = load_scene(name, scale, size)
        scenes[role] = (lf.name, scene)
        print(
            f"{role:<6}{lf.name:<14}{lf.size[0]}x{lf.size[1]} px, {lf.grid[0]}x{lf.grid[1]} "
            f"views, {scene.points.shape[0]} edge points, d_max {scene.d_max:.2f}",
            flush=True,
        )
    prep_s = time.perf_counter() - t0
    hp0 = (
        EndToEndParams.create()
        if temperature == "relative"
        else EndToEndParams.create(temperature=0.02)
    )
    before = {
        r: scene_metrics(evaluate_scene(hp0, s, config), s, scale) for r, (_, s) in scenes.items()
    }
    hard = {r: scene_metrics(hard_reference(s, config), s, scale) for r, (_, s) in scenes.items()}

    print(f"\ntuning on {scenes['train'][0]}: {steps} Adam steps, lr {lr}, loss {loss}")
    t1 = time.perf_counter()

    def progress(i, rec):
        if i % 10 == 0 or i == steps - 1:
            print(f"  step {i:>4}  loss {rec['loss']:.5f}  {rec['seconds']:.2f} s", flush=True)

    hp, hist = tune(hp0, scenes["train"][1], steps, lr, config=config, callback=progress)
    tune_s = time.perf_counter() - t1
    after = {
        r: scene_metrics(evaluate_scene(hp, s, config), s, scale) for r, (_, s) in scenes.items()
    }

    units = "" if scale == 1.0 else f" (×1/{scale:g}: original-resolution units)"
    print(f"\ncentre view, all GT-valid pixels of the crop{units}")
    print(f"{'':<28}{'MSE×100':>10}{'BP(0.07)':>10}{'Q25×100':>10}")
    for role in ("train", "eval"):
        name = scenes[role][0]
        print(_fmt_row(f"{role} {name} before", before[role]))
        print(_fmt_row(f"{role} {name} after", after[role]))
        print(_fmt_row(f"{role} {name} hard (ref.)", hard[role]))
    v0 = {k: float(x) for k, x in hp0.values().items()}
    v1 = {k: float(x) for k, x in hp.values().items()}
    print(f"\n{'hyperparameter':<20}{'before':>12}{'after':>12}")
    for n in HPARAM_NAMES:
        print(f"{n:<20}{v0[n]:>12.4g}{v1[n]:>12.4g}")
    curve = [float(x) for x in hist["loss"]] + [float(hist["final_loss"])]
    print("\nloss curve (train, every 5th step and the final value):")
    print("  " + " ".join(f"{x:.4f}" for x in curve[::5] + [curve[-1]]))
    sec = hist["seconds"][1:] if steps > 1 else hist["seconds"]
    mean_step = float(np.mean(sec)) if len(sec) else float("nan")
    print(
        f"\nprepare {prep_s:.1f} s, tune {tune_s:.1f} s (first step incl. compile "
        f"{float(hist['seconds'][0]) if steps else float('nan'):.1f} s, then {mean_step:.2f} "
        f"s/step); skipped steps {int(hist['skipped'].sum()) if steps else 0}; "
        f"{jax.devices()[0].platform}"
    )
    if json_path:
        out = {
            "config": {
                "train": scenes["train"][0],
                "eval": scenes["eval"][0],
                "steps": steps,
                "lr": lr,
                "size": size,
                "scale": scale,
                "loss": loss,
                "temperature": temperature,
                "points": {r: int(s.points.shape[0]) for r, (_, s) in scenes.items()},
                "d_max": {r: s.d_max for r, (_, s) in scenes.items()},
            },
            "before": before,
            "after": after,
            "hard_reference": hard,
            "hparams_before": v0,
            "hparams_after": v1,
            "history": {
                k: [float(x) for x in np.asarray(v)]
                for k, v in hist.items()
                if k != "disparity" and np.ndim(v) == 1
            },
            "final_loss": float(hist["final_loss"]),
            "seconds": {"prepare": prep_s, "tune": tune_s, "mean_step": mean_step},
        }
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps(out, indent=2))
        print(f"wrote {json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
