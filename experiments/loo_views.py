"""Leave-one-scene-out of one parameter on every view of the synthetic scenes (whole chain).

    python experiments/loo_views.py PATH V0,V1,... [--scenes default,thin,...] [--real]
        [--set P=V ...] [--majority] [--criterion mse|mse+badpix] [--json OUT]

``PATH`` is a field of `PipelineConfig` by dotted path: an array field (`hyperparameter_paths`,
e.g. ``reconstruct.sharpen.matte_view_jump``) or a static integer, float, boolean (``true``,
``false``) or string field (e.g. ``reconstruct.sharpen.matte_view_steps``,
``reconstruct.epi.hole_value``; one compilation per value); ``V0`` is the reference
value (normally the current default), against which the others are compared. For every
synthetic scene with ground truth in every view (the default scene and
`mvedge_jax.synthetic.VARIANTS`) and every value, the whole chain (`estimate_disparity`) runs
once (array leaves: one compilation per scene size) and is scored by the MSE×100 averaged over
all views, the worst view's MSE×100 and the BadPix(0.07) of all views. For each held-out
scene the value with the lowest geometric mean, over the other scenes, of the ratios to
``V0`` is picked (``--criterion mse``, the default: the two MSE×100 ratios; ``mse+badpix``:
those and the BadPix(0.07) ratio) and its held-out scores are printed beside ``V0``'s, then
every value's all-views ratios per scene. The real scenes (GT in the centre view only) cannot
score the other views: ``--real`` adds backgammon and antinous as two more scenes scored on
their centre view (its MSE×100 stands for both the all-views and the worst-view score), so
that a field of the edge or surface stages, which `experiments/reproduce_ch6.py --loo` keeps
at the default, is also chosen on the real scenes. ``--set P=V`` (repeatable) changes another
array field of the base configuration, for a second field's grid around a first one's pick.
``--majority`` lets a fold pick a value only where it gains on most of the other scenes (the
geometric mean alone lets one scene's large swing outweigh small losses on all the others).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from error_split import REAL, load_scene  # noqa: E402
from reproduce_ch6 import _ratio  # noqa: E402

from mvedge_jax.pipeline import (  # noqa: E402
    PipelineConfig,
    estimate_disparity,
    get_path,
    hyperparameter_paths,
    with_values,
)
from mvedge_jax.synthetic import VARIANTS  # noqa: E402

SCENES = ("default", *VARIANTS)
#: Scenes with ground truth in the centre view only, scored there (``--real``).
REAL_SCENES = tuple(REAL)


def _fmt(value) -> str:
    """A value of the grid as printed: numbers in ``g`` format, booleans and strings as they are."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return value if isinstance(value, str) else f"{value:g}"


def score_light_field(lf, config: PipelineConfig) -> tuple[float, float, float]:
    """``(all-views MSE×100, worst view MSE×100, all-views BadPix(0.07) %)`` of the whole
    chain on one light field, over the views and pixels its ground-truth mask marks valid
    (every pixel of every view for the synthetic scenes, the centre view for the real
    ones)."""
    gt = np.asarray(lf.gt_disparity)
    mask = np.ones(gt.shape, bool) if lf.gt_mask is None else np.asarray(lf.gt_mask)
    scored = mask.any(axis=(2, 3))
    d = np.asarray(estimate_disparity(lf, config).disparity)
    err = np.where(mask, d - gt, 0.0)
    per_view = 100 * (err**2).sum(axis=(2, 3))[scored] / mask.sum(axis=(2, 3))[scored]
    badpix = 100 * float((np.abs(err) > 0.07).sum() / mask.sum())
    return float(per_view.mean()), float(per_view.max()), badpix


def score_views(name: str, path: str, values: list, base: PipelineConfig | None = None) -> dict:
    """``{value: score_light_field(...)}`` of one scene, ``path`` of ``base`` (default
    `PipelineConfig()`) set to each value."""
    lf = load_scene(name)
    base = PipelineConfig() if base is None else base
    out = {}
    for v in values:
        t = time.perf_counter()
        out[v] = score_light_field(lf, with_values(base, {path: v}))
        print(
            f"  {name} {path}={_fmt(v)}: all views {out[v][0]:.3f}, worst view {out[v][1]:.3f}, "
            f"BadPix(0.07) {out[v][2]:.2f} ({time.perf_counter() - t:.0f} s)",
            flush=True,
        )
    return out


#: ``--criterion`` → `_ratio`'s criterion whose columns are those of `score_views`' tuples:
#: (all views, worst view) MSE×100, and with ``mse+badpix`` the all-views BadPix(0.07) too.
CRITERIA = {"mse": "mse+badpix", "mse+badpix": "all"}


def leave_one_out(
    scores: dict, values: list[float], criterion: str = "mse", majority: bool = False
) -> list[dict]:
    """Per held-out scene: the value picked on the others and the held-out scores.

    The pick is the value with the lowest geometric mean of the criterion's ratios to the
    reference over the other scenes. With ``majority``, a value other than the reference is a
    candidate only where its own ratio (per scene, the geometric mean of the criterion's
    columns) is below 1 on more than half of the other scenes, so that one scene's large swing
    cannot decide the pick alone."""
    ref, rows = values[0], []
    # `_ratio`'s geometric mean of the ratios of the criterion's columns to the "default"
    # entry, here the reference value.
    table = {s: {"default": d[ref], **d} for s, d in scores.items()}
    crit = CRITERIA[criterion]
    for held in scores:
        others = [s for s in scores if s != held]
        candidates = [
            v
            for v in values
            if v == ref
            or not majority
            or 2 * sum(_ratio(table, [s], v, crit) < 1 for s in others) > len(others)
        ]
        pick = min(candidates, key=lambda v: _ratio(table, others, v, crit))
        rows.append(
            {
                "held_out": held,
                "picked": pick,
                "reference": scores[held][ref],
                "held_out_score": scores[held][pick],
            }
        )
    return rows


