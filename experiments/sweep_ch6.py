"""Hyperparameter sweep of the thesis Ch. 6 reconstruction on a ground-truth scene (cf. Fig. 6.10).

Usage:
    python experiments/sweep_ch6.py SCENE_DIR --param centre.omega --values 10,30,100,150,300,1000
        [--param2 centre.c --values2 0.3,1,3] [--stage centre|full] [--scale 0.5]
        [--batch-size B] [--out DIR] [--json OUT.json] [--force]

Edge detection and surface vectors (thesis Ch. 4) run ONCE (`detect_edges`, `surface_vectors`:
the first two stages of `estimate_disparity`, same defaults and key); then the swept
stage is evaluated for every value (or every pair of values) of array leaves of
`ReconstructConfig`, named by their dotted path in it (``centre.omega``, ``centre.a``,
``centre.c``, ``centre.eps``, ``epi.c``, ``epi.data_weight``, …) without recompiling:

- ``--stage centre`` (default): the centre-view diffusion `centre_disparity` (eqs 6.1–6.3),
  ``jax.vmap``-ed over the parameter values and compiled once ahead of time (``--batch-size B``
  uses ``jax.lax.map(..., batch_size=B)`` instead, to bound memory on large images).
- ``--stage full``: the whole chain (`mvedge_jax.pipeline.sweep`: edges, surface vectors,
  centre, refinement, weighted median, EPI inpainting, off-cross-hair views) ``vmap``-ed over
  the values in one compiled program (``--batch-size B``: ``lax.map``), sharded over devices
  when several exist; any differentiable or threshold field of the chain can be swept, named
  by its dotted path (``edges.filter.presmooth_sigma``; a path that does not start with a
  stage, such as ``centre.omega``, means ``reconstruct.<path>``).
  The number of XLA compilations is printed as evidence that it compiled once.

Metrics are those of the centre view against its ground truth (`depth_metrics`). A table
(value(s), MSE×100, BadPix(0.07), Q25×100, seconds) is printed and a PNG is written into
``--out`` (default ``sweep_out/``): MSE×100 and BadPix(0.07) against the parameter (log x-axis
when the values span a decade or more; dashed line at the default), or 2-D heat maps when two
parameters are swept. Existing files are never overwritten without ``--force``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from mvedge_jax.edges import detect_edges, resolve_d_max
from mvedge_jax.io import load_light_field
from mvedge_jax.metrics import depth_metrics
from mvedge_jax.pipeline import (
    PipelineConfig,
    get_path,
    hyperparameter_paths,
    sweep,
    with_values,
)
from mvedge_jax.reconstruct import ReconstructConfig, centre_disparity
from mvedge_jax.surface import surface_vectors

METRIC_KEYS = ("mse_x100", "badpix_0.07", "q25_x100")
_BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"


class CompileCounter:
    """Counts XLA compilations (and their seconds) via `jax.monitoring` while installed.

    ``install()`` registers a duration listener once (jax offers no public way to remove it);
    ``snapshot()`` returns ``(n_backend_compiles, seconds in /jax/core/compile/*)`` so far;
    ``names`` lists the compiled functions in order.
    """

    def __init__(self):
        self.count = 0
        self.seconds = 0.0
        self.names: list[str] = []
        self._installed = False

    def _listener(self, event: str, duration: float, **kwargs) -> None:
        if event.startswith("/jax/core/compile/"):
            self.seconds += duration
            if event == _BACKEND_COMPILE:
                self.count += 1
                self.names.append(str(kwargs.get("fun_name", "?")))

    def install(self) -> CompileCounter:
        if not self._installed:
            jax.monitoring.register_event_duration_secs_listener(self._listener)
            self._installed = True
        return self

    def snapshot(self) -> tuple[int, float]:
        return self.count, self.seconds


_STAGES = ("edges", "surface", "reconstruct")


def full_path(param: str) -> str:
    """A dotted path of `PipelineConfig`: ``param`` itself when it starts with a stage name,
    else ``reconstruct.<param>``."""
    return param if param.split(".")[0] in _STAGES else f"reconstruct.{param}"


def sweepable_params() -> list[str]:
    """Dotted paths (relative to `ReconstructConfig`, e.g. ``centre.omega``) of its scalar
    array leaves (sweepable without recompiling)."""
    prefix = "reconstruct."
    return [p.removeprefix(prefix) for p in hyperparameter_paths() if p.startswith(prefix)]


def parse_values(text: str, param: str) -> np.ndarray:
    """Comma-separated floats → ``(K,)`` float64, each validated by `ReconstructConfig`.

    Raises:
        ValueError: on an empty list, a non-number, or a value the config rejects.
    """
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError as err:
        raise ValueError(
            f"--values for {param!r} must be comma-separated numbers; got {text!r}"
        ) from err
    if not vals:
        raise ValueError(f"no values given for {param!r}: {text!r}")
    for v in vals:  # raises ValueError on e.g. negative weights
        with_values(PipelineConfig(), {full_path(param): v})
    return np.asarray(vals, np.float64)


def with_params(base: ReconstructConfig, names: tuple[str, ...], values) -> ReconstructConfig:
    """``base`` with the leaves at the dotted paths ``names`` replaced by ``values`` (arrays or
    tracers)."""
    dtype = get_path(base, names[0]).dtype
    return eqx.tree_at(
        lambda c: tuple(get_path(c, n) for n in names),
        base,
        tuple(jnp.asarray(v, dtype) for v in values),
    )


def sweep_centre(edges, surface, centre_view, base, names, grid, batch_size=None):
    """`centre_disparity` for every row of ``grid`` ``(K, P)`` in one compiled call.

    The batched function is compiled ahead of time (``jit(...).lower(...).compile()``), so the
    run cannot recompile; ``vmap`` over the values, or ``lax.map`` with ``batch_size``.

    Returns:
        ``(maps (K, H, W) numpy, compile_seconds, run_seconds)``.
    """

    def one(vals, edges, surface, centre_view):
        cfg = with_params(base, names, tuple(vals[i] for i in range(len(names))))
        return centre_disparity(edges, surface, centre_view, cfg)

    def all_values(grid, edges, surface, centre_view):
        if batch_size:
            return jax.lax.map(
                lambda v: one(v, edges, surface, centre_view), grid, batch_size=batch_size
            )
        return jax.vmap(one, in_axes=(0, None, None, None))(grid, edges, surface, centre_view)

    dtype = get_path(base, names[0]).dtype
    grid = np.asarray(grid, dtype)  # host-side cast: no extra XLA compilation
    t0 = time.perf_counter()
    compiled = jax.jit(all_values).lower(grid, edges, surface, centre_view).compile()
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    maps = jax.block_until_ready(compiled(grid, edges, surface, centre_view))
    return np.asarray(maps), t_compile, time.perf_counter() - t0


def sweep_full(lf, paths: tuple[str, ...], grid, batch_size=None):
    """The whole chain (`mvedge_jax.pipeline.sweep`: edges → surface vectors → reconstruction)
    for every row of ``grid`` ``(K, P)`` in one compiled program (``vmap`` over the values, or
    ``lax.map`` with ``batch_size``; sharded over devices when there are several).

    Returns:
        ``(centre maps (K, H, W) numpy, seconds of the call including its compilation)``.
    """
    config = PipelineConfig()
    d_max = resolve_d_max(config.edges, lf.disparity_range)
    values = {p: np.asarray(grid)[:, i] for i, p in enumerate(paths)}
    t0 = time.perf_counter()
    maps = sweep(
        lf.views, config, values, key=jax.random.key(0), d_max=d_max, batch_size=batch_size
    )
    maps = np.asarray(jax.block_until_ready(maps))
    return maps, time.perf_counter() - t0


def _log_axis(values: np.ndarray) -> bool:
    return bool(np.all(values > 0) and values.max() / values.min() >= 10)


def plot_sweep(path: Path, scene: str, stage: str, params, values, table, defaults) -> None:
    """Write the error-curve (1 parameter) or heat-map (2 parameters) PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mse = np.array([r["mse_x100"] for r in table])
    bp = np.array([r["badpix_0.07"] for r in table])
    title = f"{scene}: Ch. 6 {stage} stage"
    if len(params) == 1:
        x = values[0]
        fig, ax1 = plt.subplots(figsize=(6.4, 4.2))
        ax1.plot(x, mse, "o-", color="tab:blue", label="MSE×100")
        ax1.set_xlabel(params[0])
        ax1.set_ylabel("MSE×100", color="tab:blue")
        ax2 = ax1.twinx()
        ax2.plot(x, bp, "s--", color="tab:red", label="BadPix(0.07) %")
        ax2.set_ylabel("BadPix(0.07) [%]", color="tab:red")
        if _log_axis(x):
            ax1.set_xscale("log")
        ax1.axvline(defaults[0], color="grey", ls=":", lw=1)
        ax1.set_title(f"{title} (dotted: default {params[0]}={defaults[0]:g})")
        fig.legend(loc="lower center", ncol=2, fontsize=8)
        fig.tight_layout(rect=(0, 0.06, 1, 1))
    else:
        k1, k2 = len(values[0]), len(values[1])
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
        for ax, data, name in ((axes[0], mse, "MSE×100"), (axes[1], bp, "BadPix(0.07) [%]")):
            grid = data.reshape(k1, k2)
            im = ax.imshow(grid, origin="lower", cmap="viridis", aspect="auto")
            ax.set_xticks(range(k2), [f"{v:g}" for v in values[1]])
            ax.set_yticks(range(k1), [f"{v:g}" for v in values[0]])
            ax.set_xlabel(params[1])
            ax.set_ylabel(params[0])
            ax.set_title(name)
            fig.colorbar(im, ax=ax)
            best = np.unravel_index(np.nanargmin(grid), grid.shape)
            span = float(np.nanmax(grid) - np.nanmin(grid))
            digits = int(np.clip(2 - np.floor(np.log10(span)), 2, 5)) if span > 0 else 2
            mid = 0.5 * (np.nanmax(grid) + np.nanmin(grid))
            for i in range(k1):
                for j in range(k2):
                    ax.text(
                        j,
                        i,
                        f"{grid[i, j]:.{digits}f}",
                        ha="center",
                        va="center",
                        fontsize=8,
                        color="black" if grid[i, j] > mid else "white",
                        fontweight="bold" if (i, j) == best else "normal",
                    )
        fig.suptitle(f"{title} (bold: best)")
        fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _check_writable(path: Path, force: bool) -> None:
    if path.exists() and not force:
        raise FileExistsError(f"{path} exists; pass --force to overwrite it")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", help="scene folder with ground truth (any supported layout)")
    ap.add_argument(
        "--param", required=True, help="ReconstructConfig array leaf to sweep (e.g. centre.omega)"
    )
    ap.add_argument("--values", required=True, help="comma-separated values")
    ap.add_argument("--param2", help="optional second parameter (2-D sweep)")
    ap.add_argument("--values2", help="values of the second parameter")
    ap.add_argument("--stage", choices=("centre", "full"), default="centre")
    ap.add_argument("--scale", type=float, default=None, help="spatial downscale in (0, 1]")
    ap.add_argument(
        "--batch-size",
        type=int,
        default=0,
        help="centre stage: lax.map batch size (0 = vmap over all values)",
    )
    ap.add_argument("--out", default="sweep_out", help="folder of the PNG (default sweep_out/)")
    ap.add_argument("--json", help="also write the table as JSON here")
    ap.add_argument("--force", action="store_true", help="overwrite existing output files")
    args = ap.parse_args(argv)

    params = [args.param] + ([args.param2] if args.param2 else [])
    if (args.param2 is None) != (args.values2 is None):
        ap.error("--param2 and --values2 go together")
    if args.stage == "full":
        allowed = list(hyperparameter_paths())
        params = [full_path(p) for p in params]
    else:
        allowed = sweepable_params()
    for p in params:
        if p not in allowed:
            ap.error(f"cannot sweep {p!r} at stage {args.stage}; sweepable: {allowed}")
    if len(set(params)) != len(params):
        ap.error("--param and --param2 must differ")
    try:
        values = [parse_values(args.values, args.param)]
        if args.param2:
            values.append(parse_values(args.values2, args.param2))
    except ValueError as err:
        ap.error(str(err))

    tag = "_".join(params)
    scene_name = Path(args.scene).resolve().name
    png = Path(args.out) / f"sweep_{scene_name}_{args.stage}_{tag}.png"
    try:
        _check_writable(png, args.force)
        if args.json:
            _check_writable(Path(args.json), args.force)
    except FileExistsError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    lf = load_light_field(args.scene, scale=args.scale)
    if lf.gt_disparity is None:
        print(f"error: {args.scene} has no ground-truth disparity", file=sys.stderr)
        return 2
    U, V, H, W, _ = lf.views.shape
    rc, cc = U // 2, V // 2
    gt, gt_mask = np.asarray(lf.gt_disparity[rc, cc]), np.asarray(lf.gt_mask[rc, cc])
    print(
        f"scene {lf.name}: {U}x{V} views of {H}x{W}, stage {args.stage}, "
        f"sweep {' x '.join(f'{p}={v.tolist()}' for p, v in zip(params, values, strict=True))}"
    )

    counter = CompileCounter().install()
    if args.stage == "centre":
        t0 = time.perf_counter()
        edges = detect_edges(lf)  # same defaults and key as `estimate_disparity`
        surface = jax.jit(surface_vectors)(edges, lf.centre_view)
        jax.block_until_ready(surface)
        print(
            f"edges + surface once: {time.perf_counter() - t0:.1f}s (incl. compilation), "
            f"{int(edges.valid.sum())} edge points"
        )
    defaults = [float(get_path(PipelineConfig(), full_path(p))) for p in params]
    base = ReconstructConfig()

    n_before, _ = counter.snapshot()
    mesh = np.meshgrid(*values, indexing="ij")
    grid = np.stack([m.ravel() for m in mesh], axis=1)  # (K, P)
    K = grid.shape[0]
    if args.stage == "centre":
        maps, t_compile, t_run = sweep_centre(
            edges,
            surface,
            lf.centre_view,
            base,
            tuple(params),
            grid,
            batch_size=args.batch_size or None,
        )
        n_after, _ = counter.snapshot()
        secs = np.full(K, t_run / K)
        how = f"lax.map(batch_size={args.batch_size})" if args.batch_size else "vmap"
        names = counter.names[n_before:n_after]
        print(
            f"centre stage: {n_after - n_before} XLA compilation(s) for all {K} values ({how}, "
            f"ahead of time: {names}): compile {t_compile:.1f}s, run {t_run:.1f}s for {K} "
            f"values ({t_run / K:.2f}s each)"
        )
        evidence = {
            "mode": how,
            "compilations": n_after - n_before,
            "compiled": names,
            "compile_seconds": t_compile,
            "run_seconds": t_run,
        }
    else:
        paths = tuple(full_path(p) for p in params)
        maps, seconds = sweep_full(lf, paths, grid, batch_size=args.batch_size or None)
        n_after, t_after = counter.snapshot()
        secs = np.full(K, seconds / K)
        names = counter.names[n_before:n_after]
        print(
            f"full chain: {n_after - n_before} XLA compilation(s) for all {K} values "
            f"({names}); {seconds:.1f}s in all including compilation"
        )
        evidence = {
            "mode": "pipeline.sweep",
            "compilations": n_after - n_before,
            "compiled": names,
            "seconds": seconds,
        }

    table = []
    for k in range(K):
        m = depth_metrics(maps[k], gt, gt_mask)
        row = {p: float(grid[k, i]) for i, p in enumerate(params)}
        row.update({key: m[key] for key in METRIC_KEYS})
        row["seconds"] = float(secs[k])
        table.append(row)

    head = "".join(f"{p:>14}" for p in params)
    print(f"\n{head}{'MSE×100':>10}{'BadPix.07':>11}{'Q25×100':>10}{'seconds':>9}")
    best = int(np.nanargmin([r["mse_x100"] for r in table]))
    for k, r in enumerate(table):
        vals = "".join(f"{r[p]:>14g}" for p in params)
        mark = "  <- best MSE" if k == best else ""
        print(
            f"{vals}{r['mse_x100']:>10.3f}{r['badpix_0.07']:>11.2f}{r['q25_x100']:>10.3f}"
            f"{r['seconds']:>9.2f}{mark}"
        )
    if all(all(np.isclose(r[k], table[0][k], rtol=1e-6) for k in METRIC_KEYS) for r in table):
        print(
            "NOTE: the metrics are identical for every value: the centre view (the only one "
            "with ground truth used here) does not depend on this parameter at this stage."
        )
    if args.stage == "centre":
        print(
            "(centre stage seconds = batched run time / number of values; raw diffusion, "
            "before refinement and weighted median)"
        )

    png.parent.mkdir(parents=True, exist_ok=True)
    plot_sweep(png, lf.name, args.stage, params, values, table, defaults)
    print(f"\nwrote {png}")
    if args.json:
        out = {
            "scene": lf.name,
            "source": str(lf.source),
            "scale": args.scale,
            "stage": args.stage,
            "params": params,
            "values": [v.tolist() for v in values],
            "defaults": defaults,
            "compile": evidence,
            "table": table,
        }
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
