"""Depth from unstructured multi-view images and a COLMAP sparse model (thesis Sec. 7.2.2).

For a reference image: the sparse COLMAP points it observes are projected into it
(`sparse_depth_points`); their labels ``f·B / depth`` are diffused (eq 7.2) and the smoothness
``Q`` alone is optimised against the source views (`optimize_multiview`, the eq 7.16 loss
through depth warping) for ``prelim_iterations`` steps; the preliminary map is sampled at the
RGB edges of the reference image (Canny) and these edge points join the sparse ones; then all
parameters are optimised in turns (``OptimizeConfig``: 25 iterations × 5 passes in the
thesis). Depth is ``f·B / label``; ``disparity`` is the label itself, the pixel parallax
between two cameras ``B`` apart (``B``: mean distance to the source cameras).

Entry points: `load_mvs_input`, `estimate_depth_mvs` (one reference view), `run_mvs` (one
or every view, with outputs); the CLI command ``mvedge mvs`` calls `run_mvs`.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from collections.abc import Callable

import cv2
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .diff import (
    DiffParams,
    LossConfig,
    ModelConfig,
    MultiViewCameras,
    OptimizeConfig,
    RenderConfig,
    initial_params,
    multiview_cameras,
    optimize_multiview,
    sample_bilinear,
    sparse_depth_points,
)
from .io import ColmapModel, read_colmap_model, read_rgb

_CAPACITY_STEP = 1024  # point capacities are rounded up to a multiple of this

# fewer, cheaper points than the light-field default: a handful of points per tile
_RENDER = RenderConfig(nearer="larger", density=0.5, tile_levels=((24, 1.0), (48, 0.5), (96, 0.2)))


class MVSConfig(eqx.Module):
    """Settings of the unstructured multi-view job (thesis Sec. 7.2.2).

    Attributes:
        optimize: `OptimizeConfig` of the final optimisation of all parameters (thesis:
            turns of 25 iterations, 5 passes); its ``model`` and ``loss`` serve every stage.
            The learning rates (label, position, R, Q) are larger than the light-field
            defaults: labels here span tens of pixels of parallax (on the synthetic scene,
            scale-fit MSE 0.45 → 0.28 for its middle view with the full schedule,
            experiments/mvs_synthetic.py). The reward for error gradients of eq 7.16
            (``LossConfig.gradient_reward``) is off: with it (0.05) the same runs ended at
            MSE 0.28, 0.34 and 1.25 (middle view, right and left end of the arc) instead of
            0.22, 0.41 and 1.13.
        prelim_iterations: Adam steps on the smoothness ``Q`` alone before the edge
            sampling (thesis: 50).
        sources: the most source views per reference (the nearest camera centres).
        min_track_length: minimum observations of a sparse point.
        max_error: maximum reprojection error of a sparse point in pixels (``None``: any).
        canny_low, canny_high: Canny hysteresis thresholds on the 8-bit grey reference.
        max_edge_points: capacity of the edge points (evenly thinned when more edge pixels).
        edge_gap: minimum distance in pixels between an edge point and a sparse point (the
            sparse point keeps its exact label there).
    """

    optimize: OptimizeConfig = OptimizeConfig(
        model=ModelConfig(render=_RENDER),
        iterations=25,
        passes=5,
        learning_rate=(0.3, 0.3, 0.05, 0.5),
        loss=LossConfig(gradient_reward=0.0),
    )
    prelim_iterations: int = eqx.field(static=True, default=50)
    sources: int = eqx.field(static=True, default=4)
    min_track_length: int = eqx.field(static=True, default=2)
    max_error: float | None = eqx.field(static=True, default=None)
    canny_low: float = eqx.field(static=True, default=40.0)
    canny_high: float = eqx.field(static=True, default=100.0)
    max_edge_points: int = eqx.field(static=True, default=6000)
    edge_gap: float = eqx.field(static=True, default=1.0)

    def __check_init__(self):
        for name in ("prelim_iterations", "sources", "min_track_length", "max_edge_points"):
            v = getattr(self, name)
            low = 0 if name in ("prelim_iterations", "max_edge_points") else 1
            if not isinstance(v, int) or v < low:
                raise ValueError(f"MVSConfig.{name} must be an int >= {low}; got {v!r}")
        if not 0 <= self.canny_low <= self.canny_high:
            raise ValueError(
                f"MVSConfig needs 0 <= canny_low <= canny_high; got {self.canny_low}, "
                f"{self.canny_high}"
            )
        if self.optimize.model.render.nearer != "larger":
            raise ValueError("MVSConfig.optimize.model.render.nearer must be 'larger' (labels)")


@dataclasses.dataclass(frozen=True)
class MVSInput:
    """A COLMAP model and its images.

    Attributes:
        model: the `ColmapModel`.
        images: image name → ``(H, W, 3)`` float32 RGB in [0, 1] (resized by ``scale``).
        scale: factor the images were resized by (the intrinsics are scaled to match).
        source: the model folder.
    """

    model: ColmapModel
    images: dict
    scale: float
    source: str


def _find_images_dir(model_dir: str) -> str:
    here = os.path.abspath(model_dir)
    tried = []
    for _ in range(3):  # project/images next to project/sparse/0 (COLMAP's layout)
        cand = os.path.join(here, "images")
        tried.append(cand)
        if os.path.isdir(cand):
            return cand
        here = os.path.dirname(here)
    raise FileNotFoundError(
        f"no images folder found for the COLMAP model {model_dir} (tried {tried}); "
        "pass --images DIR"
    )


def load_mvs_input(
    model_dir: str | os.PathLike,
    images_dir: str | os.PathLike | None = None,
    *,
    scale: float | None = None,
    names: list[str] | None = None,
) -> MVSInput:
    """Read a COLMAP model (text or binary) and its registered images.

    Args:
        model_dir: the model folder (``cameras``, ``images``, ``points3D`` as .txt or .bin).
        images_dir: the image folder (default: an ``images`` folder in ``model_dir`` or up to
            two levels above it, COLMAP's project layout).
        scale: optional resize factor in (0, 1] (``cv2.INTER_AREA``).
        names: read only these images (default: every registered image).

    Returns:
        `MVSInput`.

    Raises:
        FileNotFoundError: missing model, image folder or image file.
        ValueError: malformed model, an image whose size differs from its camera's, a bad
            scale.
    """
    model_dir = os.fspath(model_dir)
    model = read_colmap_model(model_dir)
    if not model.images:
        raise ValueError(f"the COLMAP model in {model_dir} has no registered images")
    if scale is not None and not 0 < scale <= 1:
        raise ValueError(f"scale must be in (0, 1]; got {scale}")
    images_dir = _find_images_dir(model_dir) if images_dir is None else os.fspath(images_dir)
    if not os.path.isdir(images_dir):
        raise FileNotFoundError(f"image folder not found: {images_dir}")
    wanted = names if names is not None else [im.name for im in model.images.values()]
    images = {}
    for name in wanted:
        im = model.image_by_name(name)
        cam = model.cameras[im.camera_id]
        path = os.path.join(images_dir, name)
        if not os.path.isfile(path):
            raise FileNotFoundError(f"image {name!r} of the COLMAP model not found: {path}")
        rgb = read_rgb(path)
        if rgb.shape[:2] != (cam.height, cam.width):
            raise ValueError(
                f"{path} is {rgb.shape[1]}x{rgb.shape[0]} px but its COLMAP camera "
                f"{cam.camera_id} is {cam.width}x{cam.height}"
            )
        if scale is not None and scale != 1.0:
            rgb = read_rgb(path, scale=scale)
        images[name] = rgb
    return MVSInput(model=model, images=images, scale=float(scale or 1.0), source=model_dir)


def nearest_sources(model: ColmapModel, reference: str, count: int) -> list[str]:
    """Names of the ``count`` images whose camera centres are nearest the reference's."""
    ref = model.image_by_name(reference)
    others = [im for im in model.images.values() if im.image_id != ref.image_id]
    others.sort(key=lambda im: float(np.linalg.norm(im.centre - ref.centre)))
    return [im.name for im in others[:count]]


def edge_points(
    image: np.ndarray,
    *,
    low: float,
    high: float,
    capacity: int,
    avoid: np.ndarray | None = None,
    gap: float = 1.0,
) -> np.ndarray:
    """Pixel positions of the RGB edges of an image (Canny on its 8-bit grey version).

    Args:
        image: ``(H, W, 3)`` RGB in [0, 1].
        low, high: Canny hysteresis thresholds (8-bit grey levels).
        capacity: the most points returned (evenly thinned in raster order beyond it).
        avoid: optional ``(M, 2)`` ``(x, y)`` positions; edge pixels within ``gap`` pixels
            of one are dropped.
        gap: see ``avoid``.

    Returns:
        ``(N, 2)`` float32 ``(x, y)`` pixel centres, ``N <= capacity``.

    References:
        Thesis Sec. 7.2.2 ("we sample this result at RGB edges"); Canny, PAMI 1986.
    """
    grey = cv2.cvtColor(np.round(np.clip(image, 0, 1) * 255).astype(np.uint8), cv2.COLOR_RGB2GRAY)
    edges = cv2.Canny(grey, low, high, L2gradient=True) > 0
    if avoid is not None and len(avoid):
        near = np.zeros_like(edges)
        xi = np.clip(np.round(avoid[:, 0]).astype(int), 0, edges.shape[1] - 1)
        yi = np.clip(np.round(avoid[:, 1]).astype(int), 0, edges.shape[0] - 1)
        near[yi, xi] = True
        r = int(np.ceil(gap))
        near = cv2.dilate(near.astype(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8)) > 0
        edges &= ~near
    ys, xs = np.nonzero(edges)
    if len(xs) > capacity:
        keep = np.linspace(0, len(xs) - 1, capacity).round().astype(int)
        ys, xs = ys[keep], xs[keep]
    return np.stack([xs, ys], axis=1).astype(np.float32)


@dataclasses.dataclass(frozen=True)
class MVSResult:
    """Depth of one reference view.

    Attributes:
        name: reference image name.
        depth: ``(H, W)`` float32 depth (world units of the COLMAP model).
        disparity: ``(H, W)`` float32 label map ``f·B / depth`` (pixels of parallax for a
            baseline ``B``).
        stages: ``{"sparse", "augmented", "optimized"}`` → ``(H, W)`` depth after the
            diffusion of the sparse points alone (initial ``Q``), after the ``Q``
            preliminary and the edge augmentation, and after the full optimisation.
        sparse_points: ``(Ns, 3)`` ``(x, y, label)`` of the sparse points.
        edge_points: ``(Ne, 3)`` ``(x, y, label)`` of the added edge points.
        params: the final `DiffParams` (capacity rounded up; ``params.label[:Ns + Ne]``
            are the sparse then the edge points, the rest is unused padding).
        cameras: the `MultiViewCameras` (``scale = f·B``).
        sources: names of the source views.
        loss: ``(steps,)`` loss of every Adam step (preliminary, then final).
        seconds: per-stage wall times.
    """

    name: str
    depth: np.ndarray
    disparity: np.ndarray
    stages: dict
    sparse_points: np.ndarray
    edge_points: np.ndarray
    params: DiffParams
    cameras: MultiViewCameras
    sources: tuple
    loss: np.ndarray
    seconds: dict


def estimate_depth_mvs(
    data: MVSInput,
    reference: str,
    config: MVSConfig = MVSConfig(),
    *,
    progress: Callable[[str, int, dict], None] | None = None,
) -> MVSResult:
    """Depth of one reference view from posed source views and sparse points (Sec. 7.2.2).

    Args:
        data: `MVSInput` holding at least the reference and one other image.
        reference: reference image name.
        config: `MVSConfig`.
        progress: called as ``progress("sparse", -1, {})`` before the first (compiling)
            diffusion and as ``progress(stage, step, info)`` after every Adam step, stage
            ``"prelim"`` or ``"optimize"``.

    Returns:
        `MVSResult`.

    Raises:
        KeyError: unknown reference image.
        ValueError: no source image, non-pinhole cameras, source images of a different size
            than each other, no sparse point in the reference view.

    References:
        Thesis Sec. 7.2.2 (sparse points, a preliminary diffusion with the smoothness
        optimised for 50 iterations, sampling at RGB edges, all parameters in turns of 25
        iterations repeated 5 times), Sec. 7.1.5.
    """
    model = data.model
    if reference not in data.images:
        model.image_by_name(reference)  # KeyError with the known names if unknown
        raise KeyError(f"image {reference!r} was not loaded")
    sources = [n for n in nearest_sources(model, reference, len(model.images)) if n in data.images]
    sources = sources[: config.sources]
    if not sources:
        raise ValueError(f"no source view for {reference!r}: multi-view depth needs two images")
    shapes = {data.images[n].shape for n in sources}
    if len(shapes) > 1:
        raise ValueError(f"source images must share one size; got {sorted(shapes)}")
    seconds = {}
    t0 = time.perf_counter()
    cams = multiview_cameras(model, reference, sources, image_scale=data.scale)
    ref = jnp.asarray(data.images[reference])
    srcs = jnp.asarray(np.stack([data.images[n] for n in sources]))
    H, W = ref.shape[:2]
    sd = sparse_depth_points(
        model,
        reference,
        min_track_length=config.min_track_length,
        max_error=config.max_error,
        observed_only=True,
    )
    if sd.position.shape[0] == 0:
        raise ValueError(f"no sparse COLMAP point is observed in {reference!r}")
    s = data.scale
    pos = (np.asarray(sd.position) + 0.5) * s - 0.5  # resized pixel centres
    lab = np.asarray(cams.label(sd.depth))
    ep = edge_points(
        np.asarray(ref),
        low=config.canny_low,
        high=config.canny_high,
        capacity=config.max_edge_points,
        avoid=pos,
        gap=config.edge_gap,
    )
    # one fixed-capacity point set for every stage (and, rounded up to a multiple of
    # `_CAPACITY_STEP`, for most views): the edge points are masked out until they receive
    # their labels, the padding always (one compilation of the step serves them all)
    n_sparse, n_edge = len(pos), len(ep)
    n = n_sparse + n_edge
    cap = -(-n // _CAPACITY_STEP) * _CAPACITY_STEP
    mean = float(np.mean(lab))
    params = DiffParams(
        position=jnp.asarray(np.concatenate([pos, ep, np.zeros((cap - n, 2))]), jnp.float32),
        label=jnp.full(cap, mean, jnp.float32).at[:n_sparse].set(lab),
        R=jnp.zeros(cap, jnp.float32),
        Q=initial_params(jnp.asarray(pos), jnp.asarray(lab), ref, config.optimize.model).Q,
    )
    index = jnp.arange(cap)
    sparse_only, every = index < n_sparse, index < n
    run = functools.partial(optimize_multiview, reference=ref, sources=srcs, cameras=cams)
    evaluate = dataclasses.replace(config.optimize, passes=0)
    if progress is not None:
        progress("sparse", -1, {})
    _, hist = run(params, config=evaluate, valid=sparse_only)
    sparse_label = hist["label"]
    seconds["sparse"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    loss = []
    prelim = sparse_label
    if config.prelim_iterations > 0:
        pre_cfg = dataclasses.replace(
            config.optimize, blocks=("Q",), iterations=config.prelim_iterations, passes=1
        )
        params, hist = run(
            params,
            config=pre_cfg,
            valid=sparse_only,
            x0=sparse_label,
            callback=None if progress is None else (lambda k, i: progress("prelim", k, i)),
        )
        prelim = hist["label"]
        loss.append(hist["loss"])
    elab = np.asarray(sample_bilinear(jnp.asarray(prelim), jnp.asarray(ep)))
    params = eqx.tree_at(lambda p: p.label, params, params.label.at[n_sparse:n].set(elab))
    _, hist = run(params, config=evaluate, valid=every, x0=prelim)
    augmented = hist["label"]
    seconds["augment"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    params, hist = run(
        params,
        config=config.optimize,
        valid=every,
        x0=augmented,
        callback=None if progress is None else (lambda k, i: progress("optimize", k, i)),
    )
    loss.append(hist["loss"])
    final = hist["label"]
    seconds["optimize"] = time.perf_counter() - t0
    to_depth = lambda x: np.asarray(cams.depth(jnp.asarray(x)), np.float32)  # noqa: E731
    return MVSResult(
        name=reference,
        depth=to_depth(final),
        disparity=np.asarray(final, np.float32),
        stages={
            "sparse": to_depth(sparse_label),
            "augmented": to_depth(augmented),
            "optimized": to_depth(final),
        },
        sparse_points=np.column_stack([pos, lab]).astype(np.float32),
        edge_points=np.column_stack([ep, elab]).astype(np.float32),
        params=params,
        cameras=cams,
        sources=tuple(sources),
        loss=np.concatenate(loss) if loss else np.zeros(0),
        seconds=seconds,
    )


def view_stem(name: str) -> str:
    """File stem for an image name (extension dropped, folders joined by ``_``)."""
    return os.path.splitext(name)[0].replace("/", "_").replace(os.sep, "_")


def _plain(obj):
    """A JSON-ready copy of a config: modules and dataclasses → dicts, arrays → lists."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (tuple, list)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.ndarray, jnp.ndarray)) or hasattr(obj, "__array__"):
        a = np.asarray(obj)
        if a.dtype == np.float32:  # shortest decimals that round-trip in float32
            short = [float(np.format_float_positional(v, unique=True)) for v in a.ravel()]
            a = np.array(short).reshape(a.shape)
        return a.item() if a.ndim == 0 else a.tolist()
    return obj


def _package_version() -> str | None:
    import importlib.metadata

    try:
        return importlib.metadata.version("mvedge_jax")
    except importlib.metadata.PackageNotFoundError:
        return None


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def mvs_steps(config: MVSConfig) -> int:
    """Adam steps per reference view (preliminary + final optimisation)."""
    o = config.optimize
    return config.prelim_iterations + o.iterations * o.passes * len(o.blocks)


def read_gt_depth(folder: str | os.PathLike, names: list[str]) -> dict[str, np.ndarray]:
    """Ground-truth depth maps ``<folder>/<stem>.pfm`` of the named images.

    Raises:
        FileNotFoundError: a map is missing.
    """
    from .io import read_pfm

    folder = os.fspath(folder)
    out = {}
    for n in names:
        path = os.path.join(folder, view_stem(n) + ".pfm")
        if not os.path.isfile(path):
            raise FileNotFoundError(f"ground-truth depth for {n!r} not found: {path}")
        out[n] = read_pfm(path)
    return out


def view_metrics(result: MVSResult, gt: np.ndarray | None = None) -> dict:
    """The ``metrics.json`` entry of one view (and the scale-fit errors of each stage when
    ground truth is given, resized to the result's size if needed)."""
    from .metrics import scale_fit_metrics

    fb = float(result.cameras.scale)
    entry = {
        "sources": list(result.sources),
        "label_scale_f_times_baseline": fb,
        "sparse_points": int(len(result.sparse_points)),
        "edge_points": int(len(result.edge_points)),
        "depth_range": [_finite(np.nanmin(result.depth)), _finite(np.nanmax(result.depth))],
        "disparity_range": [
            _finite(np.nanmin(result.disparity)),
            _finite(np.nanmax(result.disparity)),
        ],
        "loss_first": _finite(result.loss[0]) if result.loss.size else None,
        "loss_last": _finite(result.loss[-1]) if result.loss.size else None,
        "seconds": {k: round(v, 3) for k, v in result.seconds.items()},
    }
    if gt is not None:
        g = np.asarray(gt, np.float32)
        if g.shape != result.depth.shape:
            g = cv2.resize(g, result.depth.shape[::-1], interpolation=cv2.INTER_NEAREST)
        entry["scale_fit"] = {}
        for stage, d in result.stages.items():
            m = scale_fit_metrics(d, g)
            entry["scale_fit"][stage] = {
                "mse": m["mse"],
                "q25": m["q25"],
                "scale": m["scale"],
                "valid_pixels": m["valid_pixels"],
            }
    return entry


def write_mvs_outputs(
    writer,
    results: list[MVSResult],
    *,
    gt: dict[str, np.ndarray] | None = None,
    meta: dict | None = None,
) -> dict:
    """Write the outputs of `estimate_depth_mvs` for one or more reference views.

    Per view (``<stem>`` = `view_stem` of its name): ``depth/<stem>.pfm`` (depth, world
    units), ``disparity/<stem>.pfm`` (the label ``f·B / depth``), ``disparity/<stem>.png``
    (colour map), ``stages/<stem>.png`` (disparity after the sparse diffusion, the edge
    augmentation and the optimisation, one colour range, left to right); ``mvs.npz`` with
    ``depth_<stem>``, ``disparity_<stem>``, ``sparse_points_<stem>``, ``edge_points_<stem>``
    (rows ``x, y, label``); ``metrics.json``.

    Args:
        writer: an `mvedge_jax.io.OutputWriter` (committed by the caller).
        results: the `MVSResult` of each reference view.
        gt: optional image name → ground-truth depth; adds the scale-fit errors.
        meta: extra top-level entries of ``metrics.json`` (input paths, config, ...).

    Returns:
        The ``metrics.json`` content.
    """
    from .viz import colorize_disparity

    arrays, views = {}, {}
    for r in results:
        stem = view_stem(r.name)
        writer.pfm(f"depth/{stem}.pfm", r.depth)
        writer.pfm(f"disparity/{stem}.pfm", r.disparity)
        writer.png(f"disparity/{stem}.png", colorize_disparity(r.disparity))
        lo, hi = np.percentile(r.disparity, [1, 99])
        fb = float(r.cameras.scale)
        strip = [
            colorize_disparity(fb / r.stages[k], vmin=lo, vmax=hi)
            for k in ("sparse", "augmented", "optimized")
        ]
        gap = np.zeros((strip[0].shape[0], 2, 3), np.uint8)
        writer.png(
            f"stages/{stem}.png", np.concatenate([strip[0], gap, strip[1], gap, strip[2]], 1)
        )
        arrays[f"depth_{stem}"] = r.depth
        arrays[f"disparity_{stem}"] = r.disparity
        arrays[f"sparse_points_{stem}"] = r.sparse_points
        arrays[f"edge_points_{stem}"] = r.edge_points
        views[r.name] = view_metrics(r, None if gt is None else gt.get(r.name))
    writer.npz("mvs.npz", **arrays)
    metrics = dict(meta or {})
    metrics["views"] = views
    if gt is not None:
        for stage in ("sparse", "augmented", "optimized"):
            fits = [v["scale_fit"][stage] for v in views.values() if "scale_fit" in v]
            if fits:
                metrics.setdefault("scale_fit_mean", {})[stage] = {
                    "mse": float(np.mean([f["mse"] for f in fits])),
                    "q25": float(np.mean([f["q25"] for f in fits])),
                }
    writer.json("metrics.json", metrics)
    return metrics


def run_mvs(
    model_dir: str | os.PathLike,
    out: str | os.PathLike,
    *,
    reference: str | None = None,
    all_views: bool = False,
    images_dir: str | os.PathLike | None = None,
    gt_dir: str | os.PathLike | None = None,
    scale: float | None = None,
    config: MVSConfig = MVSConfig(),
    force: bool = False,
    progress: Callable[[str, str, int, dict], None] | None = None,
) -> dict:
    """The unstructured multi-view main job: depth of one or every view, written to ``out``.

    Args:
        model_dir: COLMAP model folder (text or binary).
        out: output folder (must not exist unless ``force``; never inside ``model_dir``).
        reference: reference image name (required unless ``all_views``).
        all_views: every registered image in turn as the reference.
        images_dir: image folder (default: found next to the model, see `load_mvs_input`).
        gt_dir: optional folder of ground-truth depth maps ``<stem>.pfm`` (scale-fit errors
            in ``metrics.json``).
        scale: optional image resize factor in (0, 1].
        config: `MVSConfig`.
        force: replace an existing ``out``.
        progress: called as ``progress(view, stage, step, info)`` after every Adam step.

    Returns:
        The ``metrics.json`` content.

    Raises:
        FileNotFoundError: missing inputs.
        ValueError: bad output folder, no reference given, unknown reference, bad input.

    References:
        Thesis Sec. 7.2.2.
    """
    import jax

    from .io import OutputWriter, check_output_dir

    check_output_dir(out, model_dir, force=force)
    if reference is None and not all_views:
        raise ValueError("give a reference image (--ref NAME) or --all-views")
    data = load_mvs_input(model_dir, images_dir, scale=scale)
    names = sorted(data.images) if all_views else [reference]
    for n in names:
        if n not in data.images:
            raise ValueError(f"no image named {n!r} in the model; have {sorted(data.images)}")
    gt = read_gt_depth(gt_dir, names) if gt_dir is not None else None
    t0 = time.perf_counter()
    results = []
    for n in names:
        cb = None if progress is None else functools.partial(progress, n)
        results.append(estimate_depth_mvs(data, n, config, progress=cb))
    meta = {
        "input": os.path.abspath(os.fspath(model_dir)),
        "images": None if images_dir is None else os.path.abspath(os.fspath(images_dir)),
        "scale": data.scale,
        "references": names,
        "config": _plain(config),
        "mvedge_jax_version": _package_version(),
        "jax_version": jax.__version__,
        "backend": jax.default_backend(),
        "device": str(jax.devices()[0]),
        "seconds_total": round(time.perf_counter() - t0, 3),
        "units": {
            "depth": "world units of the COLMAP model",
            "disparity": "f·B / depth: pixels of parallax for a baseline B (per view: "
            "label_scale_f_times_baseline = f·B)",
            "scale_fit": "thesis Sec. 7.2.2: least-squares scale on 500 random valid pixels, "
            "best of ten fits; mse in squared depth units, q25 in depth units",
        },
    }
    writer = OutputWriter(out)
    try:
        metrics = write_mvs_outputs(writer, results, gt=gt, meta=meta)
        writer.commit()
    except BaseException:
        writer.abort()
        raise
    return metrics
