"""Command line: ``mvedge <command>``.

Add a command with ``@main.command()``; reuse `light_field_options` for the input options
(``PATH``, ``--views``, ``--scale``, ``--transpose``) and `load_or_exit` to load with clean
error messages.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import glob
import os
import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import click
import numpy as np

if TYPE_CHECKING:  # the package imports JAX: `main` checks the platform first
    from .io import LayoutInfo
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


def input_options(fn: Callable) -> Callable:
    """Decorator: the ``--views/--scale/--transpose`` options (without the ``PATH`` argument)."""

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


def light_field_options(fn: Callable) -> Callable:
    """Decorator: the ``PATH`` argument and the ``--views/--scale/--transpose`` options."""
    return click.argument("path", type=click.Path(path_type=str))(input_options(fn))


def load_or_exit(
    path: str, views=None, scale=None, transpose=None
) -> tuple[LightField, LayoutInfo, float]:
    """Load a light field; on bad input exit with the loader's message (no traceback).

    Returns:
        ``(light_field, info, seconds)``.
    """
    from .io import load_light_field_with_info

    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            lf, info = load_light_field_with_info(
                path, views=views, scale=scale, transpose=transpose
            )
    except (FileNotFoundError, NotADirectoryError, PermissionError, ValueError) as e:
        raise click.ClickException(str(e)) from None
    _echo_warnings(str(w.message) for w in caught)
    return lf, info, time.perf_counter() - t0


def _echo_warnings(messages) -> None:
    for m in messages:
        click.secho(f"warning: {m}", fg="yellow", err=True)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--deterministic",
    is_flag=True,
    envvar="MVEDGE_DETERMINISTIC",
    help="On a GPU, use XLA's deterministic kernels (XLA_FLAGS=--xla_gpu_deterministic_ops"
    "=true), so that repeated runs give the same bits, as on the CPU; may be slower on a "
    "GPU, no effect on the CPU. Also MVEDGE_DETERMINISTIC=1.",
)
def main(deterministic: bool) -> None:
    """mvedge: multi-view edge depth for 4D light fields (JAX).

    Compiled stages are cached on disk ($MVEDGE_JAX_CACHE, default ~/.cache/mvedge_jax;
    MVEDGE_JAX_CACHE=off disables it).
    """
    if deterministic:
        from ._determinism import request_deterministic_gpu

        try:
            request_deterministic_gpu()
        except RuntimeError as e:
            raise click.ClickException(str(e)) from None
    _check_platform()


_GPU_INSTALL = 'pip install -e ".[cuda]"'


def _check_platform() -> None:
    """Fail with a clear message when JAX cannot start the requested platform.

    ``JAX_PLATFORMS=cuda`` on an install without the CUDA plugin otherwise fails at the
    first JAX call with a bare AssertionError or RuntimeError.
    """
    import jax

    try:
        jax.devices()
    except (RuntimeError, AssertionError) as e:
        wanted = os.environ.get("JAX_PLATFORMS") or os.environ.get("JAX_PLATFORM_NAME")
        detail = str(e).strip() or "no installed JAX plugin provides it, or no device is visible"
        raise click.ClickException(
            f"JAX cannot start the requested platform (JAX_PLATFORMS={wanted!r}): {detail}. "
            f"For an NVIDIA GPU install the CUDA build with {_GPU_INSTALL}; "
            "unset JAX_PLATFORMS to use the CPU."
        ) from None


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
    ``[reconstruct]`` and ``[optimize]`` tables (and sub-tables for the nested configs, such as
    ``[edges.filter]``, ``[reconstruct.centre]`` or ``[optimize.loss]``) of keyword arguments
    for the configs."""
    from .pipeline import PipelineConfig, config_from_dict

    if path is None:
        return PipelineConfig()
    import tomllib

    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise click.ClickException(f"config file not found: {path}") from None
    except IsADirectoryError:
        raise click.ClickException(f"config file {path} is a folder, not a TOML file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise click.ClickException(f"config file {path} is not valid TOML: {e}") from None
    except OSError as e:
        raise click.ClickException(f"cannot read config file {path}: {e}") from None
    try:
        return config_from_dict(data, source=path)
    except (TypeError, ValueError) as e:  # the message starts with the file's path
        raise click.ClickException(f"bad config file {e}") from None


def _check_config_early(config_path: str | None, path: str, views, scale) -> None:
    """Parse the config and bound its memory need from the folder's layout, before any
    pixel is read."""
    from .pipeline import check_memory_before_loading

    config = _config_from_file(config_path)
    try:
        check_memory_before_loading(config, path, views=views, scale=scale)
    except ValueError as e:
        raise click.ClickException(str(e)) from None


def _scene_name(path: str) -> str:
    """The light field's name (its folder's name) without reading pixels."""
    from .io import detect_layout

    try:
        folder = detect_layout(path).folder
    except (OSError, ValueError):  # reported properly when the light field is loaded
        folder = os.path.abspath(path)
    return os.path.basename(folder.rstrip(os.sep)) or "lightfield"


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt (like Ctrl-C), so that cleanup runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


@contextlib.contextmanager
def output_session(out: str, source: str | None, *, force: bool):
    """Check, lock and stage the output folder before any work (`OutputWriter`); on any
    error, Ctrl-C or SIGTERM inside the block the staging folder, the lock and the parent
    folders it created are removed and the old output is left as it was.

    Yields:
        The `OutputWriter` (commit it to publish the output).
    """
    from .io import OutputWriter

    with _terminate_as_interrupt():
        try:
            writer = OutputWriter(out, force=force, source=source)
        except ValueError as e:
            raise click.ClickException(str(e)) from None
        except OSError as e:
            raise click.ClickException(f"cannot write output folder {out}: {e}") from None
        try:
            yield writer
        finally:
            if not writer.committed:
                writer.abort()


_SUMMARY_KEYS = ("mse_x100", "badpix_0.07", "q25_x100", "view_consistency")


def _device_line() -> str:
    from .pipeline import device_info

    d = device_info()
    determinism = (
        ""
        if d["backend"] == "cpu"
        else (", deterministic kernels" if d["deterministic"] else ", nondeterministic kernels")
    )
    return (
        f"device: {d['device']} (backend {d['backend']}, {d['device_count']} device(s), "
        f"jax {d['jax_version']}{determinism})"
    )


def _run_optimize(lf: LightField, result, config, bar):
    """`optimize_disparity` with ``bar`` advanced per Adam step and once for the propagation."""
    from .diff import BLOCKS
    from .pipeline import optimize_disparity, optimize_steps

    total = optimize_steps(config.optimize)
    bar.set_postfix_str("compile optimize")

    def progress(step: int, info: dict) -> None:
        bar.update(1)
        text = f"optimize pass {info['pass'] + 1} {BLOCKS[info['block']]} loss {info['loss']:.5f}"
        if step + 1 >= total:
            text = "propagating to every view"
        bar.set_postfix_str(text)

    try:
        out = optimize_disparity(lf, result, config, progress=progress)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    bar.update(1)  # propagation
    return out


@dataclasses.dataclass(frozen=True)
class _Formats:
    """The optional outputs of ``mvedge depth`` (`write_outputs`)."""

    hci: bool = False
    depth: bool = False
    ply: bool = False


def run_depth(
    lf: LightField,
    out: str,
    *,
    force: bool,
    config_path: str | None = None,
    optimize: bool = False,
    seed: int = 0,
    formats: _Formats = _Formats(),
    camera=None,
    load_info: LayoutInfo | None = None,
    load_seconds: float | None = None,
    checked: bool = False,
    writer=None,
) -> dict:
    """Run the main job on a loaded light field and write every output into ``out``.

    ``out`` is an output folder or an `OutputWriter` from `output_session` (which then
    holds the folder's lock from before the light field was loaded).

    With ``optimize`` the Ch. 6 result is refined by the differentiable edge model
    (thesis Ch. 7, `optimize_disparity`); ``metrics.json`` then also holds the ``initial``
    metrics, ``optimize_seconds`` and ``loss_history``. One progress bar covers the stages,
    the optimisation steps, the propagation and the writing of the outputs.

    Args:
        lf: the light field.
        out: output folder (replaced only with ``force``).
        force: replace an existing ``out``.
        config_path: optional TOML configuration (`_config_from_file`).
        optimize: refine with `optimize_disparity`.
        seed: seed of the PRNG key of the randomised line refinement.
        formats: the optional field formats (HCI layout, depth, PLY).
        camera: the scene's `HciCamera` (needed for depth and PLY).
        load_info: the loader's `LayoutInfo` (scale and crop, for the provenance).
        load_seconds: seconds the loading took (``provenance.seconds_load``).
        checked: ``out`` was already validated (batch runs check every folder first).

    Returns:
        The metrics dictionary that was written to ``metrics.json``.

    Raises:
        click.ClickException: on an existing or misplaced ``out``, a bad configuration,
            depth/PLY without a camera, or bad input.
    """
    import jax
    from tqdm import tqdm

    from .io import OutputWriter, check_output_dir
    from .pipeline import STAGES, estimate_disparity, optimize_steps, provenance, write_outputs

    if not checked:
        try:
            check_output_dir(out, lf.source, force=force)
        except ValueError as e:
            raise click.ClickException(str(e)) from None
    if (formats.depth or formats.ply) and camera is None:
        raise click.ClickException(
            f"{lf.name}: --depth and --ply need the camera of an HCI 4D scene "
            "(parameters.cfg); this input has none"
        )
    config = _config_from_file(config_path)
    U, V = lf.grid
    H, W = lf.size
    click.echo(f"{lf.name}: {U}x{V} views of {H}x{W} px")
    if formats.hci and load_info is not None and load_info.scale not in (None, 1.0):
        click.echo(
            f"warning: --format hci with --scale {load_info.scale:g}: the benchmark expects "
            "full-resolution disparity maps",
            err=True,
        )
    total = len(STAGES) + 1 + (optimize_steps(config.optimize) + 1 if optimize else 0)
    bar = tqdm(total=total, desc=lf.name, unit="step", leave=True)

    def progress(stage: str, event: str) -> None:
        if event in ("compile", "run"):
            bar.set_postfix_str(f"{event} {stage}")
        else:
            bar.update(1)

    try:
        t0 = time.perf_counter()
        try:
            result = estimate_disparity(lf, config, key=jax.random.key(seed), progress=progress)
        except ValueError as e:
            raise click.ClickException(str(e)) from None
        initial = info = None
        if optimize:
            initial = result
            result, info = _run_optimize(lf, result, config, bar)
        total_s = time.perf_counter() - t0
        prov = provenance(
            lf,
            config,
            seed=seed,
            scale=None if load_info is None else load_info.scale,
            views=None if load_info is None else _requested_views(load_info, lf),
            window=None if load_info is None else load_info.window,
        )
        prov["seconds_load"] = load_seconds
        if writer is None:
            try:
                writer = OutputWriter(out, force=force, source=lf.source)
            except ValueError as e:  # OutputError: a concurrent run holds the lock, ...
                raise click.ClickException(str(e)) from None
        try:
            metrics = write_outputs(
                writer,
                lf,
                result,
                seconds_total=total_s,
                initial=initial,
                optimize_info=info,
                provenance=prov,
                hci=formats.hci,
                camera=camera,
                depth=formats.depth,
                ply=formats.ply,
                progress=lambda name: bar.set_postfix_str(f"write {name}"),
            )
            writer.commit()
        except BaseException:
            writer.abort()
            raise
        bar.update(1)
        bar.set_postfix_str("done")
    finally:
        bar.close()
    click.echo(f"wrote {writer.out}")
    _echo_warnings(metrics.get("warnings", []))
    for k in _SUMMARY_KEYS + ("seconds_total", "compile_seconds"):
        if metrics.get(k) is not None:
            line = f"  {k:<18} {metrics[k]:.4f}"
            if metrics.get("initial", {}).get(k) is not None:
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


def _requested_views(info: LayoutInfo, lf: LightField):
    return None if info.window is None else tuple(lf.grid)


_CONFIG_HELP = (
    "TOML file with [edges], [surface], [reconstruct], [optimize] parameter tables "
    "(sub-tables for nested configs, e.g. [edges.filter], [reconstruct.centre], "
    "[optimize.loss]; `mvedge config --dump` prints them all)."
)
_OPTIMIZE_HELP = (
    "Refine the result with the differentiable edge model (thesis Ch. 7: self-supervised "
    "Adam on the points, then propagation to every view); slow."
)


def _job_options(fn: Callable) -> Callable:
    """Decorator: ``--force``, ``--config``, ``--optimize``, ``--seed``."""

    @click.option("--force", is_flag=True, help="Replace existing output folders.")
    @click.option(
        "--config",
        "config_path",
        type=click.Path(path_type=str),
        default=None,
        help=_CONFIG_HELP,
    )
    @click.option("--optimize", is_flag=True, help=_OPTIMIZE_HELP)
    @click.option(
        "--seed",
        type=int,
        default=0,
        show_default=True,
        help="Seed of the randomised line refinement (stored in metrics.json).",
    )
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        return fn(*args, **kwargs)

    return wrapper


def _expand_paths(paths: tuple[str, ...]) -> list[str]:
    """Folders of the ``PATH...`` arguments; a quoted glob (``'data/hci4d/*/*'``) is expanded."""
    out: list[str] = []
    for p in paths:
        if not os.path.exists(p) and glob.has_magic(p):
            hits = sorted(h for h in glob.glob(p) if os.path.isdir(h))
            if not hits:
                raise click.ClickException(f"no folder matches {p!r}")
            out += hits
        else:
            out.append(p)
    return out


def _summary_rows(rows: list[dict]) -> tuple[list[str], list[list[str]]]:
    cols = ["scene", "status", *_SUMMARY_KEYS, "seconds_total", "output"]
    table = []
    for r in rows:
        line = []
        for c in cols:
            v = r.get(c)
            line.append("" if v is None else (f"{v:.4f}" if isinstance(v, float) else str(v)))
        table.append(line)
    return cols, table


def _write_summary(out: str, rows: list[dict], scenes: dict[str, str], hci: bool) -> str:
    """``summary/``: ``scenes.csv`` and ``scenes.md`` (one row per scene), and with ``hci``
    the whole benchmark submission layout (``disp_maps/``, ``runtimes/``) of every scene."""
    import csv
    import io as _io
    import shutil

    from .io import OutputWriter

    cols, table = _summary_rows(rows)
    writer = OutputWriter(os.path.join(out, "summary"))
    try:
        buf = _io.StringIO()
        csv.writer(buf, lineterminator="\n").writerows([cols, *table])
        writer.path("scenes.csv").write_text(buf.getvalue())
        md = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        md += ["| " + " | ".join(line) + " |" for line in table]
        writer.path("scenes.md").write_text("\n".join(md) + "\n")
        if hci:
            for name, folder in scenes.items():
                for sub, ext in (("disp_maps", "pfm"), ("runtimes", "txt")):
                    src = os.path.join(folder, sub, f"{name}.{ext}")
                    if os.path.isfile(src):
                        shutil.copyfile(src, writer.path(f"{sub}/{name}.{ext}"))
        writer.commit()
    except BaseException:
        writer.abort()
        raise
    return str(writer.out)


@main.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=str))
@input_options
@click.option(
    "--out",
    type=click.Path(path_type=str),
    default=None,
    help="Output folder (default: mvedge_out/<scene name>). With several PATHs: the parent "
    "folder of one folder per scene and summary/ (default: mvedge_out).",
)
@_job_options
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["mvedge", "hci"]),
    default="mvedge",
    show_default=True,
    help="hci: also write the HCI 4D benchmark submission layout (disp_maps/<scene>.pfm, "
    "runtimes/<scene>.txt).",
)
@click.option(
    "--depth",
    "want_depth",
    is_flag=True,
    help="Also write metric depth (depth/view_RR_CC.pfm in metres, centre_depth.png); needs "
    "an HCI 4D parameters.cfg.",
)
@click.option(
    "--ply",
    is_flag=True,
    help="Also write centre_view.ply, the centre view's coloured point cloud (mm); needs an "
    "HCI 4D parameters.cfg.",
)
def depth(
    paths, views, scale, transpose, out, force, config_path, optimize, seed, fmt, want_depth, ply
) -> None:
    """Disparity for every view of the light field in each PATH (thesis Ch. 6, with
    --optimize refined as in Ch. 7). PATH may be several folders or a quoted glob.

    Writes per-view PFMs, disparity.npz, figures with colour bars (centre disparity, a mosaic
    of all views, edge points, EPIs with the detected lines, and with ground truth the error
    and BadPix maps) and metrics.json (scores, timings, device, configuration). With several
    PATHs, one folder per scene and summary/scenes.csv.
    """
    from .io import check_output_dir, read_hci_camera

    folders = _expand_paths(paths)
    formats = _Formats(hci=fmt == "hci", depth=want_depth, ply=ply)
    click.echo(_device_line())
    job = functools.partial(
        run_depth,
        force=force,
        config_path=config_path,
        optimize=optimize,
        seed=seed,
        formats=formats,
    )
    _config_from_file(config_path)  # a bad config fails before any scene is loaded
    if len(folders) == 1:
        target = out or os.path.join("mvedge_out", os.path.basename(os.path.normpath(folders[0])))
        try:  # the output location is checked before the scene is loaded
            check_output_dir(target, folders[0], force=force)
        except ValueError as e:
            raise click.ClickException(str(e)) from None
        # locked and staged before the scene is loaded; SIGTERM cleans up like Ctrl-C
        with output_session(target, folders[0], force=force) as writer:
            lf, info, seconds = load_or_exit(folders[0], views, scale, transpose)
            click.echo(f"loaded {folders[0]} in {seconds:.2f} s")
            camera = _camera_or_exit(read_hci_camera, info.folder, formats)
            job(
                lf,
                target,
                camera=camera,
                load_info=info,
                load_seconds=seconds,
                checked=True,
                writer=writer,
            )
        return
    root = out or "mvedge_out"
    names = [os.path.basename(os.path.normpath(f)) for f in folders]
    dupes = sorted({n for n in names if names.count(n) > 1} | ({"summary"} & set(names)))
    if dupes:
        raise click.ClickException(
            f"scene folder names must be unique and not 'summary' (one output folder each); "
            f"repeated or reserved: {', '.join(dupes)}"
        )
    try:
        for f, n in zip(folders, names, strict=True):
            check_output_dir(os.path.join(root, n), f, force=force)
        check_output_dir(os.path.join(root, "summary"), None, force=force)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    rows, written = [], {}
    for i, (f, n) in enumerate(zip(folders, names, strict=True)):
        click.echo(f"[{i + 1}/{len(folders)}] {f}")
        dest = os.path.join(root, n)
        try:
            lf, info, seconds = load_or_exit(f, views, scale, transpose)
            camera = _camera_or_exit(read_hci_camera, info.folder, formats)
            m = job(lf, dest, camera=camera, load_info=info, load_seconds=seconds, checked=True)
        except click.ClickException as e:
            click.echo(f"error: {f}: {e.format_message()}", err=True)
            rows.append({"scene": n, "status": f"failed: {e.format_message()}", "output": ""})
            continue
        rows.append({"scene": n, "status": "ok", "output": dest, **m})
        written[n] = dest
    summary = _write_summary(root, rows, written, formats.hci)
    cols, table = _summary_rows(rows)
    click.echo(f"wrote {summary}")
    widths = [max(len(c), *(len(r[j]) for r in table)) for j, c in enumerate(cols[:-1])]
    for line in [cols[:-1]] + [r[:-1] for r in table]:
        click.echo("  ".join(v.ljust(w) for v, w in zip(line, widths, strict=True)))
    failed = [r["scene"] for r in rows if r["status"] != "ok"]
    if failed:
        raise click.ClickException(f"{len(failed)} of {len(rows)} scenes failed: {failed}")


