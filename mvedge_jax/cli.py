"""Command line: ``mvedge <command>``.

Add a command with ``@main.command()``; reuse `light_field_options` for the input options
(``PATH``, ``--views``, ``--scale``, ``--transpose``) and `load_or_exit` to load with clean
error messages.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable

import click
import numpy as np

from .io import LayoutInfo, load_light_field_with_info
from .lightfield import LightField


class _ViewsParam(click.ParamType):
    """``7x7``, ``7X5`` or ``7`` → ``(7, 7)``, ``(7, 5)``, ``(7, 7)``."""

    name = "UxV"

    def convert(self, value, param, ctx):
        if value is None or isinstance(value, tuple):
            return value
        text = str(value).strip().lower().replace("×", "x")
        parts = text.split("x")
        try:
            nums = tuple(int(p) for p in parts)
        except ValueError:
            self.fail(f"expected UxV (e.g. 7x7) or a single number; got {value!r}", param, ctx)
        if len(nums) == 1:
            nums = (nums[0], nums[0])
        if len(nums) != 2 or min(nums) < 1:
            self.fail(f"expected UxV (e.g. 7x7) or a single number; got {value!r}", param, ctx)
        return nums


VIEWS = _ViewsParam()


def light_field_options(fn: Callable) -> Callable:
    """Decorator: the ``PATH`` argument and the ``--views/--scale/--transpose`` options."""

    @click.argument("path", type=click.Path(path_type=str))
    @click.option(
        "--views",
        type=VIEWS,
        default=None,
        help="Use the central UxV views only, e.g. 7x7 (or 7).",
    )
    @click.option(
        "--scale",
        type=click.FloatRange(0.0, 1.0, min_open=True),
        default=None,
        help="Spatial downscale factor in (0, 1], e.g. 0.5 (INTER_AREA; GT scaled too).",
    )
    @click.option(
        "--transpose/--no-transpose",
        default=None,
        help="View grids: force swapping/keeping the file's RR/CC indices (default: decide "
        "from the parallax).",
    )
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        return fn(*args, **kwargs)

    return wrapper


def load_or_exit(
    path: str, views=None, scale=None, transpose=None
) -> tuple[LightField, LayoutInfo, float]:
    """Load a light field; on bad input exit with the loader's message (no traceback).

    Returns:
        ``(light_field, info, seconds)``.
    """
    t0 = time.perf_counter()
    try:
        lf, info = load_light_field_with_info(path, views=views, scale=scale, transpose=transpose)
    except (FileNotFoundError, NotADirectoryError, ValueError) as e:
        raise click.ClickException(str(e)) from None
    return lf, info, time.perf_counter() - t0


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def main() -> None:
    """mvedge: multi-view edge depth for 4D light fields (JAX)."""
    _enable_compilation_cache()


def _enable_compilation_cache() -> None:
    """Persist compiled stages across runs ($MVEDGE_JAX_CACHE, default ~/.cache/mvedge_jax)."""
    import jax

    cache = os.environ.get("MVEDGE_JAX_CACHE") or os.path.join(
        os.path.expanduser("~"), ".cache", "mvedge_jax"
    )
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


def _fmt_range(lo: float, hi: float) -> str:
    return f"[{lo:.3f}, {hi:.3f}]"


def _grid_map(mask: np.ndarray) -> list[str]:
    return [" ".join("#" if m else "." for m in row) for row in mask]


def info_lines(lf: LightField, info: LayoutInfo, seconds: float | None = None) -> list[str]:
    """The report of ``mvedge info`` as lines (``key  value``)."""
    U, V = lf.grid
    H, W = lf.size
    mask = np.asarray(lf.view_mask)
    rc, cc = lf.centre_index
    out = [("path", info.folder), ("layout", f"{info.layout}  ({info.pattern})")]
    grid = f"{U}x{V} views (U x V), {int(mask.sum())} of {U * V} present, centre ({rc}, {cc})"
    if info.window is not None:
        r0, c0, u, v = info.window
        grid += (
            f"; central crop of the {info.grid[0]}x{info.grid[1]} grid "
            f"(rows {r0}-{r0 + u - 1}, cols {c0}-{c0 + v - 1})"
        )
    out.append(("grid", grid))
    if not mask.all():
        out += [("views present" if i == 0 else "", row) for i, row in enumerate(_grid_map(mask))]
    size = f"{H}x{W} px (H x W)"
    if info.scale is not None and info.image_size is not None:
        size += f", scaled by {info.scale:g} from {info.image_size[0]}x{info.image_size[1]}"
    out.append(("size", size))
    if lf.gt_disparity is None:
        out.append(("ground truth", "none"))
    else:
        gtm = np.asarray(lf.gt_mask)
        has = [tuple(int(i) for i in p) for p in np.argwhere(gtm.any(axis=(2, 3)))]
        has.sort(key=lambda p: p != (rc, cc))  # centre view first
        gt = np.asarray(lf.gt_disparity)
        shown, rest = has[:3], has[3:]
        for i, (r, c) in enumerate(shown):
            valid = gtm[r, c]
            vals = gt[r, c][valid]
            rng = _fmt_range(float(vals.min()), float(vals.max())) if vals.size else "n/a"
            label = "centre view" if (r, c) == (rc, cc) else "view"
            out.append(
                (
                    "ground truth" if i == 0 else "",
                    f"{label} ({r}, {c}): disparity {rng} px/view, "
                    f"{100.0 * float(valid.mean()):.1f}% valid",
                )
            )
        if rest:
            sel = np.zeros(gtm.shape[:2], bool)
            sel[tuple(np.array(rest).T)] = True
            vals = gt[sel][gtm[sel]]
            rng = _fmt_range(float(vals.min()), float(vals.max())) if vals.size else "n/a"
            out.append(
                (
                    "",
                    f"and {len(rest)} more views: disparity {rng} px/view, "
                    f"{100.0 * float(gtm[sel].mean()):.1f}% valid",
                )
            )
    if lf.disparity_range is None:
        out.append(("disparity range", "unknown (no metadata)"))
    else:
        lo, hi = lf.disparity_range
        out.append(("disparity range", f"{_fmt_range(lo, hi)} px/view (metadata)"))
    out.append(("memory", f"{lf.views.size * 4 / 2**20:.0f} MiB of views (float32)"))
    for i, note in enumerate(info.notes):
        out.append(("notes" if i == 0 else "", note))
    if seconds is not None:
        out.append(("load time", f"{seconds:.2f} s"))
    width = max(len(k) for k, _ in out)
    return [f"{k:<{width}}  {v}" for k, v in out]


@main.command()
@light_field_options
def info(path: str, views, scale, transpose) -> None:
    """Describe the light field in PATH: layout, grid, size, ground truth, disparity range."""
    lf, layout, seconds = load_or_exit(path, views, scale, transpose)
    for line in info_lines(lf, layout, seconds):
        click.echo(line)


def _config_from_file(path: str | None):
    """A `PipelineConfig` from a TOML file with optional ``[edges]``, ``[surface]``,
    ``[reconstruct]`` and ``[optimize]`` tables (and sub-tables such as ``[optimize.loss]``) of
    keyword arguments for the stage configs."""
    from .pipeline import PipelineConfig, config_from_dict

    if path is None:
        return PipelineConfig()
    import tomllib

    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise click.ClickException(f"config file not found: {path}") from None
    except tomllib.TOMLDecodeError as e:
        raise click.ClickException(f"config file {path} is not valid TOML: {e}") from None
    try:
        return config_from_dict(data)
    except (TypeError, ValueError) as e:
        raise click.ClickException(f"bad config file {path}: {e}") from None


_SUMMARY_KEYS = ("mse_x100", "badpix_0.07", "q25_x100", "view_consistency")


def _run_optimize(lf: LightField, result, config):
    """`optimize_disparity` with a progress bar over the Adam steps (loss in the postfix)."""
    from tqdm import tqdm

    from .diff import BLOCKS
    from .pipeline import optimize_disparity, optimize_steps

    total = optimize_steps(config.optimize)
    bar = tqdm(total=total, desc="optimize", unit="step", leave=True)
    bar.set_postfix_str("compile")

    def progress(step: int, info: dict) -> None:
        bar.update(1)
        text = f"pass {info['pass'] + 1} {BLOCKS[info['block']]} loss {info['loss']:.5f}"
        if step + 1 >= total:
            text += ", propagating to every view"
        bar.set_postfix_str(text)

    try:
        return optimize_disparity(lf, result, config, progress=progress)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    finally:
        bar.close()


def run_depth(
    lf: LightField, out: str, *, force: bool, config_path: str | None, optimize: bool = False
) -> dict:
    """Run the main job on a loaded light field and write every output into ``out``.

    With ``optimize`` the Ch. 6 result is refined by the differentiable edge model
    (thesis Ch. 7, `optimize_disparity`); ``metrics.json`` then also holds the ``initial``
    metrics, ``optimize_seconds`` and ``loss_history``.

    Returns:
        The metrics dictionary that was written to ``metrics.json``.
    """
    from tqdm import tqdm

    from .io import OutputWriter, check_output_dir
    from .pipeline import STAGES, estimate_disparity, write_outputs

    try:
        check_output_dir(out, lf.source, force=force)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    config = _config_from_file(config_path)
    U, V = lf.grid
    H, W = lf.size
    click.echo(f"{lf.name}: {U}x{V} views of {H}x{W} px")
    bar = tqdm(total=len(STAGES) * 2, desc="mvedge depth", unit="step", leave=True)

    def progress(stage: str, event: str) -> None:
        if event in ("compile", "run"):
            bar.set_postfix_str(f"{event} {stage}")
        else:
            bar.update(1)

    t0 = time.perf_counter()
    try:
        result = estimate_disparity(lf, config, progress=progress)
    except ValueError as e:
        bar.close()
        raise click.ClickException(str(e)) from None
    bar.close()
    initial = info = None
    if optimize:
        initial = result
        result, info = _run_optimize(lf, result, config)
    total = time.perf_counter() - t0
    writer = OutputWriter(out)
    try:
        metrics = write_outputs(
            writer, lf, result, seconds_total=total, initial=initial, optimize_info=info
        )
        writer.commit()
    except BaseException:
        writer.abort()
        raise
    click.echo(f"wrote {writer.out}")
    for k in _SUMMARY_KEYS + ("seconds_total", "compile_seconds"):
        if k in metrics:
            line = f"  {k:<18} {metrics[k]:.4f}"
            if k in metrics.get("initial", {}):
                line += f"  (before optimisation {metrics['initial'][k]:.4f})"
            click.echo(line)
    for k, v in metrics["seconds_per_stage"].items():
        click.echo(f"  {'seconds[' + k + ']':<18} {v:.2f}")
    if "loss_history" in metrics and metrics["loss_history"]:
        hist = metrics["loss_history"]
        click.echo(
            f"  {'loss':<18} {hist[0]:.5f} -> {hist[-1]:.5f} over {len(hist)} steps "
            f"({metrics['optimize_points']} points)"
        )
    return metrics


_CONFIG_HELP = (
    "TOML file with [edges], [surface], [reconstruct], [optimize] parameter tables "
    "(sub-tables for nested configs, e.g. [optimize.loss])."
)
_OPTIMIZE_HELP = (
    "Refine the result with the differentiable edge model (thesis Ch. 7: self-supervised "
    "Adam on the points, then propagation to every view); slow."
)


@main.command()
@light_field_options
@click.option(
    "--out",
    type=click.Path(path_type=str),
    default=None,
    help="Output folder (default: mvedge_out/<scene name>).",
)
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option(
    "--config",
    "config_path",
    type=click.Path(path_type=str),
    default=None,
    help=_CONFIG_HELP,
)
@click.option("--optimize", is_flag=True, help=_OPTIMIZE_HELP)
def depth(path: str, views, scale, transpose, out, force, config_path, optimize) -> None:
    """Disparity for every view of the light field in PATH (thesis Ch. 6, with --optimize
    refined as in Ch. 7).

    Writes per-view PFMs, disparity.npz, PNG colour maps, a mosaic of all views, EPIs with
    the detected lines, and metrics.json (with error maps when ground truth exists).
    """
    lf, _, seconds = load_or_exit(path, views, scale, transpose)
    click.echo(f"loaded {path} in {seconds:.2f} s")
    out = out or os.path.join("mvedge_out", lf.name)
    run_depth(lf, out, force=force, config_path=config_path, optimize=optimize)


@main.command()
@click.option(
    "--out",
    type=click.Path(path_type=str),
    default="mvedge_out/demo",
    show_default=True,
    help="Output folder.",
)
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option(
    "--config",
    "config_path",
    type=click.Path(path_type=str),
    default=None,
    help=_CONFIG_HELP,
)
@click.option("--optimize", is_flag=True, help=_OPTIMIZE_HELP)
def demo(out, force, config_path, optimize) -> None:
    """Run the main job on the embedded synthetic light field (ground truth for every view)."""
    from .synthetic import default_light_field

    lf = default_light_field()
    metrics = run_depth(lf, out, force=force, config_path=config_path, optimize=optimize)
    if "all_views" in metrics:
        a = metrics["all_views"]
        line = (
            f"  all {metrics['n_views']} views: MSE×100 {a['mse_x100']:.4f}, "
            f"BadPix(0.07) {a['badpix_0.07']:.2f}%"
        )
        b = metrics.get("initial", {}).get("all_views")
        if b is not None:
            line += f" (before optimisation {b['mse_x100']:.4f}, {b['badpix_0.07']:.2f}%)"
        click.echo(line)


# --- mvedge mvs: unstructured multi-view input (thesis Sec. 7.2.2) -------------------------


@main.command()
@click.argument("colmap_dir", type=click.Path(path_type=str))
@click.option("--ref", "reference", default=None, help="Reference image name, as in the model.")
@click.option("--all-views", is_flag=True, help="Depth for every registered image in turn.")
@click.option(
    "--images",
    "images_dir",
    type=click.Path(path_type=str),
    default=None,
    help="Image folder (default: an images/ folder in COLMAP_DIR or up to two levels above).",
)
@click.option(
    "--out",
    type=click.Path(path_type=str),
    default=None,
    help="Output folder (default: mvedge_out/mvs_<reference> or mvedge_out/mvs_all).",
)
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option(
    "--scale",
    type=click.FloatRange(0.0, 1.0, min_open=True),
    default=None,
    help="Resize the images by this factor in (0, 1] (intrinsics scaled to match).",
)
@click.option(
    "--sources", type=click.IntRange(1), default=4, show_default=True, help="Source views."
)
@click.option(
    "--iterations",
    type=click.IntRange(0),
    default=25,
    show_default=True,
    help="Adam steps per parameter block and pass.",
)
@click.option(
    "--passes", type=click.IntRange(0), default=5, show_default=True, help="Optimisation passes."
)
@click.option(
    "--prelim",
    type=click.IntRange(0),
    default=50,
    show_default=True,
    help="Adam steps on the smoothness before the edge points are sampled.",
)
@click.option(
    "--gt-depth",
    "gt_dir",
    type=click.Path(path_type=str),
    default=None,
    help="Folder of ground-truth depth maps <image stem>.pfm: adds scale-fit MSE/Q25.",
)
def mvs(
    colmap_dir,
    reference,
    all_views,
    images_dir,
    out,
    force,
    scale,
    sources,
    iterations,
    passes,
    prelim,
    gt_dir,
) -> None:
    """Depth from unstructured images and a COLMAP sparse model in COLMAP_DIR (thesis
    Sec. 7.2.2): sparse points, edge augmentation, differentiable optimisation.

    COLMAP_DIR holds cameras, images and points3D as .txt or .bin (pinhole cameras: run
    colmap image_undistorter first for others). Writes depth/ and disparity/ PFMs (depth in
    the model's units; disparity = f*B/depth, pixels of parallax for the mean source
    baseline B), PNG colour maps, stages/ (sparse, augmented, optimised), mvs.npz and
    metrics.json.
    """
    import dataclasses

    from tqdm import tqdm

    from .mvs import MVSConfig, mvs_steps, run_mvs, view_stem

    if reference is None and not all_views:
        raise click.UsageError("give --ref IMAGE_NAME or --all-views")
    base = MVSConfig()
    config = dataclasses.replace(
        base,
        sources=sources,
        prelim_iterations=prelim,
        optimize=dataclasses.replace(base.optimize, iterations=iterations, passes=passes),
    )
    out = out or os.path.join(
        "mvedge_out", "mvs_all" if all_views else "mvs_" + view_stem(reference)
    )
    bars: dict = {}

    def progress(view: str, stage: str, step: int, info: dict) -> None:
        if view not in bars:
            for b in bars.values():
                b.close()
            bars[view] = tqdm(total=mvs_steps(config), desc=view, unit="step", leave=True)
        if step < 0:
            bars[view].set_postfix_str(f"{stage} points: diffusing (compiles on first view)")
            return
        bars[view].update(1)
        bars[view].set_postfix_str(f"{stage} loss {info['loss']:.5f}")

    t0 = time.perf_counter()
    try:
        metrics = run_mvs(
            colmap_dir,
            out,
            reference=reference,
            all_views=all_views,
            images_dir=images_dir,
            gt_dir=gt_dir,
            scale=scale,
            config=config,
            force=force,
            progress=progress,
        )
    except (FileNotFoundError, KeyError, ValueError) as e:
        raise click.ClickException(str(e).strip("'\"")) from None
    finally:
        for b in bars.values():
            b.close()
    click.echo(f"wrote {os.path.abspath(out)} in {time.perf_counter() - t0:.1f} s")
    for name, v in metrics["views"].items():
        line = (
            f"  {name}: {v['sparse_points']} sparse + {v['edge_points']} edge points, "
            f"depth {v['depth_range'][0]:.3g}..{v['depth_range'][1]:.3g}"
        )
        fit = v.get("scale_fit", {})
        if fit:
            line += ", scale-fit MSE " + " -> ".join(
                f"{fit[k]['mse']:.4f}" for k in ("sparse", "augmented", "optimized")
            )
        click.echo(line)


if __name__ == "__main__":  # pragma: no cover
    main(prog_name=os.path.basename(__file__))