def add_scene_arguments(ap: argparse.ArgumentParser) -> None:
    """The ``--scenes``, ``--real``, ``--set`` and ``--majority`` options (read by
    `scene_list`, `parse_sets` and `leave_one_out`)."""
    ap.add_argument("--scenes", default=",".join(SCENES), help="synthetic scenes (comma-separated)")
    ap.add_argument(
        "--real",
        action="store_true",
        help=f"also score {', '.join(REAL_SCENES)} (centre view: GT there only)",
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="P=V",
        help="array field P of the base configuration set to V (repeatable)",
    )
    ap.add_argument(
        "--majority",
        action="store_true",
        help="a value other than the reference is picked only where it gains on most of the "
        "other scenes",
    )


def scene_list(ap: argparse.ArgumentParser, args: argparse.Namespace) -> list[str]:
    """The scenes of ``--scenes`` and ``--real``; an argument error unless they are two or more
    known scenes."""
    scenes = [s.strip() for s in args.scenes.split(",")]
    if args.real:
        scenes += [s for s in REAL_SCENES if s not in scenes]
    if len(scenes) < 2 or any(s not in SCENES + REAL_SCENES for s in scenes):
        ap.error(f"need two or more scenes of {SCENES + REAL_SCENES}; got {scenes}")
    return scenes


def parse_sets(ap: argparse.ArgumentParser, sets: list[str]) -> PipelineConfig:
    """`PipelineConfig()` with the array fields of ``--set P=V`` arguments changed."""
    values = {}
    for item in sets:
        path, eq, value = item.partition("=")
        if not eq or path not in hyperparameter_paths():
            ap.error(f"--set takes P=V with P an array field of PipelineConfig; got {item!r}")
        values[path] = float(value)
    return with_values(PipelineConfig(), values)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "path",
        help="PipelineConfig array field (e.g. reconstruct.sharpen.matte_view_jump) or static "
        "integer, boolean or string field (e.g. reconstruct.sharpen.matte_view_steps)",
    )
    ap.add_argument("values", help="comma-separated values; the first is the reference")
    ap.add_argument(
        "--criterion",
        choices=tuple(CRITERIA),
        default="mse",
        help="mse: all-views and worst-view MSE×100; mse+badpix: and all-views BadPix(0.07)",
    )
    add_scene_arguments(ap)
    ap.add_argument("--json", help="write the scores and the table as JSON")
    args = ap.parse_args(argv)
    base = parse_sets(ap, args.set)
    if args.path in hyperparameter_paths():
        values = [float(v) for v in args.values.split(",")]
    else:
        try:
            current = get_path(PipelineConfig(), args.path)
        except AttributeError:
            current = None
        raw = args.values.split(",")
        if isinstance(current, bool):
            if any(v not in ("true", "false") for v in raw):
                ap.error(f"{args.path!r} takes true or false; got {args.values!r}")
            values = [v == "true" for v in raw]
        elif isinstance(current, int):
            values = [int(v) for v in raw]
        elif isinstance(current, float):
            values = [float(v) for v in raw]
        elif isinstance(current, str):
            values = raw
        else:
            ap.error(
                f"{args.path!r} is neither an array field of PipelineConfig (see "
                "hyperparameter_paths) nor a static integer, float, boolean or string field"
            )
    scenes = scene_list(ap, args)
    if len(values) < 2:
        ap.error(f"need two or more values; got {args.values!r}")
    scores = {s: score_views(s, args.path, values, base) for s in scenes}
    rows = leave_one_out(scores, values, args.criterion, args.majority)
    ref = values[0]
    print(f"\ncriterion: {args.criterion}")
    print(
        f"| held out | picked on the others | all views, {_fmt(ref)} → picked "
        f"| worst view, {_fmt(ref)} → picked | BadPix(0.07), {_fmt(ref)} → picked |"
    )
    print("|---|---|---|---|---|")
    for r in rows:
        (a0, w0, b0), (a1, w1, b1) = r["reference"], r["held_out_score"]
        print(
            f"| {r['held_out']} | {_fmt(r['picked'])} | {a0:.3f} → {a1:.3f} | {w0:.3f} → {w1:.3f} "
            f"| {b0:.2f} → {b1:.2f} |"
        )
    for col, name in ((0, "All-views MSE×100"), (2, "All-views BadPix(0.07)")):
        print(f"\n{name} ratio to {_fmt(ref)} ({', '.join(scenes)}):")
        for v in values[1:]:
            ratios = ", ".join(f"{scores[s][v][col] / scores[s][ref][col]:.3f}" for s in scenes)
            print(f"{_fmt(v)}: {ratios}")
    if args.json:
        payload = {
            "path": args.path,
            "values": values,
            "criterion": args.criterion,
            "set": args.set,
            "majority": args.majority,
            "scores": {s: {_fmt(v): sc for v, sc in d.items()} for s, d in scores.items()},
            "loo": rows,
        }
        Path(args.json).write_text(json.dumps(payload, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
