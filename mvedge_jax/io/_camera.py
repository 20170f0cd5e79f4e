"""The camera of an HCI 4D scene (``parameters.cfg``): disparity ↔ metric depth, point clouds."""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from ._layout import read_hci_parameters


@dataclasses.dataclass(frozen=True)
class HciCamera:
    """The intrinsics and extrinsics of an HCI 4D light field that relate disparity to depth.

    Attributes:
        focal_length_mm: focal length (mm).
        sensor_size_mm: sensor size along the longer image side (mm).
        baseline_mm: distance between neighbouring views (mm).
        focus_distance_m: distance of the zero-disparity plane (m).
        image_size: ``(H, W)`` of the views in the files (pixels).

    References:
        Honauer et al., ACCV 2016; the benchmark toolkit's ``parameters.cfg`` fields.
    """

    focal_length_mm: float
    sensor_size_mm: float
    baseline_mm: float
    focus_distance_m: float
    image_size: tuple[int, int]


_FIELDS = {
    "focal_length_mm": ("intrinsics", "focal_length_mm"),
    "sensor_size_mm": ("intrinsics", "sensor_size_mm"),
    "baseline_mm": ("extrinsics", "baseline_mm"),
    "focus_distance_m": ("extrinsics", "focus_distance_m"),
    "width": ("intrinsics", "image_resolution_x_px"),
    "height": ("intrinsics", "image_resolution_y_px"),
}


def read_hci_camera(folder: str | os.PathLike) -> HciCamera | None:
    """The camera of the HCI 4D scene in ``folder``, or ``None`` without ``parameters.cfg``.

    Args:
        folder: scene folder.

    Returns:
        The `HciCamera`, or ``None`` when the folder has no ``parameters.cfg``.

    Raises:
        ValueError: if ``parameters.cfg`` lacks a camera field or one is not a positive number.
    """
    path = os.path.join(os.fspath(folder), "parameters.cfg")
    if not os.path.isfile(path):
        return None
    params = read_hci_parameters(path)
    vals = {}
    for name, (section, key) in _FIELDS.items():
        text = params.get(section, {}).get(key)
        if text is None:
            raise ValueError(f"{path}: [{section}] {key} is missing (needed for metric depth)")
        try:
            vals[name] = float(text)
        except ValueError:
            raise ValueError(f"{path}: [{section}] {key} = {text!r} is not a number") from None
        if not vals[name] > 0:
            raise ValueError(f"{path}: [{section}] {key} = {text!r} must be positive")
    return HciCamera(
        focal_length_mm=vals["focal_length_mm"],
        sensor_size_mm=vals["sensor_size_mm"],
        baseline_mm=vals["baseline_mm"],
        focus_distance_m=vals["focus_distance_m"],
        image_size=(int(vals["height"]), int(vals["width"])),
    )


def disparity_to_depth(disparity: np.ndarray, camera: HciCamera) -> np.ndarray:
    """Metric depth (m) from disparity (pixels per view step), the HCI toolkit's relation.

    ``depth = 1 / (1000 · sensor · d / (baseline · focal · max(H, W)) + 1 / focus)``, with
    ``(H, W)`` the size of the disparity map itself: a map of a light field loaded with
    ``scale`` has both its disparity and its size scaled, so the depth does not change.

    Args:
        disparity: ``(H, W)`` disparity (pixels per view step).
        camera: the scene's `HciCamera`.

    Returns:
        ``(H, W)`` float32 depth in metres; NaN where the disparity is not finite or lies at
        or beyond infinity (the denominator is not positive).

    Raises:
        ValueError: if ``disparity`` is not 2-D.

    References:
        HCI 4D benchmark toolkit, ``BaseScene.disp2depth`` (Honauer et al., ACCV 2016).
    """
    d = np.asarray(disparity, np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity_to_depth expects (H, W); got shape {d.shape}")
    q = camera.baseline_mm * camera.focal_length_mm * max(d.shape)
    inv = 1000.0 * camera.sensor_size_mm * d / q + 1.0 / camera.focus_distance_m
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(np.isfinite(inv) & (inv > 0), 1.0 / inv, np.nan)
    return depth.astype(np.float32)


def depth_to_points(depth: np.ndarray, camera: HciCamera) -> np.ndarray:
    """3-D points of a depth map, the HCI toolkit's point-cloud convention.

    Millimetres; ``x`` to the right, ``y`` up, ``z = -depth`` (the camera looks along -z);
    pixel ``(row, col)`` maps to ``x = (col / (W - 1) - 0.5) · sensor · depth / focal`` and
    ``y = -(row / (H - 1) - 0.5) · sensor · depth / focal``.

    Args:
        depth: ``(H, W)`` depth in metres (NaN: no point).
        camera: the scene's `HciCamera`.

    Returns:
        ``(H, W, 3)`` float32 points in millimetres (NaN where ``depth`` is NaN).

    Raises:
        ValueError: if ``depth`` is not 2-D.

    References:
        HCI 4D benchmark toolkit, ``point_cloud.convert`` (Honauer et al., ACCV 2016).
    """
    z = np.asarray(depth, np.float64) * 1000.0
    if z.ndim != 2:
        raise ValueError(f"depth_to_points expects (H, W); got shape {z.shape}")
    H, W = z.shape
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    k = camera.sensor_size_mm * z / camera.focal_length_mm
    x = (cols / max(W - 1, 1) - 0.5) * k
    y = -(rows / max(H - 1, 1) - 0.5) * k
    return np.stack([x, y, -z], axis=-1).astype(np.float32)


def write_ply(path: str | os.PathLike, points: np.ndarray, colours: np.ndarray) -> int:
    """Write a coloured point cloud as binary PLY (with ``plyfile``), skipping NaN points.

    Args:
        path: destination ``.ply`` file; its folder must exist.
        points: ``(..., 3)`` float coordinates.
        colours: ``(..., 3)`` uint8 RGB, or float RGB in [0, 1].

    Returns:
        The number of points written.

    Raises:
        ValueError: if the shapes do not match or are not ``(..., 3)``.
    """
    from plyfile import PlyData, PlyElement

    p = np.asarray(points, np.float32).reshape(-1, 3) if np.ndim(points) >= 2 else None
    c = np.asarray(colours)
    if p is None or np.shape(points)[-1] != 3 or c.shape != np.shape(points):
        raise ValueError(
            f"write_ply expects points and colours of one shape (..., 3); got "
            f"{np.shape(points)} and {c.shape}"
        )
    if np.issubdtype(c.dtype, np.floating):
        c = np.round(np.clip(c, 0.0, 1.0) * 255.0)
    c = c.astype(np.uint8).reshape(-1, 3)
    keep = np.isfinite(p).all(axis=1)
    vertex = np.empty(
        int(keep.sum()),
        dtype=[
            ("x", "f4"),
            ("y", "f4"),
            ("z", "f4"),
            ("red", "u1"),
            ("green", "u1"),
            ("blue", "u1"),
        ],
    )
    for i, name in enumerate(("x", "y", "z")):
        vertex[name] = p[keep, i]
    for i, name in enumerate(("red", "green", "blue")):
        vertex[name] = c[keep, i]
    PlyData([PlyElement.describe(vertex, "vertex")], text=False).write(os.fspath(path))
    return int(keep.sum())
