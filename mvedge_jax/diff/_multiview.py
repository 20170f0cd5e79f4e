"""Unstructured multi-view input (thesis Sec. 7.2.2): sparse depth points and depth warping.

Pinhole cameras from a COLMAP model (`mvedge_jax.io.read_colmap_text`). Pixel coordinates
follow this project's convention (pixel centres at integers): COLMAP's ``(u, v)`` minus 0.5.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..io._colmap import ColmapCamera, ColmapImage, ColmapModel

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
    Kr, Ks = jnp.asarray(k_reference, dtype), jnp.asarray(k_source, dtype)
    R, t = jnp.asarray(rotation, dtype), jnp.asarray(translation, dtype)
    H, W = d.shape
    H2, W2 = img.shape[:2]
    ys, xs = jnp.meshgrid(jnp.arange(H, dtype=dtype), jnp.arange(W, dtype=dtype), indexing="ij")
    pix = jnp.stack([xs, ys, jnp.ones_like(xs)], -1)
    rays = pix @ jnp.linalg.inv(Kr).T
    X = rays * d[..., None]
    Xs = X @ R.T + t
    z = Xs[..., 2]
    zs = jnp.where(jnp.abs(z) > 1e-9, z, 1e-9)
    proj = (Xs / zs[..., None]) @ Ks.T
    sx, sy = proj[..., 0], proj[..., 1]
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


def intrinsics(camera: ColmapCamera) -> np.ndarray:
    """``(3, 3)`` pinhole K of a COLMAP camera in this project's pixel convention."""
    K = camera.calibration_matrix()
    K[0, 2] -= camera.pixel_offset
    K[1, 2] -= camera.pixel_offset
    return K
