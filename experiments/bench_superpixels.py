"""Time `superpixels` on one light field after compilation (thesis Ch. 5; issue target:
9x9x512² in <= 20 s on the 2-core CPU).

Usage:
    PYTHONPATH=. python experiments/bench_superpixels.py ../shared/data/hci4d/stratified/backgammon
    PYTHONPATH=. python experiments/bench_superpixels.py \
        ../shared/data/hci4d/stratified/backgammon --dense --seed-candidates 1 6

Computes the edges and surface vectors once (with ``--dense``: the Ch. 6 chain,
`estimate_disparity`, whose dense disparity is passed to `superpixels` as the CLI's default
does), then calls `superpixels` on them: once per ``--seed-candidates`` value to compile, then
``--repeat`` rounds that alternate the values. Prints the seconds per stage of every timed
call and the 1-minute load average before and after (the machine is shared).
"""

from __future__ import annotations

import argparse
import os
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("path")
    ap.add_argument("--size", type=float, default=20.0)
    ap.add_argument("--scale", type=float, default=None)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--dense", action="store_true", help="pass the Ch. 6 dense disparity")
    ap.add_argument(
        "--seed-candidates", type=int, nargs="+", default=[6], help="values to alternate"
    )
    args = ap.parse_args()

    import jax

    from mvedge_jax.edges import detect_edges
    from mvedge_jax.io import load_light_field
    from mvedge_jax.pipeline import estimate_disparity
    from mvedge_jax.superpixels import SuperpixelConfig, superpixels
    from mvedge_jax.surface import surface_vectors

    lf = load_light_field(args.path, scale=args.scale)
    configs = {n: SuperpixelConfig(size=args.size, seed_candidates=n) for n in args.seed_candidates}
    first = next(iter(configs.values()))
    t0 = time.perf_counter()
    disparity = None
    if args.dense:
        est = estimate_disparity(lf)
        edges, offset, disparity = est.edges, est.surface.offset, est.disparity
        jax.block_until_ready(disparity)
    else:
        edges = detect_edges(lf, first.edges)
        offset = surface_vectors(edges, lf.centre_view, first.surface).offset
        jax.block_until_ready(offset)
    what = "Ch. 6 chain" if args.dense else "edges + surface"
    print(
        f"{lf.name} {lf.grid} {lf.size}: {what} (with compilation) {time.perf_counter() - t0:.1f} s"
    )
    kw = dict(edges=edges, surface_offset=offset, disparity=disparity)
    for cfg in configs.values():
        superpixels(lf, cfg, **kw)  # compiles
    for i in range(args.repeat):
        for n, cfg in configs.items():
            load0 = os.getloadavg()[0]
            t0 = time.perf_counter()
            res = superpixels(lf, cfg, **kw)
            total = time.perf_counter() - t0
            stages = ", ".join(f"{k} {v:.2f}" for k, v in res.seconds.items())
            print(
                f"round {i + 1}, seed_candidates {n}: {total:.2f} s ({stages}); "
                f"load average {load0:.1f} -> {os.getloadavg()[0]:.1f}"
            )


if __name__ == "__main__":
    main()
