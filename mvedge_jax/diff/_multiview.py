"""Unstructured multi-view input (thesis Sec. 7.2.2): sparse depth points, depth warping, the
eq 7.16 loss between posed views and its block-coordinate optimisation.

Pinhole cameras from a COLMAP model (`mvedge_jax.io.read_colmap_text`). Pixel coordinates
follow this project's convention (pixel centres at integers): COLMAP's ``(u, v)`` minus 0.5.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float

from ..io import ColmapCamera, ColmapImage, ColmapModel
from ._loss import LossConfig, combine_view_errors, masked_view_errors, weighted_terms
from ._model import DiffParams, predict
from ._optimize import _DEFAULT_OPTIMIZE, BLOCKS, OptimizeConfig, adam_block_update, adam_reset

_DEFAULT_LOSS = LossConfig()

_PINHOLE = ("SIMPLE_PINHOLE", "PINHOLE")
_RADIAL = ("SIMPLE_RADIAL", "RADIAL", "OPENCV", "FULL_OPENCV")


def _distort(camera: ColmapCamera, u: np.ndarray, v: np.ndarray):
    """Apply the camera's lens distortion to normalised coordinates (COLMAP's formulas)."""
    m, d = camera.model, camera.distortion
    if m in _PINHOLE:
        return u, v
    r2 = u * u + v * v
    if m == "SIMPLE_RADIAL":
        f = 1 + d[0] * r2
        return u * f, v * f
    if m == "RADIAL":
        f = 1 + d[0] * r2 + d[1] * r2 * r2
        return u * f, v * f
    k1, k2, p1, p2 = d[:4]
    if m == "OPENCV":
        f = 1 + k1 * r2 + k2 * r2 * r2
    else:  # FULL_OPENCV
        k3, k4, k5, k6 = d[4:8]
        f = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
    uv = u * v
    du = 2 * p1 * uv + p2 * (r2 + 2 * u * u)
    dv = p1 * (r2 + 2 * v * v) + 2 * p2 * uv
    return u * f + du, v * f + dv


def project_points(
    xyz: np.ndarray, camera: ColmapCamera, image: ColmapImage
) -> tuple[np.ndarray, np.ndarray]:
    """Project world points into an image.

    Args:
        xyz: ``(P, 3)`` world coordinates.
        camera: the image's `ColmapCamera` (pinhole, SIMPLE_RADIAL, RADIAL, OPENCV or
            FULL_OPENCV).
        image: the `ColmapImage` (pose).

    Returns:
        ``(position (P, 2), depth (P,))``: pixel ``(x, y)`` with pixel centres at integers,
        and the camera-space depth ``z`` (``<= 0`` behind the camera).

    Raises:
        ValueError: for camera models whose projection is not implemented (fisheye, FOV, ...).
    """
    if camera.model not in _PINHOLE + _RADIAL:
        raise ValueError(
            f"projection with camera model {camera.model} is not implemented; supported: "
            f"{_PINHOLE + _RADIAL}"
        )
    xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
    cam = xyz @ image.rotation.T + image.tvec
    z = cam[:, 2]
    zs = np.where(np.abs(z) > 1e-12, z, 1e-12)
    u, v = _distort(camera, cam[:, 0] / zs, cam[:, 1] / zs)
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    x = fx * u + cx - camera.pixel_offset
    y = fy * v + cy - camera.pixel_offset
    return np.stack([x, y], axis=1), z


class SparseDepth(eqx.Module):
    """Sparse depth samples of one reference view.

    Attributes:
        position: ``(N, 2)`` float32 pixel ``(x, y)``, pixel centres at integers.
        depth: ``(N,)`` float32 camera-space depth (world units).
        point_ids: ``(N,)`` int32 COLMAP point ids.
        shape: ``(H, W)`` of the reference image.
    """

    position: Float[Array, "N 2"]
    depth: Float[Array, " N"]
    point_ids: Array
    shape: tuple[int, int] = eqx.field(static=True)

    @property
    def inverse_depth(self) -> Float[Array, " N"]:
        """``1 / depth``: larger is nearer, linear in image-space parallax (use with
        ``RenderConfig(nearer="larger")``)."""
        return 1.0 / self.depth


def _resolve_image(model: ColmapModel, image: int | str) -> ColmapImage:
    if isinstance(image, str):
        return model.image_by_name(image)
    if image not in model.images:
        raise KeyError(f"no image with id {image}; have {sorted(model.images)}")
    return model.images[image]


def sparse_depth_points(
    model: ColmapModel,
    image: int | str,
    *,
    min_track_length: int = 2,
    max_error: float | None = None,
    observed_only: bool = False,
    min_depth: float = 1e-6,
) -> SparseDepth:
    """Depth samples for a reference view from the sparse COLMAP points (Sec. 7.2.2).

    Every 3-D point with a long enough track (and small enough reprojection error) is
    projected into the reference view; points behind the camera or outside the image are
    dropped. With ``observed_only`` only the points the reference image itself observes are
    used (no visibility reasoning is needed for them).

    Args:
        model: a `ColmapModel`.
        image: the reference image id or name.
        min_track_length: minimum number of observations of a point.
        max_error: maximum reprojection error in pixels (``None``: no limit).
        observed_only: keep only points observed in the reference image.
        min_depth: minimum camera-space depth.

    Returns:
        `SparseDepth` for the reference view.

    Raises:
        KeyError: unknown image.
        ValueError: unsupported camera model.

    References:
        Thesis Sec. 7.2.2 (COLMAP's sparse output as the initial point set).
    """
    im = _resolve_image(model, image)
    cam = model.cameras[im.camera_id]
    P = model.points3d
    keep = P.track_length >= min_track_length
    if max_error is not None:
        keep &= P.error <= max_error
    if observed_only:
        keep &= np.isin(P.ids, im.point3d_ids[im.point3d_ids >= 0])
    pos, z = project_points(P.xyz, cam, im)
    W, H = cam.width, cam.height
    keep &= (z > min_depth) & (pos[:, 0] > -0.5) & (pos[:, 0] < W - 0.5)
    keep &= (pos[:, 1] > -0.5) & (pos[:, 1] < H - 0.5)
    return SparseDepth(
        position=jnp.asarray(pos[keep], jnp.float32),
        depth=jnp.asarray(z[keep], jnp.float32),
        point_ids=jnp.asarray(P.ids[keep], jnp.int32),
        shape=(H, W),
    )


def relative_pose(reference: ColmapImage, source: ColmapImage) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` with ``X_source = R X_reference + t`` (camera coordinates)."""
    Rr, Rs = reference.rotation, source.rotation
    R = Rs @ Rr.T
    return R, source.tvec - R @ reference.tvec


def _reproject(depth, k_reference, k_source, rotation, translation):
    """Source-view pixel ``(sx, sy)`` and camera-space depth ``z`` of every reference pixel."""
    d = jnp.asarray(depth)
    dtype = d.dtype
    Kr, Ks = jnp.asarray(k_reference, dtype), jnp.asarray(k_source, dtype)
    R, t = jnp.asarray(rotation, dtype), jnp.asarray(translation, dtype)
    H, W = d.shape
    ys, xs = jnp.meshgrid(jnp.arange(H, dtype=dtype), jnp.arange(W, dtype=dtype), indexing="ij")
    pix = jnp.stack([xs, ys, jnp.ones_like(xs)], -1)
    # Full float32 precision: with a GPU's default TensorFloat-32 matmuls (inputs rounded to
    # a 10-bit mantissa) pixel coordinates and focal lengths near 1000 move the projection
    # by up to ~0.8 px.
    hi = lax.Precision.HIGHEST
    X = jnp.matmul(pix, jnp.linalg.inv(Kr).T, precision=hi) * d[..., None]
    Xs = jnp.matmul(X, R.T, precision=hi) + t
    z = Xs[..., 2]
    zs = jnp.where(jnp.abs(z) > 1e-9, z, 1e-9)
    proj = jnp.matmul(Xs / zs[..., None], Ks.T, precision=hi)
    return proj[..., 0], proj[..., 1], z


def warp_by_depth(
    image: Float[ArrayLike, "H2 W2 C"],
    depth: Float[ArrayLike, "H W"],
    k_reference: Float[ArrayLike, "3 3"],
    k_source: Float[ArrayLike, "3 3"],
    rotation: Float[ArrayLike, "3 3"],
    translation: Float[ArrayLike, 3],
) -> tuple[Float[Array, "H W C"], Float[Array, "H W"]]:
    """Resample a source view into the reference view through the reference depth map.

    Reference pixel ``p`` (centres at integers) is back-projected with its depth, moved into
    the source camera (``X_s = R X_r + t``) and projected with ``k_source``; the source image
    is sampled bilinearly there (border-clamped). Differentiable in ``image`` and ``depth``;
    the general-camera counterpart of `mvedge_jax.lightfield.backward_warp` for eq 7.15.
    Pinhole intrinsics in this project's pixel convention (subtract 0.5 from COLMAP's
    principal point).

    Args:
        image: ``(H2, W2, C)`` source view.
        depth: ``(H, W)`` reference depth (> 0).
        k_reference: ``(3, 3)`` reference intrinsics.
        k_source: ``(3, 3)`` source intrinsics.
        rotation: ``(3, 3)`` relative rotation (see `relative_pose`).
        translation: ``(3,)`` relative translation.

    Returns:
        ``(warped (H, W, C), valid (H, W))``: the resampled view and a float mask that is 1
        where the sample lands inside the source image in front of its camera.
    """
    img = jnp.asarray(image)
    d = jnp.asarray(depth)
    dtype = d.dtype
    H2, W2 = img.shape[:2]
    sx, sy, z = _reproject(d, k_reference, k_source, rotation, translation)
    valid = (z > 0) & (sx > -0.5) & (sx < W2 - 0.5) & (sy > -0.5) & (sy < H2 - 0.5)
    sx = jnp.clip(sx, 0.0, W2 - 1)
    sy = jnp.clip(sy, 0.0, H2 - 1)
    x0 = jnp.clip(jnp.floor(sx), 0, max(W2 - 2, 0))
    y0 = jnp.clip(jnp.floor(sy), 0, max(H2 - 2, 0))
    fx, fy = (sx - x0)[..., None], (sy - y0)[..., None]
    xi, yi = x0.astype(jnp.int32), y0.astype(jnp.int32)
    x1, y1 = jnp.minimum(xi + 1, W2 - 1), jnp.minimum(yi + 1, H2 - 1)
    im = img.astype(dtype)
    top = im[yi, xi] * (1 - fx) + im[yi, x1] * fx
    bot = im[y1, xi] * (1 - fx) + im[y1, x1] * fx
    return top * (1 - fy) + bot * fy, valid.astype(dtype)


def intrinsics(camera: ColmapCamera, image_scale: float = 1.0) -> np.ndarray:
    """``(3, 3)`` pinhole K of a COLMAP camera in this project's pixel convention.

    Args:
        camera: a `ColmapCamera`.
        image_scale: factor by which the image was resized (COLMAP's corner-origin
            coordinates scale linearly: ``f`` and ``c`` are multiplied by it).
    """
    K = camera.calibration_matrix()
    K[:2] *= image_scale
    K[0, 2] -= camera.pixel_offset
    K[1, 2] -= camera.pixel_offset
    return K


class MultiViewCameras(eqx.Module):
    """The cameras of one reference view and its S source views, and the label scale.

    Labels are scaled inverse depths ``label = scale / depth`` with ``scale = f_ref · B``
    (reference focal length in pixels times a baseline ``B`` in world units): the pixel
    parallax a point at that depth shows between two cameras ``B`` apart, so that the
    render's depth spread σ_Z = 1 and the optimiser's learning rates keep their pixel meaning.

    Attributes:
        k_reference: ``(3, 3)`` reference intrinsics (pixel centres at integers).
        k_source: ``(S, 3, 3)`` source intrinsics.
        rotation: ``(S, 3, 3)`` relative rotations, ``X_s = R X_ref + t``.
        translation: ``(S, 3)`` relative translations.
        scale: ``()`` ``f_ref · B`` in pixel × world units.
    """

    k_reference: Float[Array, "3 3"]
    k_source: Float[Array, "S 3 3"]
    rotation: Float[Array, "S 3 3"]
    translation: Float[Array, "S 3"]
    scale: Float[Array, ""]

    def depth(self, label: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
        """Depth of a label (``scale / label``; labels below 1e-6 are clamped)."""
        label = jnp.asarray(label)
        return self.scale.astype(label.dtype) / jnp.maximum(label, 1e-6)

    def label(self, depth: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
        """Label of a depth (``scale / depth``)."""
        depth = jnp.asarray(depth)
        return self.scale.astype(depth.dtype) / depth


def multiview_cameras(
    model: ColmapModel,
    reference: int | str,
    sources: list[int | str],
    *,
    baseline: float | None = None,
    image_scale: float = 1.0,
) -> MultiViewCameras:
    """`MultiViewCameras` of a reference image and source images of a COLMAP model.

    Args:
        model: a `ColmapModel` with pinhole cameras (undistort other models first, e.g.
            ``colmap image_undistorter``).
        reference: reference image id or name.
        sources: source image ids or names (at least one).
        baseline: ``B`` of the label scale (world units; default the mean distance from the
            reference camera centre to the source camera centres).
        image_scale: factor by which the images were resized (intrinsics scaled to match).

    Returns:
        `MultiViewCameras` in float32.

    Raises:
        KeyError: unknown image.
        ValueError: no source, a non-pinhole camera, coincident camera centres.

    References:
        Thesis Sec. 7.2.2 (unstructured views), eq 7.15 (warping between views).
    """
    if not sources:
        raise ValueError("multi-view depth needs at least one source view besides the reference")
    ref = _resolve_image(model, reference)
    src = [_resolve_image(model, s) for s in sources]
    ks = []
    for im in [ref, *src]:
        cam = model.cameras[im.camera_id]
        if cam.model not in _PINHOLE:
            raise ValueError(
                f"image {im.name!r} has a {cam.model} camera; multi-view warping needs pinhole "
                "cameras (SIMPLE_PINHOLE or PINHOLE): undistort first (colmap image_undistorter)"
            )
        ks.append(intrinsics(cam, image_scale))
    poses = [relative_pose(ref, s) for s in src]
    if baseline is None:
        baseline = float(np.mean([np.linalg.norm(s.centre - ref.centre) for s in src]))
    if not np.isfinite(baseline) or baseline <= 0:
        raise ValueError(f"baseline must be finite and > 0; got {baseline} (coincident cameras?)")
    return MultiViewCameras(
        k_reference=jnp.asarray(ks[0], jnp.float32),
        k_source=jnp.asarray(np.stack(ks[1:]), jnp.float32),
        rotation=jnp.asarray(np.stack([R for R, _ in poses]), jnp.float32),
        translation=jnp.asarray(np.stack([t for _, t in poses]), jnp.float32),
        scale=jnp.asarray(ks[0][0, 0] * baseline, jnp.float32),
    )


def multiview_occlusion_mask(
    label: Float[ArrayLike, "H W"],
    cameras: MultiViewCameras,
    index: int,
    source_shape: tuple[int, int],
    *,
    tolerance: Float[ArrayLike, ""] = 0.25,
) -> Bool[Array, "H W"]:
    """Which reference pixels source view ``index`` sees (no gradient; eq 7.15 ``M^i``).

    Every reference pixel is moved into the source camera with its depth; a z-buffer of the
    landing pixels (nearest pixel) keeps the largest source-view label ``scale / z_s``
    (the nearest point). A pixel is visible when it lands inside the source image in front
    of the camera and its own source-view label is within ``tolerance`` of the z-buffer
    there. The general-camera counterpart of `occlusion_mask`.

    Args:
        label: ``(H, W)`` reference label map (``scale / depth``).
        cameras: `MultiViewCameras`.
        index: source view index in ``[0, S)`` (may be traced).
        source_shape: ``(H2, W2)`` of the source image.
        tolerance: visibility slack in label units (pixels of parallax).

    Returns:
        ``(H, W)`` bool mask.

    References:
        Thesis eq 7.15 (binary occlusion mask recomputed at every iteration).
    """
    d = jnp.asarray(label)
    indices = jnp.asarray(index, jnp.int32)[None]
    return _multiview_occlusion_masks(d, cameras, indices, source_shape, tolerance)[0]


def _multiview_occlusion_masks(d, cameras: MultiViewCameras, indices, source_shape, tolerance):
    """`multiview_occlusion_mask` of the source views ``indices`` ``(K,)`` at once:
    ``(K, H, W)``. One z-buffer over the K stacked source frames (flat indices), so the
    program holds no batched scatter (see `mvedge_jax.lightfield.forward_project_views`)."""
    d = jax.lax.stop_gradient(d)
    H2, W2 = source_shape
    n = H2 * W2
    depth = cameras.depth(d)

    def landing(i):
        sx, sy, z = _reproject(
            depth,
            cameras.k_reference,
            cameras.k_source[i],
            cameras.rotation[i],
            cameras.translation[i],
        )
        inside = (z > 0) & (sx > -0.5) & (sx < W2 - 0.5) & (sy > -0.5) & (sy < H2 - 0.5)
        ls = cameras.scale.astype(d.dtype) / jnp.where(z > 0, z, 1.0)
        xi = jnp.clip(jnp.floor(sx + 0.5), 0, W2 - 1).astype(jnp.int32)
        yi = jnp.clip(jnp.floor(sy + 0.5), 0, H2 - 1).astype(jnp.int32)
        return inside, ls, jnp.where(inside, yi * W2 + xi, n)

    inside, ls, flat = jax.vmap(landing)(indices)
    # Each source frame's slots, and its last slot for the pixels that land outside.
    flat = flat + (jnp.arange(indices.shape[0], dtype=jnp.int32) * (n + 1))[:, None, None]
    zb = (
        jnp.full(indices.shape[0] * (n + 1), -jnp.inf, d.dtype)
        .at[flat.ravel()]
        .max(jnp.where(inside, ls, -jnp.inf).ravel())
    )
    return inside & (ls >= zb[flat] - jnp.asarray(tolerance, d.dtype))


def multiview_photometric_terms(
    label: Float[ArrayLike, "H W"],
    reference: Float[ArrayLike, "H W 3"],
    sources: Float[ArrayLike, "S H2 W2 3"],
    cameras: MultiViewCameras,
    config: LossConfig = _DEFAULT_LOSS,
) -> dict[str, Array]:
    """The terms of eq 7.16 for a reference label map and S posed source views.

    Each source view is warped onto the reference through the depth ``scale / label``
    (`warp_by_depth`); per-view masks (`multiview_occlusion_mask`, no gradient) times the
    warp's in-image mask select the pixels that view sees.

    Args:
        label: ``(H, W)`` reference label map.
        reference: ``(H, W, 3)`` reference view in [0, 1].
        sources: ``(S, H2, W2, 3)`` source views.
        cameras: `MultiViewCameras` with S sources.
        config: `LossConfig`.

    Returns:
        Dict of scalars ``photometric``, ``ssim``, ``smooth``, ``error_gradient`` and the
        maps ``error`` ``(H, W)`` and ``mask_count`` ``(H, W)``, as `photometric_terms`.

    Raises:
        ValueError: on mismatched shapes.

    References:
        Thesis eqs 7.15–7.16, Sec. 7.2.2.
    """
    d = jnp.asarray(label)
    ref = jnp.asarray(reference, d.dtype)
    srcs = jnp.asarray(sources, d.dtype)
    if d.ndim != 2 or ref.shape != (*d.shape, 3):
        raise ValueError(
            f"label must be (H, W) and reference (H, W, 3); got {d.shape} and {ref.shape}"
        )
    S = cameras.k_source.shape[0]
    if srcs.ndim != 4 or srcs.shape[0] != S or srcs.shape[-1] != 3:
        raise ValueError(f"sources must have shape ({S}, H2, W2, 3); got {tuple(srcs.shape)}")
    depth = cameras.depth(d)
    visible = _multiview_occlusion_masks(
        d, cameras, jnp.arange(S, dtype=jnp.int32), srcs.shape[1:3], config.occlusion_tolerance
    ).astype(d.dtype)

    def per_view(view, i, m):
        warped, inside = warp_by_depth(
            view,
            depth,
            cameras.k_reference,
            cameras.k_source[i],
            cameras.rotation[i],
            cameras.translation[i],
        )
        return masked_view_errors(ref, warped, inside * m)

    return combine_view_errors(*jax.vmap(per_view)(srcs, jnp.arange(S), visible), d, ref, config)


def multiview_loss(
    label: Float[ArrayLike, "H W"],
    reference: Float[ArrayLike, "H W 3"],
    sources: Float[ArrayLike, "S H2 W2 3"],
    cameras: MultiViewCameras,
    config: LossConfig = _DEFAULT_LOSS,
) -> Array:
    """Eq 7.16 for posed views: ``mean(E) + w_ssim E_SSIM + w_s E_S - w_g mean|∇E|``.

    Args and references: see `multiview_photometric_terms`.
    """
    return weighted_terms(
        multiview_photometric_terms(label, reference, sources, cameras, config), config
    )


@eqx.filter_jit
def _mv_step(params, states, block, lr, x0, valid, reference, sources, cameras, model, loss):
    """One Adam step of `optimize_multiview` on ``BLOCKS[block]`` (traced; -1: evaluate).

    Only the model and loss configs are arguments (not the schedule), so every schedule
    shares one compilation.
    """

    def loss_fn(p):
        pred = predict(p, model, valid=valid, x0=x0)
        return multiview_loss(pred.disparity, reference, sources, cameras, loss), pred

    (loss, pred), grads = jax.value_and_grad(loss_fn, has_aux=True)(params)
    new_params, new_states = adam_block_update(params, grads, states, block, lr, jnp.isfinite(loss))
    info = {"loss": loss, "solver_iterations": pred.solve.iterations}
    return new_params, new_states, pred.disparity, info


def optimize_multiview(
    params: DiffParams,
    reference: Float[ArrayLike, "H W 3"],
    sources: Float[ArrayLike, "S H2 W2 3"],
    cameras: MultiViewCameras,
    config: OptimizeConfig = _DEFAULT_OPTIMIZE,
    *,
    valid: Bool[ArrayLike, " N"] | None = None,
    x0: Float[ArrayLike, "H W"] | None = None,
    callback: Callable[[int, dict], None] | None = None,
) -> tuple[DiffParams, dict[str, np.ndarray]]:
    """Block-coordinate Adam on the points and smoothness against posed source views.

        The schedule is `OptimizeConfig.schedule` (each block of ``config.blocks`` in turn for
        ``config.iterations`` steps, ``config.passes`` times, a fresh Adam state per turn); the
        loss is `multiview_loss` of the diffused label map (`predict`). One jitted step serves
        every block and every schedule (the block index is traced); the solve is warm-started. With
    ``passes = 0`` it only evaluates: ``history["label"]`` is the diffusion of the points.

        Args:
            params: initial `DiffParams` (labels ``scale / depth``, see `MultiViewCameras`).
            reference: ``(H, W, 3)`` reference view in [0, 1].
            sources: ``(S, H2, W2, 3)`` source views in [0, 1].
            cameras: `MultiViewCameras` with S sources.
            config: `OptimizeConfig` (its ``model`` and ``loss`` are used).
            valid: ``(N,)`` bool point mask (default all).
            x0: optional ``(H, W)`` warm start of the first solve (a label map).
            callback: called as ``callback(step, info)`` after every step.

        Returns:
            ``(params, history)``: the optimised `DiffParams`; ``history`` holds per-step arrays
            ``loss``, ``pass``, ``block``, ``solver_iterations``, ``seconds`` and ``label``, the
            final ``(H, W)`` diffused label map.

        Raises:
            ValueError: on mismatched shapes.

        References:
            Thesis Sec. 7.1.5 (Adam, one parameter block at a time), Sec. 7.2.2 (turns of 25
            iterations repeated 5 times for multi-view stereo).
    """
    ref = jnp.asarray(reference, jnp.float32)
    srcs = jnp.asarray(sources, jnp.float32)
    if ref.ndim != 3 or ref.shape[-1] != 3:
        raise ValueError(f"reference must have shape (H, W, 3); got {tuple(ref.shape)}")
    if params.shape != ref.shape[:2]:
        raise ValueError(f"params.Q has shape {params.shape}; the reference is {ref.shape[:2]}")
    S = cameras.k_source.shape[0]
    if srcs.ndim != 4 or srcs.shape[0] != S or srcs.shape[-1] != 3:
        raise ValueError(f"sources must have shape ({S}, H2, W2, 3); got {tuple(srcs.shape)}")
    valid = jnp.ones(params.label.shape, bool) if valid is None else jnp.asarray(valid, bool)
    if valid.shape != params.label.shape:
        raise ValueError(f"valid must have shape {params.label.shape}; got {valid.shape}")
    x0 = jnp.zeros(params.shape, params.label.dtype) if x0 is None else jnp.asarray(x0)
    args = (ref, srcs, cameras, config.model, config.loss)
    hist: dict[str, list] = {
        k: [] for k in ("loss", "pass", "block", "solver_iterations", "seconds")
    }
    states = adam_reset(params)
    step = 0
    for k, block, lr in config.schedule():
        b = BLOCKS.index(block)
        states = adam_reset(params, states, block)
        bi = jnp.asarray(b, jnp.int32)
        for _ in range(config.iterations):
            t0 = time.perf_counter()
            params, states, x0, info = _mv_step(params, states, bi, lr, x0, valid, *args)
            info = {name: float(v) for name, v in info.items()}
            info.update(seconds=time.perf_counter() - t0, block=b)
            info["pass"] = k
            for name in hist:
                hist[name].append(info[name])
            if callback is not None:
                callback(step, info)
            step += 1
    none = jnp.asarray(-1, jnp.int32)
    _, _, final, _ = _mv_step(params, states, none, jnp.zeros(()), x0, valid, *args)
    history = {name: np.asarray(v) for name, v in hist.items()}
    history["label"] = np.asarray(final)
    return params, history
