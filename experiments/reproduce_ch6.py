"""Reproduce thesis Table 6.1 style numbers: the Ch. 6 pipeline on every scene with ground truth.

Usage:
    python experiments/reproduce_ch6.py [SCENE_DIR ...] [--json OUT.json] [--out DIR]
        [--no-synthetic] [--variants] [--seed N] [--config PIPELINE.toml]
    python experiments/reproduce_ch6.py --sensitivity [--cache DIR] [--json OUT.json]
    python experiments/reproduce_ch6.py --loo [--grid 'NAME=V1,V2;NAME2=V3,V4'] [--cache DIR]
        [--criterion mse|mse+badpix|all] [--json OUT.json]

Without arguments it runs every ground-truth scene in ``$MVEDGE_DATA`` (default
``../shared/data``): backgammon, antinous, stillLife, and the synthetic default scene (with
``--variants`` also the synthetic variants of `mvedge_jax.synthetic.VARIANTS`; ``--seed N``
renders the variants with texture seed ``N``, for wide also its layout, so that seeds other
than 0 are scenes no default was chosen on). Prints one
row per scene, centre view: full frame (MSE×100, BadPix(0.01/0.03/0.07), Q25×100) and the
HCI 4D benchmark protocol (`benchmark_metrics`: 15-px frame excluded, the toolkit's Q25;
every scene with GT), view consistency, the worst view's MSE×100 (scenes with GT in every view),
seconds per stage, and for scenes the thesis used, the thesis' Table 6.1 numbers beside them.
With ``--out``, the full `mvedge depth` outputs (PFMs, PNGs, metrics.json) are written per
scene.

``--sensitivity`` and ``--loo`` choose defaults of `ReconstructConfig` without looking at the
score of the scene they report. Validation scenes: backgammon and antinous (full resolution)
and the synthetic default scene and variants. Edges and surface vectors are computed once per
scene with the default config (cached in ``--cache``, shared with
``experiments/error_split.py``); each candidate config then runs the centre-view part of the
reconstruction (`centre_disparity` and `sharpen`; only array leaves change, so nothing
recompiles) and is scored by the centre view's MSE×100 against GT (the propagation changes the
centre view's MSE×100 by less than 0.5 % on every scene, experiments/error_split.py).

- ``--sensitivity``: one parameter at a time, each value of `SENSITIVITY`; prints per scene
  the MSE×100 ratio to the default and the geometric mean over scenes.
- ``--loo``: every combination of `LOO_GRID` (or of ``--grid``: array fields of
  `ReconstructConfig` by dotted path, e.g. ``sharpen.wmf_sigma``); for each held-out scene the
  combination with the lowest geometric-mean MSE×100 ratio to the default over the OTHER
  scenes (``--criterion mse+badpix``: the geometric mean of the MSE×100 and BadPix(0.07)
  ratios; ``all``: of those and the Q25×100 ratio) is picked and its held-out MSE×100 and
  BadPix(0.07) are reported beside the default's (the leave-one-out table), with the held-out
  ratios of all three metrics.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
import tomllib

jax.config.update(
    "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

from mvedge_jax.io import OutputWriter, load_light_field  # noqa: E402
from mvedge_jax.metrics import benchmark_metrics, depth_metrics  # noqa: E402
from mvedge_jax.pipeline import (  # noqa: E402
    PipelineConfig,
    config_from_dict,
    estimate_disparity,
    hyperparameter_paths,
    with_values,
    write_outputs,
)
from mvedge_jax.reconstruct import ReconstructConfig, sharpen  # noqa: E402
from mvedge_jax.synthetic import VARIANTS, default_light_field  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from error_split import SCENES as VALIDATION_SCENES  # noqa: E402
from error_split import (  # noqa: E402
    diffuse_centre,
    load_scene,
    run_pipeline,
)

DATA = Path(os.environ.get("MVEDGE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
GT_SCENES = ["hci4d/stratified/backgammon", "hci4d/additional/antinous", "hci_old/stillLife_lf_3x3"]
# Thesis Table 6.1 (Ch. 6 method, centre view): MSE×100, Q25 (SPEC §8).
THESIS = {
    "cotton": (0.70, 0.74),
    "dino": (0.45, 0.85),
    "sideboard": (1.03, 1.22),
    "boxes": (7.52, 1.41),
}
# Targets of the main-job issue: MSE×100, BadPix(0.07).
TARGETS = {"backgammon": (1.2, 1.5), "antinous": (5.0, 10.0)}
# Candidate values (one parameter at a time) of the centre-view defaults of ReconstructConfig
# (dotted paths relative to it).
SENSITIVITY = {
    "centre.omega": (50.0, 450.0),
    "centre.a": (1.5, 4.5),
    "centre.c": (0.3, 3.0),
    "centre.eps": (1e-6, 1e-5),
    "centre.conf_beta": (3.0, 30.0),
    "centre.offset_scale": (0.5, 1.5),
    "sharpen.wmf_sigma": (0.025, 0.1),
    "sharpen.refine_jump": (0.1, 0.4),
    "sharpen.matte_jump": (0.1, 0.4),
    "sharpen.matte_min_separation": (0.05, 0.2),
}
# The leave-one-out grid: the thresholds that decide where the sharpening acts (the stage that
# changes the error most on every scene, experiments/error_split.py; on slanted planes a
# 7-px window spans more than 0.2 px of disparity, so the 0.2 thresholds act inside them).
LOO_GRID = {
    "sharpen.refine_jump": (0.2, 0.4, 0.8),
    "sharpen.matte_jump": (0.2, 0.4, 0.8),
}


def replaced(values: dict) -> ReconstructConfig:
    """The default `ReconstructConfig` with the fields at the dotted paths of ``values``
    (relative to it, e.g. ``"centre.omega"``) replaced and validated (`with_values`)."""
    full = {f"reconstruct.{path}": v for path, v in values.items()}
    return with_values(PipelineConfig(), full).reconstruct


def run_scene(lf, out_root: str | None, config: PipelineConfig | None = None) -> dict:
    t0 = time.perf_counter()
    result = estimate_disparity(lf, config)
    total = time.perf_counter() - t0
    if out_root:
        writer = OutputWriter(Path(out_root) / lf.name)
    else:
        writer = OutputWriter(Path("/tmp") / f"mvedge_ch6_{os.getpid()}" / lf.name)
    metrics = write_outputs(writer, lf, result, seconds_total=total)
    if out_root:
        writer.commit()
    else:
        writer.abort()
    if lf.gt_disparity is not None:
        rc, cc = lf.centre_index
        metrics["hci"] = benchmark_metrics(
            np.asarray(result.disparity[rc, cc]),
            np.asarray(lf.gt_disparity[rc, cc]),
            np.asarray(lf.gt_mask[rc, cc]),
        )
    metrics["scene"] = lf.name
    return metrics


def _score_scenes(configs: dict, cache: Path | None) -> dict:
    """``{scene: {label: (MSE×100, BadPix(0.07), Q25×100)}}`` of the sharpened centre view
    (compiled once per scene: only array leaves of the configs differ)."""
    out = {}
    for name in VALIDATION_SCENES:
        lf = load_scene(name)
        rc, cc = lf.centre_index
        base = run_pipeline(lf, PipelineConfig(), cache)
        edges = jax.tree.map(jax.numpy.asarray, base["edges"])
        surface = jax.tree.map(jax.numpy.asarray, base["surface"])
        gt = np.asarray(lf.gt_disparity[rc, cc])
        out[name] = {}
        diffused = {}
        t0 = time.perf_counter()
        for label, cfg in configs.items():
            # The centre diffusion (eq 6.1) reads ``cfg.centre`` and ``cfg.seeds``; the other
            # swept fields act in the sharpening only, so one diffusion serves all of them.
            # Array leaves by value, static fields through the tree structure.
            part = (cfg.centre, cfg.seeds)
            key = (jax.tree.structure(part), tuple(float(v) for v in jax.tree.leaves(part)))
            if key not in diffused:
                diffused[key] = diffuse_centre(lf.views, edges, surface, cfg)
            m = depth_metrics(np.asarray(sharpen(lf.views, diffused[key], cfg)), gt)
            out[name][label] = (m["mse_x100"], m["badpix_0.07"], m["q25_x100"])
        print(f"  {name}: {len(configs)} configs in {time.perf_counter() - t0:.1f} s", flush=True)
    return out


#: criterion -> the columns of `_score_scenes`' tuples whose ratios it averages.
CRITERIA = {"mse": (0,), "mse+badpix": (0, 1), "all": (0, 1, 2)}


def _ratio(scores: dict, scenes, label, criterion: str = "mse") -> float:
    """Geometric mean over ``scenes`` of MSE×100(label) / MSE×100(default); with
    ``criterion="mse+badpix"`` the geometric mean of that and the BadPix(0.07) ratio, with
    ``"all"`` of those and the Q25×100 ratio."""
    cols = CRITERIA[criterion]
    logs = [
        np.log(max(scores[s][label][c], 1e-3) / max(scores[s]["default"][c], 1e-3))
        for s in scenes
        for c in cols
    ]
    return float(np.exp(np.mean(logs)))


def sensitivity(cache: Path | None) -> dict:
    configs = {"default": ReconstructConfig()}
    for name, values in SENSITIVITY.items():
        for v in values:
            configs[f"{name}={_fmt(v)}"] = replaced({name: v})
    scores = _score_scenes(configs, cache)
    scenes = list(scores)
    head = f"{'config':<26}" + "".join(f"{s[:11]:>12}" for s in scenes) + f"{'geo-mean':>10}"
    print("MSE×100 ratio to the default (sharpened centre view); default row: MSE×100")
    print(head)
    print("-" * len(head))
    for label in configs:
        if label == "default":
            cells = "".join(f"{scores[s]['default'][0]:>12.3f}" for s in scenes)
            print(f"{label:<26}{cells}{'':>10}")
            continue
        cells = "".join(f"{scores[s][label][0] / scores[s]['default'][0]:>12.3f}" for s in scenes)
        print(f"{label:<26}{cells}{_ratio(scores, scenes, label):>10.3f}")
    return scores


def _static_grid_paths(config=None, prefix: str = "") -> dict[str, str]:
    """Dotted paths of the static ``int``/``float``/``str`` fields of `ReconstructConfig`
    (relative to it) and their kinds; a grid over them recompiles the sharpening once per
    value."""
    import dataclasses

    from mvedge_jax._fields import field_spec

    config = ReconstructConfig() if config is None else config
    out = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        spec = field_spec(f)
        if isinstance(value, eqx.Module):
            out.update(_static_grid_paths(value, f"{prefix}{f.name}."))
        elif spec is not None and spec.kind in ("int", "float", "str"):
            out[f"{prefix}{f.name}"] = spec.kind
    return out


def _fmt(value) -> str:
    """A grid value as it appears in a label: numbers ``:g``, strings as they are."""
    return value if isinstance(value, str) else f"{value:g}"


def parse_grid(text: str) -> dict[str, tuple]:
    """``"name=v1,v2;name2=v3,v4"`` → ``{name: (v1, v2), name2: (v3, v4)}`` (array fields of
    `ReconstructConfig` by dotted path, e.g. ``sharpen.wmf_sigma``, or its static numeric or
    string fields, e.g. ``sharpen.wmf_slope_baseline``, ``sharpen.matte_colour``: those
    recompile per value)."""
    prefix = "reconstruct."
    fields = {p.removeprefix(prefix) for p in hyperparameter_paths() if p.startswith(prefix)}
    statics = _static_grid_paths()
    grid = {}
    for part in text.split(";"):
        name, _, values = part.partition("=")
        name = name.strip()
        if (name not in fields and name not in statics) or not values:
            raise ValueError(
                f"bad grid entry {part!r}: use NAME=V1,V2 with a ReconstructConfig array field "
                "(a dotted path such as sharpen.wmf_sigma) or static numeric or string field"
            )
        kind = statics.get(name)
        if kind == "str":
            grid[name] = tuple(v.strip() for v in values.split(","))
        else:
            cast = int if kind == "int" else float
            grid[name] = tuple(cast(float(v)) for v in values.split(","))
    return grid


def leave_one_out(cache: Path | None, grid: dict | None = None, criterion: str = "mse") -> dict:
    grid = LOO_GRID if grid is None else grid
    names = list(grid)
    combos = list(itertools.product(*grid.values()))
    configs = {"default": ReconstructConfig()}
    for combo in combos:
        label = ", ".join(f"{n}={_fmt(v)}" for n, v in zip(names, combo, strict=True))
        configs[label] = replaced(dict(zip(names, combo, strict=True)))
    scores = _score_scenes(configs, cache)
    scenes = list(scores)
    labels = [k for k in configs if k != "default"]
    head = (
        f"{'held out':<22}{'picked on the other scenes':<40}{'MSE×100 dflt':>13}"
        f"{'→ picked':>10}{'BP.07 dflt':>11}{'→ picked':>10}"
    )
    print(f"Leave-one-scene-out over {', '.join(names)} (sharpened centre view)")
    print(head)
    print("-" * len(head))
    table = []
    for held in scenes:
        others = [s for s in scenes if s != held]
        pick = min(labels, key=lambda lab: _ratio(scores, others, lab, criterion))
        d, p = scores[held]["default"], scores[held][pick]
        table.append({"held_out": held, "picked": pick, "default": d, "held_out_score": p})
        print(f"{held:<22}{pick:<40}{d[0]:>13.3f}{p[0]:>10.3f}{d[1]:>11.2f}{p[1]:>10.2f}")

    def held_out(col: int) -> float:  # geometric mean of held-out / default in one column
        logs = [
            np.log(max(r["held_out_score"][col], 1e-3) / max(r["default"][col], 1e-3))
            for r in table
        ]
        return float(np.exp(np.mean(logs)))

    mean_ratio, bp_ratio, q25_ratio = held_out(0), held_out(1), held_out(2)
    best_all = min(labels, key=lambda lab: _ratio(scores, scenes, lab, criterion))
    print(f"picked by: {criterion} ratio to the default, geometric mean over the other scenes")
    print(f"held-out MSE×100 ratio to the default, geometric mean over scenes: {mean_ratio:.3f}")
    print(f"held-out BadPix(0.07) ratio to the default, geometric mean over scenes: {bp_ratio:.3f}")
    print(f"held-out Q25×100 ratio to the default, geometric mean over scenes: {q25_ratio:.3f}")
    print(
        f"best on all scenes: {best_all} (ratio {_ratio(scores, scenes, best_all, criterion):.3f})"
    )
    return {
        "grid": grid,
        "criterion": criterion,
        "scores": scores,
        "loo": table,
        "held_out_ratio": mean_ratio,
        "held_out_badpix_ratio": bp_ratio,
        "held_out_q25_ratio": q25_ratio,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "scenes",
        nargs="*",
        help="scene folders or names of experiments/error_split.py's SCENES (backgammon, "
        "antinous, default, textureless, ...); default: all GT scenes in the data",
    )
    ap.add_argument("--json", help="write the rows as a JSON list")
    ap.add_argument("--out", help="write full outputs per scene under this folder")
    ap.add_argument("--no-synthetic", action="store_true", help="skip the synthetic scenes")
    ap.add_argument("--variants", action="store_true", help="also the synthetic variants")
    ap.add_argument(
        "--seed",
        type=int,
        default=0,
        help="texture seed of the synthetic variants (and wide's layout); seeds other than 0 "
        "are renders no default was chosen on",
    )
    ap.add_argument("--sensitivity", action="store_true", help="one-at-a-time sensitivity")
    ap.add_argument("--loo", action="store_true", help="leave-one-scene-out table")
    ap.add_argument("--cache", help="folder of cached edges/surfaces (with --loo/--sensitivity)")
    ap.add_argument("--config", help="a TOML pipeline config (as `mvedge depth --config`)")
    ap.add_argument(
        "--grid", help="--loo grid, e.g. 'sharpen.wmf_sigma=0.025,0.05;centre.conf_beta=3,10'"
    )
    ap.add_argument(
        "--criterion",
        choices=CRITERIA,
        default="mse",
        help="--loo: pick by the MSE×100 ratio, or by the geometric mean of the MSE×100 and "
        "BadPix(0.07) ratios (mse+badpix), or of those and the Q25×100 ratio (all)",
    )
    args = ap.parse_args(argv)
    if args.seed and (args.sensitivity or args.loo):
        ap.error("--seed applies to the scene run; --loo and --sensitivity use seed 0")
    if args.sensitivity or args.loo:
        cache = Path(args.cache) if args.cache else None
        if args.sensitivity:
            out = sensitivity(cache)
        else:
            grid = parse_grid(args.grid) if args.grid else None
            out = leave_one_out(cache, grid, args.criterion)
        if args.json:
            Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
        return 0
    config = None
    if args.config:
        config = config_from_dict(tomllib.loads(Path(args.config).read_text()))
    scenes = args.scenes or [str(DATA / s) for s in GT_SCENES]
    lfs = [(s, None) for s in scenes]
    if not args.scenes and not args.no_synthetic:
        lfs.append(("synthetic", default_light_field()))
        if args.variants:
            lfs += [(k, None) for k in VARIANTS]
    if args.seed and not {s for s, _ in lfs} & set(VARIANTS):
        ap.error("--seed renders the synthetic variants: name them or use --variants")
    rows = []
    head = (
        f"{'scene':<14}{'MSE×100':>9}{'BP.01':>8}{'BP.03':>8}{'BP.07':>8}{'Q25×100':>9}"
        f"{'consist.':>10}{'edges s':>9}{'surf s':>8}{'recon s':>9}{'total s':>9}"
        f"{'compile s':>10}{'HCI MSE':>9}{'HCI BP.07':>10}{'HCI Q25':>9}{'worst view':>11}"
        "  thesis/target"
    )
    print(head)
    print("-" * len(head))
    for path, lf in lfs:
        if lf is None:
            if path in VALIDATION_SCENES:
                lf = load_scene(path, args.seed)
            else:
                lf = load_light_field(path)
        m = run_scene(lf, args.out, config)
        rows.append(m)
        st = m["seconds_per_stage"]
        ref = ""
        if lf.name in THESIS:
            ref = f"thesis MSE×100 {THESIS[lf.name][0]}, Q25 {THESIS[lf.name][1]}"
        elif lf.name in TARGETS:
            ref = f"target MSE×100 ≤ {TARGETS[lf.name][0]}, BP.07 ≤ {TARGETS[lf.name][1]}"
        g = lambda k, m=m: f"{m[k]:8.3f}" if k in m else f"{'-':>8}"
        h = m.get("hci", {})
        worst = m.get("all_views", {}).get("worst_view_mse_x100", np.nan)
        print(
            f"{lf.name:<14}{g('mse_x100'):>9}{g('badpix_0.01')}{g('badpix_0.03')}"
            f"{g('badpix_0.07')}{g('q25_x100'):>9}{m['view_consistency']:10.4f}"
            f"{st.get('edges', 0):9.2f}{st.get('surface', 0):8.2f}{st.get('reconstruct', 0):9.2f}"
            f"{m['seconds_total']:9.2f}{m['compile_seconds']:10.2f}"
            f"{h.get('mse_x100', np.nan):9.3f}{h.get('badpix_0.07', np.nan):10.3f}"
            f"{h.get('q25_x100', np.nan):9.3f}{worst:11.3f}  {ref}"
        )
        if "all_views" in m:
            a = m["all_views"]
            print(
                f"{'  all views':<14}{a['mse_x100']:9.3f}{a['badpix_0.01']:8.3f}"
                f"{a['badpix_0.03']:8.3f}{a['badpix_0.07']:8.3f}{a['q25_x100']:9.3f}"
            )
        sys.stdout.flush()
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