def _camera_or_exit(read, folder: str, formats: _Formats):
    if not (formats.depth or formats.ply):
        return None
    try:
        camera = read(folder)
    except (FileNotFoundError, ValueError) as e:
        raise click.ClickException(str(e)) from None
    if camera is None:
        raise click.ClickException(
            f"--depth and --ply need an HCI 4D parameters.cfg with the camera; {folder} has none"
        )
    return camera


@main.command()
@click.option(
    "--out",
    type=click.Path(path_type=str),
    default="mvedge_out/demo",
    show_default=True,
    help="Output folder.",
)
@_job_options
def demo(out, force, config_path, optimize, seed) -> None:
    """Run the main job on the embedded synthetic light field (ground truth for every view)."""
    from .synthetic import default_light_field

    click.echo(_device_line())
    lf = default_light_field()
    metrics = run_depth(lf, out, force=force, config_path=config_path, optimize=optimize, seed=seed)
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


@main.command("config")
@click.option(
    "--dump",
    is_flag=True,
    help="Print every field of the pipeline configuration as TOML.",
)
@click.option(
    "--config",
    "config_path",
    type=click.Path(path_type=str),
    default=None,
    help="TOML file whose values are merged over the defaults before printing.",
)
def config_command(dump: bool, config_path: str | None) -> None:
    """Show the pipeline configuration (`mvedge config --dump > cfg.toml`, edit, then
    `mvedge depth PATH --config cfg.toml`)."""
    from .pipeline import config_to_toml

    if not dump:
        raise click.UsageError("nothing to do; pass --dump to print the configuration")
    click.echo(config_to_toml(_config_from_file(config_path)), nl=False)


