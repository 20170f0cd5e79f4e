"""Time `superpixels` on one light field after compilation (thesis Ch. 5; issue target:
9x9x512² in <= 20 s on the 2-core CPU).

Usage:
    PYTHONPATH=. python experiments/bench_superpixels.py ../shared/data/hci4d/stratified/backgammon

Runs edge detection and surface vectors once, then `superpixels` ``--repeat`` times on the
same edges (the first call compiles); prints the seconds per stage of every call and the
1-minute load average before and after (the machine is shared).
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
    args = ap.parse_args()

    import jax

    from mvedge_jax.edges import detect_edges
    from mvedge_jax.io import load_light_field
    from mvedge_jax.superpixels import SuperpixelConfig, superpixels
    from mvedge_jax.surface import surface_vectors

    lf = load_light_field(args.path, scale=args.scale)
    cfg = SuperpixelConfig(size=args.size)
    t0 = time.perf_counter()
    edges = detect_edges(lf, cfg.edges)
    offset = jax.block_until_ready(surface_vectors(edges, lf.centre_view, cfg.surface).offset)
    print(
        f"{lf.name} {lf.grid} {lf.size}: edges + surface (with compilation) "
        f"{time.perf_counter() - t0:.1f} s"
    )
    for i in range(args.repeat):
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        res = superpixels(lf, cfg, edges=edges, surface_offset=offset)
        total = time.perf_counter() - t0
        stages = ", ".join(f"{k} {v:.2f}" for k, v in res.seconds.items())
        print(
            f"call {i + 1}: {total:.2f} s ({stages}); load average {load0:.1f} -> "
            f"{os.getloadavg()[0]:.1f}"
        )


if __name__ == "__main__":
    main()
