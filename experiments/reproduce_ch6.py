"""Reproduce thesis Table 6.1 style numbers: the Ch. 6 pipeline on every scene with ground truth.

Usage:
    python experiments/reproduce_ch6.py [SCENE_DIR ...] [--json OUT.json] [--out DIR]

Without arguments it runs every ground-truth scene in ``$MVEDGE_DATA`` (default
``../shared/data``): backgammon, antinous, stillLife, and the synthetic default scene. Prints one
row per scene (MSE×100, BadPix(0.01/0.03/0.07), Q25×100, view consistency, seconds per stage)
and, for scenes the thesis used, the thesis' Table 6.1 numbers beside them. With ``--out``, the
full `mvedge depth` outputs (PFMs, PNGs, metrics.json) are written per scene.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update(
    "jax_compilation_cache_dir", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

from mvedge_jax.io import OutputWriter, load_light_field  # noqa: E402
from mvedge_jax.pipeline import estimate_disparity, write_outputs  # noqa: E402
from mvedge_jax.synthetic import default_light_field  # noqa: E402

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
TARGETS = {"backgammon": (2.0, 12.0), "antinous": (10.0, 18.0)}


def run_scene(lf, out_root: str | None) -> dict:
    t0 = time.perf_counter()
    result = estimate_disparity(lf)
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
    return metrics


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("scenes", nargs="*", help="scene folders (default: all GT scenes in the data)")
    ap.add_argument("--json", help="write the rows as a JSON list")
    ap.add_argument("--out", help="write full outputs per scene under this folder")
    ap.add_argument("--no-synthetic", action="store_true", help="skip the synthetic scene")
    args = ap.parse_args(argv)
    scenes = args.scenes or [str(DATA / s) for s in GT_SCENES]
    lfs = [(s, None) for s in scenes]
    if not args.scenes and not args.no_synthetic:
        lfs.append(("synthetic", default_light_field()))
    rows = []
    head = (
        f"{'scene':<14}{'MSE×100':>9}{'BP.01':>8}{'BP.03':>8}{'BP.07':>8}{'Q25×100':>9}"
        f"{'consist.':>10}{'edges s':>9}{'surf s':>8}{'recon s':>9}{'total s':>9}"
        f"{'compile s':>10}  thesis/target"
    )
    print(head)
    print("-" * len(head))
    for path, lf in lfs:
        if lf is None:
            lf = load_light_field(path)
        m = run_scene(lf, args.out)
        rows.append(m)
        st = m["seconds_per_stage"]
        ref = ""
        if lf.name in THESIS:
            ref = f"thesis MSE×100 {THESIS[lf.name][0]}, Q25 {THESIS[lf.name][1]}"
        elif lf.name in TARGETS:
            ref = f"target MSE×100 ≤ {TARGETS[lf.name][0]}, BP.07 ≤ {TARGETS[lf.name][1]}"
        g = lambda k, m=m: f"{m[k]:8.3f}" if k in m else f"{'-':>8}"
        print(
            f"{lf.name:<14}{g('mse_x100'):>9}{g('badpix_0.01')}{g('badpix_0.03')}"
            f"{g('badpix_0.07')}{g('q25_x100'):>9}{m['view_consistency']:10.4f}"
            f"{st.get('edges', 0):9.2f}{st.get('surface', 0):8.2f}{st.get('reconstruct', 0):9.2f}"
            f"{m['seconds_total']:9.2f}{m['compile_seconds']:10.2f}  {ref}"
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
