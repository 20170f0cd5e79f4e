"""Benchmark one optimisation step of the differentiable edge model (thesis Sec. 7.1.5).

Points are placed at the N strongest image-gradient pixels of a real view (HCI backgammon,
sub-pixel jitter) when the data folder is present, else uniformly at random; labels are
random disparities. Times (seconds, best of ``--repeat`` after compilation):

* ``render_seconds``   forward splatting + transmittance compositing (eqs 7.3–7.14)
* ``solve_seconds``    forward Poisson solve (eq 7.2)
* ``backward_seconds`` value_and_grad of render → solve → loss minus their forward time
* ``step_seconds``     one full jitted optimisation step (forward, backward, Adam update)
* ``compile_seconds``  first call of the step (tracing + XLA compile)
* ``overflow_points``  points that did not fit a tile (should be 0)

Example::

    .venv/bin/python experiments/bench_diff.py --points 50000 --size 512 --json out.json
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
import jax.numpy as jnp
import numpy as np

from mvedge_jax.diff import (
    BLOCKS,
    ModelConfig,
    OptimizeConfig,
    RenderConfig,
    image_gradient_magnitude,
    initial_params,
    predict,
    render,
    smoothness_weights,
)
from mvedge_jax.diff._optimize import Data, _adam, _step, objective
from mvedge_jax.solve import solve_poisson

DATA = Path(os.environ.get("MVEDGE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def _timeit(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def _scene(n: int, size: int, seed: int):
    rng = np.random.default_rng(seed)
    path = DATA / "hci4d" / "stratified" / "backgammon" / "input_Cam040.png"
    if path.is_file():
        import cv2

        img = cv2.imread(str(path))[..., ::-1].astype(np.float32) / 255.0
        img = cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA)
        mag = np.asarray(image_gradient_magnitude(img))
        idx = np.argsort(mag.ravel())[::-1][:n]
        yy, xx = np.unravel_index(idx, mag.shape)
        pos = np.stack([xx, yy], 1) + rng.uniform(-0.3, 0.3, (len(idx), 2))
        source = "backgammon gradient pixels"
    else:
        img = rng.uniform(0, 1, (size, size, 3)).astype(np.float32)
        pos = rng.uniform(0, size - 1, (n, 2))
        source = "uniform random"
    lab = rng.uniform(-2, 2, len(pos))
    target = rng.uniform(-2, 2, (size, size)).astype(np.float32)
    return img, pos.astype(np.float32), lab.astype(np.float32), target, source


def _levels(text: str) -> tuple[tuple[int, float], ...]:
    """``"48:1,96:0.35"`` → ``((48, 1.0), (96, 0.35))``."""
    try:
        return tuple((int(c), float(f)) for c, f in (p.split(":") for p in text.split(",")))
    except ValueError as err:
        raise click.BadParameter(f"expected capacity:fraction,...; got {text!r}") from err


@click.command()
@click.option("--points", default=50000, show_default=True)
@click.option("--size", default=512, show_default=True)
@click.option("--depth-samples", default=8, show_default=True, help="0 = exact integral")
@click.option("--tile-size", default=8, show_default=True)
@click.option(
    "--tile-levels",
    default="48:1,96:0.4,200:0.2",
    show_default=True,
    help="capacity:fraction of tiles, comma separated (RenderConfig.tile_levels)",
)
@click.option("--repeat", default=3, show_default=True)
@click.option("--seed", default=0, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
def main(points, size, depth_samples, tile_size, tile_levels, repeat, seed, json_path):
    img, pos, lab, target, source = _scene(points, size, seed)
    rcfg = RenderConfig(
        depth_samples=depth_samples, tile_size=tile_size, tile_levels=_levels(tile_levels)
    )
    mcfg = ModelConfig(render=rcfg)
    cfg = OptimizeConfig(model=mcfg)
    params = initial_params(pos, lab, img, mcfg)
    shape = (size, size)

    f_render = eqx.filter_jit(lambda p: render(p.position, p.label, p.R, shape, rcfg))
    out = f_render(params)
    jax.block_until_ready(out)
    render_s = _timeit(lambda: f_render(params), repeat)

    wx, wy = smoothness_weights(params.Q, mcfg.smoothness)
    lam = out.weight * mcfg.label_weight
    f_solve = eqx.filter_jit(lambda lam, S: solve_poisson(lam, S, wx, wy, config=mcfg.solver))
    sol = f_solve(lam, out.label)
    jax.block_until_ready(sol)
    solve_s = _timeit(lambda: f_solve(lam, out.label), repeat)

    data = Data(
        centre=jnp.asarray(img),
        others=None,
        offsets=None,
        target=jnp.asarray(target),
        target_mask=None,
    )
    f_fwd = eqx.filter_jit(lambda p: objective(predict(p, mcfg).disparity, data, cfg.loss))
    jax.block_until_ready(f_fwd(params))
    fwd_s = _timeit(lambda: f_fwd(params), repeat)
    f_vg = eqx.filter_jit(
        jax.value_and_grad(lambda p: objective(predict(p, mcfg).disparity, data, cfg.loss))
    )
    jax.block_until_ready(f_vg(params))
    vg_s = _timeit(lambda: f_vg(params), repeat)

    states = tuple(_adam.init(getattr(params, b)) for b in BLOCKS)
    x0 = jnp.zeros(shape, jnp.float32)
    lr = jnp.asarray(0.015)
    blk = jnp.asarray(0, jnp.int32)
    t0 = time.perf_counter()
    res = _step(params, states, blk, lr, x0, None, data, cfg)
    jax.block_until_ready(res)
    compile_s = time.perf_counter() - t0
    step_s = _timeit(lambda: _step(params, states, blk, lr, x0, None, data, cfg), repeat)

    result = {
        "points": points,
        "size": size,
        "point_source": source,
        "depth_samples": depth_samples,
        "tile_size": tile_size,
        "tile_levels": tile_levels,
        "render_seconds": render_s,
        "solve_seconds": solve_s,
        "forward_seconds": fwd_s,
        "backward_seconds": max(vg_s - fwd_s, 0.0),
        "value_and_grad_seconds": vg_s,
        "step_seconds": step_s,
        "compile_seconds": compile_s,
        "solver_iterations": int(sol.iterations),
        "overflow_points": int(out.overflow),
        "cpu_count": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "backend": jax.default_backend(),
    }
    w = max(len(k) for k in result)
    for k, v in result.items():
        print(f"{k:<{w}}  {v:.3f}" if isinstance(v, float) else f"{k:<{w}}  {v}")
    if json_path:
        Path(json_path).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
