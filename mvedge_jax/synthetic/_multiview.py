"""A synthetic unstructured multi-view scene: textured rectangles seen by pinhole cameras on an
arc, with exact depth for every view and a COLMAP sparse model of points on the surfaces.

World coordinates follow COLMAP's camera convention (``x`` right, ``y`` down, ``z`` forward);
image pixel centres sit at integers (this project's convention; the COLMAP model written by
`write_multiview_scene` adds COLMAP's 0.5). A pixel's ray ``C + s Rᵀ K⁻¹ (x, y, 1)`` meets the
nearest rectangle at ``s``, which is also the camera-space depth ``z`` of the hit (the ray's
camera-space direction has ``z = 1``). Colours are averaged over ``supersample²`` sub-pixel
rays in linear light and encoded as sRGB (anti-aliased texture and occlusion edges, as a
camera integrates light over its pixel); depth is that of the pixel-centre ray (exact).

References:
    Thesis Sec. 7.2.2 (unstructured five-camera scenes, sparse COLMAP points as input).
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from ..io import (
    ColmapCamera,
    ColmapImage,
    ColmapModel,
    ColmapPoints,
    rotmat_to_qvec,
    write_colmap_binary,
    write_colmap_text,
    write_pfm,
    write_png,
)
from ..lightfield import linear_to_srgb, srgb_to_linear

_N_WAVES = 5


@dataclasses.dataclass(frozen=True)
class Rectangle:
    """A textured rectangle ``origin + u edge_u + v edge_v``, ``u, v`` in [0, 1].

    Attributes:
        origin: ``(3,)`` world position of the corner ``u = v = 0``.
        edge_u, edge_v: ``(3,)`` orthogonal edge vectors (world units).
        base: ``(3,)`` RGB base colour in [0, 1].
        waves: ``(_N_WAVES, 6)`` rows ``(ku, kv, phase, amp_r, amp_g, amp_b)``: smooth colour
            variation ``Σ amp sin(ku a + kv b + phase)`` in the rectangle's metric coordinates
            ``(a, b) = (u |edge_u|, v |edge_v|)`` (radians per world unit).
        stripes: ``(ku, kv, phase, threshold)``: hard-edged stripes where
            ``sin(ku a + kv b + phase) > threshold``.
        stripe_colour: ``(3,)`` RGB added on the stripes.
    """

    origin: np.ndarray
    edge_u: np.ndarray
    edge_v: np.ndarray
    base: np.ndarray
    waves: np.ndarray
    stripes: np.ndarray
    stripe_colour: np.ndarray

    def colour(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``(..., 3)`` RGB in [0, 1] at metric coordinates ``(a, b)``."""
        out = np.broadcast_to(self.base, (*a.shape, 3)).copy()
        for ku, kv, ph, r, g, bl in self.waves:
            out += np.sin(ku * a + kv * b + ph)[..., None] * np.array([r, g, bl])
        ku, kv, ph, th = self.stripes
        on = np.sin(ku * a + kv * b + ph) > th
        out += on[..., None] * self.stripe_colour
        return np.clip(out, 0.0, 1.0)


def _rectangle(rng, origin, edge_u, edge_v) -> Rectangle:
    waves = np.concatenate(
        [
            rng.uniform(-9.0, 9.0, (_N_WAVES, 2)),
            rng.uniform(0, 2 * np.pi, (_N_WAVES, 1)),
            rng.uniform(-0.08, 0.08, (_N_WAVES, 3)),
        ],
        axis=1,
    )
    angle = rng.uniform(0, np.pi)
    k = rng.uniform(2.0, 5.0)
    return Rectangle(
        origin=np.asarray(origin, np.float64),
        edge_u=np.asarray(edge_u, np.float64),
        edge_v=np.asarray(edge_v, np.float64),
        base=rng.uniform(0.25, 0.75, 3),
        waves=waves,
        stripes=np.array([k * np.cos(angle), k * np.sin(angle), rng.uniform(0, 6.3), 0.6]),
        stripe_colour=rng.uniform(-0.3, 0.3, 3),
    )


