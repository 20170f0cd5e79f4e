"""Compilation benchmark of the main job: cold compile, warm-cache compile, and the second call.

Each phase runs in a fresh Python process (as `mvedge depth` does), so the in-process cache
of compiled stages is empty and only JAX's persistent compilation cache carries over:

1. ``cold``: empty caches: `estimate_disparity` traces and compiles every stage.
2. ``warm``: a new process with the caches of phase 1 (JAX's persistent compilation cache and
   the exported stages of `mvedge_jax._cache.StageStore`): nothing is traced.
3. Within the warm process, a second call with a new hyperparameter value
   (``reconstruct.centre.omega`` and ``edges.filter.presmooth_sigma`` changed): no recompilation.

Usage::

    python experiments/bench_compile.py [SCENE ...] [--repeat 1]

``SCENE`` is a light-field folder (default: HCI backgammon under ``$MVEDGE_DATA`` or
``../shared/data``), ``synthetic`` (the embedded default light field, 9×9×160²) or ``small``
(a synthetic 5×5×48² light field). Prints one table row per scene: seconds of the cold
compile, warm-cache compile, the first call's run, the second call with new hyperparameter
values (compile + run), and the second call's wall over the first call's wall in the warm
and in the cold process.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MVEDGE_DATA", ROOT.parent / "shared" / "data"))


def _phase(scene: str) -> dict:
    import time

    import jax
    import jax.numpy as jnp

    from mvedge_jax.io import load_light_field
    from mvedge_jax.pipeline import PipelineConfig, estimate_disparity, replace_paths
    from mvedge_jax.synthetic import default_light_field, make_scene

    if scene == "synthetic":
        lf = default_light_field()
    elif scene == "small":
        lf = make_scene(5, grid=(5, 5), size=(48, 48), disparity_range=(-1.0, 1.0), n_objects=3)
    else:
        lf = load_light_field(scene)
    config = PipelineConfig()
    t0 = time.perf_counter()
    first = estimate_disparity(lf, config)
    first_wall = time.perf_counter() - t0
    changed = replace_paths(
        config,
        {
            "reconstruct.centre.omega": jnp.asarray(120.0),
            "edges.filter.presmooth_sigma": jnp.asarray(0.9),
        },
    )
    t0 = time.perf_counter()
    second = estimate_disparity(lf, changed)
    second_wall = time.perf_counter() - t0
    return {
        "scene": lf.name,
        "shape": list(lf.views.shape),
        "compile": first.compile_seconds,
        "run": sum(first.seconds_per_stage.values()),
        "first_wall": first_wall,
        "second_compile": second.compile_seconds,
        "second_wall": second_wall,
        "device": str(jax.devices()[0]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*")
    parser.add_argument("--phase-scene", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.phase_scene:
        print(json.dumps(_phase(args.phase_scene)))
        return
    scenes = args.scenes or [str(DATA / "hci4d" / "stratified" / "backgammon")]
    header = (
        f"{'scene':<22} {'cold compile s':>14} {'warm compile s':>14} {'first run s':>11} "
        f"{'2nd call s':>10} {'2nd/1st warm':>12} {'2nd/1st cold':>12}"
    )
    print(header)
    print("-" * len(header))
    for scene in scenes:
        with tempfile.TemporaryDirectory(prefix="mvedge-cache-") as cache:
            env = dict(os.environ, MVEDGE_JAX_CACHE=cache)
            rows = []
            for _ in ("cold", "warm"):
                out = subprocess.run(
                    [sys.executable, __file__, "--phase-scene", scene],
                    env=env,
                    check=True,
                    capture_output=True,
                    text=True,
                ).stdout
                rows.append(json.loads(out.strip().splitlines()[-1]))
        cold, warm = rows
        ratio = warm["second_wall"] / warm["first_wall"]
        ratio_cold = cold["second_wall"] / cold["first_wall"]
        print(
            f"{cold['scene']:<22} {cold['compile']:>14.1f} {warm['compile']:>14.1f} "
            f"{warm['run']:>11.2f} {warm['second_wall']:>10.2f} {ratio:>12.3f} "
            f"{ratio_cold:>12.3f}"
        )
        print(
            f"  ({'x'.join(map(str, cold['shape']))}, {cold['device']}; 2nd call compiled "
            f"{warm['second_compile']:.2f} s; '2nd/1st' = wall of the second call over the "
            f"first call's wall in the same process, compilation included)"
        )


if __name__ == "__main__":
    main()
