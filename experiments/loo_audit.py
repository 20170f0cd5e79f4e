"""Leave-one-scene-out audit of the chain's array hyperparameters (whole chain).

    python experiments/loo_audit.py [--paths P1,P2,...] [--factors 0.5,2]
        [--scenes default,thin,...] [--real] [--set P=V ...] [--majority]
        [--criterion mse|mse+badpix] [--json OUT]

Every field of `hyperparameter_paths` (or those of ``--paths``) is tried at its default (that of
`PipelineConfig()`, or of ``--set P=V`` arguments) and at the default times each factor, clipped
into the field's declared bounds. A field whose default is 0 or not finite is not moved by a
factor and is skipped; `experiments/loo_views.py` takes explicit values for it. The scenes are
those of `loo_views.py` (``--real`` adds backgammon and antinous, scored on their centre view)
and are loaded once; the array leaves do not recompile, so after the first compilation a 128²
synthetic scene costs about a second per run and a 512² real scene about 12 s on the 2-core CPU.

For each field, the leave-one-out of `loo_views.py` (the value picked on the other scenes by
the geometric mean of the criterion's ratios to the default, scored on the held-out scene) is
condensed to one row: how many folds pick a value other than the default, and the geometric
means over the held-out scenes of the picked values' ratios to the default (all views, worst
view, BadPix(0.07)). A field whose folds agree on one value and whose held-out means are below
1 is a candidate for a new default; `loo_views.py` then gives its full table. ``--majority``
takes a value only where it gains on most of the other scenes (see `loo_views.leave_one_out`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from error_split import load_scene  # noqa: E402
from loo_views import (  # noqa: E402
    _fmt,
    add_scene_arguments,
    leave_one_out,
    parse_sets,
    scene_list,
    score_light_field,
)

from mvedge_jax.pipeline import (  # noqa: E402
    PipelineConfig,
    get_path,
    hyperparameter_paths,
    path_spec,
    with_values,
)


def trial_values(config: PipelineConfig, path: str, factors: list[float]) -> list[float]:
    """``[default, default × f for f in factors]`` clipped into the field's bounds, without
    repeats; ``[]`` where the default is 0 or not finite."""
    default = float(get_path(config, path))
    if default == 0.0 or not math.isfinite(default):
        return []
    spec = path_spec(config, path)
    values = [default]
    for f in factors:
        v = default * f
        if spec.upper is not None:
            v = min(v, spec.upper)
        if spec.lower is not None and (v < spec.lower or (spec.lower_open and v == spec.lower)):
            continue
        v = float(np.float32(v))
        if v not in values:
            values.append(v)
    return values if len(values) > 1 else []


def audit_row(scores: dict, values: list[float], criterion: str, majority: bool = False) -> dict:
    """One field's leave-one-out condensed: folds off the default, held-out geometric-mean
    ratios of the picked values to the default (all views, worst view, BadPix(0.07)) and the
    value each fold picks."""
    rows = leave_one_out(scores, values, criterion, majority)
    logs = np.zeros(3)
    for r in rows:
        ref, held = r["reference"], r["held_out_score"]
        logs += [math.log(max(h, 1e-3) / max(a, 1e-3)) for h, a in zip(held, ref, strict=True)]
    return {
        "folds_off_default": sum(r["picked"] != values[0] for r in rows),
        "held_out_ratio": [float(math.exp(x / len(rows))) for x in logs],
        "picked": {r["held_out"]: r["picked"] for r in rows},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--paths", help="comma-separated fields (default: every hyperparameter)")
    ap.add_argument("--factors", default="0.5,2", help="multipliers of the default")
    add_scene_arguments(ap)
    ap.add_argument("--criterion", choices=("mse", "mse+badpix"), default="mse+badpix")
    ap.add_argument("--json", help="write every score and row as JSON")
    args = ap.parse_args(argv)
    config = parse_sets(ap, args.set)
    known = hyperparameter_paths(config)
    paths = known if args.paths is None else tuple(p.strip() for p in args.paths.split(","))
    unknown = [p for p in paths if p not in known]
    if unknown:
        ap.error(f"not hyperparameters of PipelineConfig: {unknown}")
    factors = [float(f) for f in args.factors.split(",")]
    scenes = scene_list(ap, args)
    light_fields = {s: load_scene(s) for s in scenes}
    base = {s: score_light_field(lf, config) for s, lf in light_fields.items()}
    print("default: " + ", ".join(f"{s} {v[0]:.3f}/{v[1]:.3f}/{v[2]:.2f}" for s, v in base.items()))
    out, skipped = {}, []
    print(
        "\n| field | default | tried | folds off the default | held-out ratio: all views "
        "| worst view | BadPix(0.07) |\n|---|---|---|---|---|---|---|",
        flush=True,
    )
    for path in paths:
        values = trial_values(config, path, factors)
        if not values:
            skipped.append(path)
            continue
        t = time.perf_counter()
        scores = {
            s: {
                values[0]: base[s],
                **{v: score_light_field(lf, with_values(config, {path: v})) for v in values[1:]},
            }
            for s, lf in light_fields.items()
        }
        row = audit_row(scores, values, args.criterion, args.majority)
        out[path] = {
            "values": values,
            "scores": {s: {_fmt(v): sc for v, sc in d.items()} for s, d in scores.items()},
            **row,
        }
        a, w, b = row["held_out_ratio"]
        picks = sorted({_fmt(v) for v in row["picked"].values()})
        print(
            f"| `{path}` | {_fmt(values[0])} | {', '.join(_fmt(v) for v in values[1:])} "
            f"| {row['folds_off_default']} of {len(scenes)} ({', '.join(picks)}) "
            f"| {a:.3f} | {w:.3f} | {b:.3f} |  ({time.perf_counter() - t:.0f} s)",
            flush=True,
        )
        if args.json:  # rewritten after every field, so that a stopped audit keeps its rows
            payload = {
                "factors": factors,
                "scenes": scenes,
                "criterion": args.criterion,
                "set": args.set,
                "majority": args.majority,
                "default": base,
                "fields": out,
                "skipped": skipped,
            }
            Path(args.json).write_text(json.dumps(payload, indent=1))
    if skipped:
        print(f"\nskipped (default 0 or not finite): {', '.join(skipped)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