def _box(rng, lo, hi) -> list[Rectangle]:
    """The six faces of an axis-aligned box ``lo``–``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dx, dy, dz = np.diag(hi - lo)
    faces = [
        (lo, dx, dy),
        (lo + dz, dx, dy),
        (lo, dy, dz),
        (lo + dx, dy, dz),
        (lo, dx, dz),
        (lo + dy, dx, dz),
    ]
    return [_rectangle(rng, o, u, v) for o, u, v in faces]


def default_rectangles(seed: int = 0) -> list[Rectangle]:
    """The default scene: a back wall (z = 12), a floor (y = 2), a box standing on the floor
    (z 6–8) and a panel turned 35° about the vertical (z ≈ 4.8–6), all textured."""
    rng = np.random.default_rng(seed)
    rects = [
        _rectangle(rng, (-14.0, -10.0, 12.0), (28.0, 0, 0), (0, 12.0, 0)),  # wall
        _rectangle(rng, (-14.0, 2.0, 1.0), (28.0, 0, 0), (0, 0, 11.0)),  # floor
    ]
    rects += _box(rng, (-2.4, 0.2, 6.0), (-0.4, 2.0, 8.0))
    a = np.deg2rad(35.0)
    rects.append(
        _rectangle(rng, (0.5, -1.8, 4.8), 2.0 * np.array([np.cos(a), 0, np.sin(a)]), (0, 2.8, 0))
    )
    return rects


def look_at(centre, target) -> np.ndarray:
    """``(3, 3)`` world-to-camera rotation of a camera at ``centre`` looking at ``target``
    (image ``y`` pointing down, towards world ``+y``)."""
    f = np.asarray(target, float) - np.asarray(centre, float)
    f /= np.linalg.norm(f)
    r = np.cross(np.array([0.0, 1.0, 0.0]), f)  # y down: right = down × forward
    r /= np.linalg.norm(r)
    d = np.cross(f, r)
    return np.stack([r, d, f])


def trace(
    rects: list[Rectangle], centre: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Nearest hit of rays ``centre + s directions`` with the rectangles.

    Args:
        rects: the rectangles.
        centre: ``(3,)`` ray origin.
        directions: ``(..., 3)`` ray directions (not normalised).

    Returns:
        ``(s, index, a, b)``, each ``(...)``: ray parameter of the hit (``inf`` for none),
        rectangle index (-1 for none) and the hit's metric coordinates on that rectangle.
    """
    shape = directions.shape[:-1]
    d = directions.reshape(-1, 3)
    best = np.full(d.shape[0], np.inf)
    idx = np.full(d.shape[0], -1)
    a_out, b_out = np.zeros(d.shape[0]), np.zeros(d.shape[0])
    for k, r in enumerate(rects):
        n = np.cross(r.edge_u, r.edge_v)
        denom = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((r.origin - centre) @ n) / denom
        P = centre + s[:, None] * d - r.origin
        lu, lv = np.linalg.norm(r.edge_u), np.linalg.norm(r.edge_v)
        a = P @ r.edge_u / lu
        b = P @ r.edge_v / lv
        hit = (np.abs(denom) > 1e-12) & (s > 1e-6) & (a >= 0) & (a <= lu) & (b >= 0) & (b <= lv)
        better = hit & (s < best)
        best = np.where(better, s, best)
        idx = np.where(better, k, idx)
        a_out = np.where(better, a, a_out)
        b_out = np.where(better, b, b_out)
    return best.reshape(shape), idx.reshape(shape), a_out.reshape(shape), b_out.reshape(shape)


def _shade(rects, idx, a, b) -> np.ndarray:
    out = np.zeros((*idx.shape, 3))
    for k, r in enumerate(rects):
        m = idx == k
        if m.any():
            out[m] = r.colour(a[m], b[m])
    return out