#: Pixels excluded at each image border by the HCI 4D benchmark protocol (at 512 × 512).
HCI_BORDER = 15


def _read_disparity_file(path: str) -> np.ndarray:
    """A 2-D disparity map from ``.pfm``, ``.npy`` or ``.npz`` (``disparity``: its centre view
    when it holds every view, as the ``disparity.npz`` of ``mvedge depth``)."""
    from .io import read_pfm

    ext = os.path.splitext(path)[1].lower()
    if not os.path.isfile(path):
        raise click.ClickException(f"file not found: {path}")
    try:
        if ext == ".pfm":
            a = read_pfm(path)
        elif ext == ".npy":
            a = np.load(path, allow_pickle=False)
        elif ext == ".npz":
            with np.load(path, allow_pickle=False) as z:
                if "disparity" not in z:
                    raise click.ClickException(f"{path} holds no 'disparity' array: {list(z)}")
                a = z["disparity"]
            if a.ndim == 4:
                a = a[a.shape[0] // 2, a.shape[1] // 2]
        else:
            raise click.ClickException(
                f"unknown disparity format {ext!r} of {path}; use .pfm, .npy or .npz"
            )
    except (ValueError, OSError) as e:
        raise click.ClickException(f"cannot read {path}: {e}") from None
    a = np.asarray(a)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim != 2:
        raise click.ClickException(f"{path}: expected a 2-D disparity map; got shape {a.shape}")
    return a.astype(np.float32)


def _read_gt(path: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Ground truth from a file, or the centre-view GT (and mask) of a light-field folder."""
    if os.path.isdir(path):
        lf, _, _ = load_or_exit(path)
        if lf.gt_disparity is None:
            raise click.ClickException(f"{path} has no ground truth")
        rc, cc = lf.centre_index
        return np.asarray(lf.gt_disparity[rc, cc]), np.asarray(lf.gt_mask[rc, cc])
    return _read_disparity_file(path), None


def evaluate_disparity(
    pred: np.ndarray, gt: np.ndarray, gt_mask: np.ndarray | None = None, border: int = HCI_BORDER
) -> dict:
    """Score a centre-view disparity map against ground truth, two ways.

    ``full_frame``: every pixel with valid ground truth; ``hci_protocol``: the same with a
    ``border``-pixel frame excluded, as the HCI 4D benchmark toolkit does (15 px at 512²).
    Pixels where the prediction is not finite are excluded and counted.

    Args:
        pred, gt: ``(H, W)`` disparity in pixels per view step.
        gt_mask: optional ``(H, W)`` bool of valid ground truth.
        border: pixels excluded at each side for ``hci_protocol``.

    Returns:
        ``{"full_frame": depth_metrics, "hci_protocol": depth_metrics, "pixels",
        "invalid_prediction_pixels", "border"}``.

    Raises:
        click.ClickException: on different shapes, or no pixel left to score.

    References:
        Honauer et al., ACCV 2016 (metrics and the 15-px evaluation border of the toolkit);
        thesis Sec. 6.2.3.
    """
    from .metrics import depth_metrics

    if pred.shape != gt.shape:
        raise click.ClickException(
            f"prediction shape {pred.shape} differs from ground-truth shape {gt.shape}"
        )
    H, W = gt.shape
    valid = np.isfinite(gt) & (np.ones_like(gt, bool) if gt_mask is None else gt_mask)
    finite = np.isfinite(pred)
    m_full = valid & finite
    m_hci = m_full.copy()
    b = max(0, int(border))
    if 2 * b >= min(H, W):
        raise click.ClickException(f"border {b} px leaves nothing of a {H}x{W} map")
    frame = np.zeros_like(m_hci)
    frame[b : H - b, b : W - b] = True
    m_hci &= frame
    if not m_hci.any():
        raise click.ClickException("no pixel with valid ground truth and a finite prediction")
    p, g = np.where(finite, pred, 0.0), np.where(np.isfinite(gt), gt, 0.0)
    return {
        "full_frame": depth_metrics(p, g, m_full),
        "hci_protocol": depth_metrics(p, g, m_hci),
        "pixels": {"full_frame": int(m_full.sum()), "hci_protocol": int(m_hci.sum())},
        "invalid_prediction_pixels": int((valid & ~finite).sum()),
        "border": b,
    }


@main.command(name="eval")
@click.argument("pred", type=click.Path(path_type=str))
@click.argument("gt", type=click.Path(path_type=str))
@click.option(
    "--border",
    type=click.IntRange(0),
    default=HCI_BORDER,
    show_default=True,
    help="Pixels excluded at each side in the HCI protocol (15 at 512x512; scale it with "
    "the map, e.g. 8 at 256x256).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the scores as JSON.")
def eval_cmd(pred: str, gt: str, border: int, as_json: bool) -> None:
    """Score the disparity map PRED against ground truth GT: MSE×100, BadPix, Q25×100.

    PRED: .pfm, .npy, or the disparity.npz of mvedge depth (its centre view). GT: the same
    formats, or a light-field folder with ground truth (its centre view and mask). Both
    protocols: the full frame, and the HCI 4D benchmark's with a 15-px border excluded.
    """
    import json

    p = _read_disparity_file(pred)
    g, gm = _read_gt(gt)
    scores = evaluate_disparity(p, g, gm, border)
    if as_json:
        from .pipeline import strict_json

        click.echo(json.dumps(strict_json(scores), indent=2, allow_nan=False))
        return
    keys = list(scores["full_frame"])
    click.echo(f"{'metric':<14} {'full frame':>12} {'HCI (border ' + str(border) + ')':>16}")
    for k in keys:
        click.echo(f"{k:<14} {scores['full_frame'][k]:>12.4f} {scores['hci_protocol'][k]:>16.4f}")
    click.echo(
        f"{'pixels':<14} {scores['pixels']['full_frame']:>12d} "
        f"{scores['pixels']['hci_protocol']:>16d}"
    )
    if scores["invalid_prediction_pixels"]:
        click.echo(
            f"warning: {scores['invalid_prediction_pixels']} pixels of PRED are NaN/Inf and "
            "were not scored",
            err=True,
        )


# ---- superpixels (thesis Ch. 5) ------------------------------------------------------------


@main.command("superpixels")
@light_field_options
@click.option(
    "--size",
    type=click.FloatRange(2.0, None),
    default=20.0,
    show_default=True,
    help="Mean superpixel side in pixels (the number of superpixels is H*W/size²).",
)
@click.option(
    "--out",
    type=click.Path(path_type=str),
    default=None,
    help="Output folder (default: mvedge_out/<scene name>_superpixels).",
)
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option(
    "--dense/--no-dense",
    default=True,
    show_default=True,
    help="Project the centre labels into every view with the Ch. 6 dense disparity "
    "(estimate_disparity; about 15 s more at 512x512) instead of the EPI segments' disparity.",
)
@click.option(
    "--seed-candidates",
    type=click.IntRange(1, 8),
    default=6,
    show_default=True,
    help="Cluster from this many shifted seed grids and keep the partition predicted to be "
    "the most view-consistent (1: the thesis' single grid, fastest).",
)
def superpixels_command(
    path: str, views, scale, transpose, size, out, force, dense, seed_candidates
) -> None:
    """View-consistent superpixels of every view of the light field in PATH (thesis Ch. 5).

    Writes labels.npz (labels and disparity of every view), views/RR_CC.png (each view with
    its superpixel boundaries), labels_centre.png (label colours), sweep.png (the centre row
    and column of views, to see boundary stability) and metrics.json (compactness, and with a
    disparity ground truth the self-similarity error and labels per pixel). With --dense the
    edges, surface vectors and dense disparity come from the Ch. 6 chain (estimate_disparity)
    and labels.npz's disparity is that reconstruction.
    """
    from .edges import detect_edges
    from .io import OutputWriter, check_output_dir
    from .metrics import superpixel_metrics
    from .pipeline import estimate_disparity
    from .superpixels import (
        SuperpixelConfig,
        draw_boundaries,
        label_colours,
        superpixels,
        view_sweep,
    )
    from .surface import surface_vectors

    lf, _, seconds = load_or_exit(path, views, scale, transpose)
    out = out or os.path.join("mvedge_out", f"{lf.name}_superpixels")
    try:
        check_output_dir(out, lf.source, force=force)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    U, V = lf.grid
    H, W = lf.size
    click.echo(f"loaded {lf.name}: {U}x{V} views of {H}x{W} px in {seconds:.2f} s")
    config = SuperpixelConfig(size=float(size), seed_candidates=seed_candidates)
    t0 = time.perf_counter()
    try:
        dense_d = None
        if dense:
            click.echo(
                "estimating the Ch. 6 disparity (edges, surface vectors, reconstruction) ..."
            )
            est = estimate_disparity(lf)
            edges, offset, dense_d = est.edges, est.surface.offset, est.disparity
        else:
            click.echo("detecting multi-view edges and surface vectors ...")
            edges = detect_edges(lf, config.edges)
            offset = surface_vectors(edges, lf.centre_view, config.surface).offset
        t_edges = time.perf_counter() - t0
        click.echo(f"clustering {config.n_superpixels(H, W)} superpixels ...")
        res = superpixels(lf, config, edges=edges, surface_offset=offset, disparity=dense_d)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    total = time.perf_counter() - t0
    labels = np.asarray(res.labels)
    disparity = np.asarray(res.disparity)
    metrics = {
        "scene": lf.name,
        "grid": [U, V],
        "size_px": [H, W],
        "superpixel_size": float(size),
        "n_superpixels": res.n_superpixels,
        "n_labels_used": int(np.unique(labels).size),
        "consistent_fraction": res.consistent_fraction,
        "dense_disparity": bool(dense),
        "seed_candidates": int(seed_candidates),
        "seconds_edges_and_surface": t_edges,
        "seconds_per_stage": res.seconds,
        "seconds_total": total,
    }
    gt = None if lf.gt_disparity is None else np.asarray(lf.gt_disparity)
    gt_mask = None if lf.gt_mask is None else np.asarray(lf.gt_mask)
    if gt is not None and gt_mask is not None and not gt_mask[U // 2, V // 2].all():
        gt = None  # the metrics need a complete centre-view ground truth
    metrics.update(superpixel_metrics(labels, gt_disparity=gt, gt_mask=gt_mask))
    views_np = np.asarray(lf.views)
    writer = OutputWriter(out)
    try:
        writer.npz("labels.npz", labels=labels, disparity=disparity)
        for r in range(U):
            for c in range(V):
                writer.png(
                    f"views/{r:02d}_{c:02d}.png", draw_boundaries(views_np[r, c], labels[r, c])
                )
        writer.png("labels_centre.png", label_colours(labels[U // 2, V // 2]))
        writer.png("sweep.png", view_sweep(views_np, labels))
        writer.json("metrics.json", metrics)
        writer.commit()
    except BaseException:
        writer.abort()
        raise
    click.echo(f"wrote {writer.out}")
    for k in (
        "n_labels_used",
        "consistent_fraction",
        "compactness",
        "self_similarity_error",
        "labels_per_pixel",
        "seconds_total",
    ):
        if k in metrics:
            click.echo(f"  {k:<22} {metrics[k]:.4f}")


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