def render_view(
    rects: list[Rectangle],
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    size: tuple[int, int],
    *,
    supersample: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """Ray-trace one pinhole view.

    Args:
        rects: the scene's rectangles.
        K: ``(3, 3)`` intrinsics, pixel centres at integers.
        R, t: world-to-camera rotation ``(3, 3)`` and translation ``(3,)``.
        size: ``(H, W)`` in pixels.
        supersample: sub-pixel rays per axis for the colour.

    Returns:
        ``(image (H, W, 3) float32 in [0, 1], depth (H, W) float64)``: colour and the
        camera-space depth ``z`` of the pixel-centre ray (``inf`` where no surface is hit).
    """
    H, W = size
    C = -R.T @ t
    Kinv_T = np.linalg.inv(K).T
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([xs, ys, np.ones_like(xs)], -1) @ Kinv_T @ R
    depth, _, _, _ = trace(rects, C, rays)
    ss = int(supersample)
    offs = (np.arange(ss) + 0.5) / ss - 0.5
    col = np.zeros((H, W, 3))
    for oy in offs:
        for ox in offs:
            r = np.stack([xs + ox, ys + oy, np.ones_like(xs)], -1) @ Kinv_T @ R
            _, idx, a, b = trace(rects, C, r)
            col += np.asarray(srgb_to_linear(_shade(rects, idx, a, b)))
    return np.asarray(linear_to_srgb(col / ss**2), np.float32), depth


@dataclasses.dataclass(frozen=True)
class MultiViewScene:
    """Rendered views, exact depth and a COLMAP model of a synthetic multi-view scene.

    Attributes:
        images: ``(V, H, W, 3)`` float32 RGB in [0, 1].
        depth: ``(V, H, W)`` float64 camera-space depth of every pixel (world units).
        model: `ColmapModel` with one PINHOLE camera, the ``V`` posed images (names
            ``view_00.png``, ...) with their observations, and the sparse 3-D points.
        rectangles: the scene's `Rectangle` list.
    """

    images: np.ndarray
    depth: np.ndarray
    model: ColmapModel
    rectangles: tuple

    @property
    def names(self) -> list[str]:
        """Image names in view order."""
        return [self.model.images[i + 1].name for i in range(len(self.model.images))]


def make_multiview_scene(
    n_views: int = 6,
    size: tuple[int, int] = (96, 128),
    *,
    focal: float | None = None,
    arc_degrees: float = 24.0,
    radius: float = 7.5,
    n_points: int = 800,
    supersample: int = 3,
    point_noise: float = 0.0,
    seed: int = 0,
) -> MultiViewScene:
    """Render `default_rectangles` from ``n_views`` cameras on a horizontal arc.

    The cameras sit on an arc of radius ``radius`` around the point ``(0, 0.5, 7.5)`` at
    angles evenly spread over ``arc_degrees``, alternately 0.15 above and below the arc,
    all looking at that point. ``n_points`` points are drawn uniformly (by area) on the
    rectangles; those seen by at least two views (exact ray visibility) become the sparse
    model, with exact observations (COLMAP pixel coordinates) in every view that sees them.

    Args:
        n_views: number of views (>= 2).
        size: ``(H, W)`` in pixels.
        focal: focal length in pixels (default ``0.8 W``).
        arc_degrees: angle spanned by the cameras.
        radius: distance of the cameras from the look-at point (world units).
        n_points: candidate sparse points.
        supersample: sub-pixel rays per axis for the colours.
        point_noise: standard deviation of Gaussian noise added to the sparse points' world
            positions after the observations are made (a triangulation error), world units.
        seed: seed of the textures, points and noise.

    Returns:
        A `MultiViewScene`.

    Raises:
        ValueError: for fewer than two views, a bad size or no point seen twice.

    References:
        Thesis Sec. 7.2.2 (five unstructured views, a few hundred sparse points).
    """
    if n_views < 2:
        raise ValueError(f"n_views must be >= 2; got {n_views}")
    H, W = (int(s) for s in size)
    if H < 8 or W < 8:
        raise ValueError(f"size must be at least 8x8 pixels; got {size}")
    f = 0.8 * W if focal is None else float(focal)
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])
    rects = default_rectangles(seed)
    target = np.array([0.0, 0.5, 7.5])
    poses = []
    for i, ang in enumerate(np.deg2rad(np.linspace(-arc_degrees / 2, arc_degrees / 2, n_views))):
        C = target + radius * np.array([np.sin(ang), 0.0, -np.cos(ang)])
        C[1] += 0.15 * (-1) ** i
        R = look_at(C, target)
        poses.append((R, -R @ C))
    views = [render_view(rects, K, R, t, (H, W), supersample=supersample) for R, t in poses]
    images = np.stack([v[0] for v in views])
    depth = np.stack([v[1] for v in views])

    rng = np.random.default_rng(seed + 1)
    areas = np.array([np.linalg.norm(np.cross(r.edge_u, r.edge_v)) for r in rects])
    which = rng.choice(len(rects), n_points, p=areas / areas.sum())
    uv = rng.uniform(0.02, 0.98, (n_points, 2))
    xyz = np.stack(
        [
            rects[k].origin + u * rects[k].edge_u + v * rects[k].edge_v
            for k, (u, v) in zip(which, uv, strict=True)
        ]
    )
    obs: list[list] = [[] for _ in poses]
    tracks: list[list] = [[] for _ in range(n_points)]
    for i, (R, t) in enumerate(poses):
        cam = xyz @ R.T + t
        z = cam[:, 2]
        pix = (cam / z[:, None]) @ K.T
        inside = (z > 0) & (pix[:, 0] > -0.5) & (pix[:, 0] < W - 0.5)
        inside &= (pix[:, 1] > -0.5) & (pix[:, 1] < H - 0.5)
        s, _, _, _ = trace(rects, -R.T @ t, xyz - (-R.T @ t))  # hit at s = 1 when visible
        seen = inside & (np.abs(s - 1.0) < 1e-6)
        for p in np.flatnonzero(seen):
            tracks[p].append((i + 1, len(obs[i])))
            obs[i].append((pix[p, 0] + 0.5, pix[p, 1] + 0.5, p + 1))
    keep = np.array([len(tr) >= 2 for tr in tracks])
    if not keep.any():
        raise ValueError("no sparse point is seen by two views; widen the scene or add points")
    noisy = xyz + rng.normal(0.0, point_noise, xyz.shape) if point_noise > 0 else xyz
    colours = [
        rects[k].colour(
            np.array([u * np.linalg.norm(rects[k].edge_u)]),
            np.array([v * np.linalg.norm(rects[k].edge_v)]),
        )[0]
        for k, (u, v) in zip(which, uv, strict=True)
    ]
    rgb = np.round(np.array(colours) * 255).astype(np.uint8)
    kept = np.flatnonzero(keep)
    points = ColmapPoints(
        ids=(kept + 1).astype(np.int64),
        xyz=noisy[kept],
        rgb=rgb[kept],
        error=np.zeros(kept.size),
        track_length=np.array([len(tracks[p]) for p in kept], np.int64),
        tracks=tuple(np.array(tracks[p], np.int64).reshape(-1, 2) for p in kept),
    )
    camera = ColmapCamera(1, "PINHOLE", W, H, np.array([f, f, K[0, 2] + 0.5, K[1, 2] + 0.5]))
    cimages = {}
    for i, (R, t) in enumerate(poses):
        o = np.array(obs[i], np.float64).reshape(-1, 3)
        ids = o[:, 2].astype(np.int64)
        ids = np.where(keep[ids - 1], ids, -1)  # observations of dropped points: no 3-D point
        cimages[i + 1] = ColmapImage(
            i + 1, rotmat_to_qvec(R), t.copy(), 1, f"view_{i:02d}.png", o[:, :2].copy(), ids
        )
    model = ColmapModel(cameras={1: camera}, images=cimages, points3d=points)
    return MultiViewScene(images=images, depth=depth, model=model, rectangles=tuple(rects))


def write_multiview_scene(
    scene: MultiViewScene, folder: str | os.PathLike, *, binary: bool = False
) -> None:
    """Write a scene as a COLMAP project: ``images/<name>``, the model in ``sparse/``
    (text or binary) and the exact depth of each view in ``depth_gt/<stem>.pfm``.

    Args:
        scene: a `MultiViewScene`.
        folder: destination (created if needed).
        binary: write ``sparse/`` as ``.bin`` files instead of ``.txt``.
    """
    folder = os.fspath(folder)
    for sub in ("images", "sparse", "depth_gt"):
        os.makedirs(os.path.join(folder, sub), exist_ok=True)
    for i, name in enumerate(scene.names):
        write_png(os.path.join(folder, "images", name), scene.images[i])
        stem = os.path.splitext(name)[0]
        write_pfm(
            os.path.join(folder, "depth_gt", stem + ".pfm"), scene.depth[i].astype(np.float32)
        )
    writer = write_colmap_binary if binary else write_colmap_text
    writer(scene.model, os.path.join(folder, "sparse"))
