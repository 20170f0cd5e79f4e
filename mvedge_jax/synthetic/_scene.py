"""Procedural light fields of textured planar surfaces with exact per-view ground truth.

A scene is a list of surfaces described in centre-view pixel coordinates ``(X, Y)`` measured
from the image centre ``((W - 1) / 2, (H - 1) / 2)``:

* a planar disparity ``d(X, Y) = a + b X + c Y`` (pixels per view step; fronto-parallel when
  ``b = c = 0``),
* a support: the whole plane, a (rotated) rectangle or a disc, in centre-view coordinates,
* a texture: a continuous function of ``(X, Y)`` (base colour + smooth random colour noise
  + hard-edged stripes or a checkerboard).

A pixel ``(X', Y')`` of the view at offset ``(dr, dc)`` sees the point of a surface with
``X' = X - dc d(X, Y)``, ``Y' = Y - dr d(X, Y)`` (SPEC §0). For a plane this has the closed
form ``d = (a + b X' + c Y') / (1 - b dc - c dr)``, ``X = X' + dc d``, ``Y = Y' + dr d``.
Among the surfaces whose support contains their point, the largest disparity (the nearest)
is visible. Ground truth is that disparity at the pixel centre (exact, no interpolation);
colours are averaged over ``supersample²`` sub-pixel samples in linear light and encoded as
sRGB (anti-aliasing of both texture edges and occlusion boundaries, as a camera integrates
light over its pixel: textures are sRGB values).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..lightfield import LightField, linear_to_srgb, srgb_to_linear, view_offsets

WHOLE, RECT, DISC = 0, 1, 2
N_MODES = 6  # smooth colour-noise sinusoids per surface
N_SHADE = 2  # view-dependent shading sinusoids per surface


@dataclasses.dataclass(frozen=True)
class Surface:
    """One planar, textured surface of a synthetic scene (centre-view pixel coordinates).

    Attributes:
        plane: ``(a, b, c)``: disparity ``a + b X + c Y``; ``X, Y`` in pixels from the image
            centre, ``a`` in pixels per view step, ``b, c`` per pixel.
        kind: ``WHOLE`` (0, covers everything), ``RECT`` (1) or ``DISC`` (2).
        centre: ``(X, Y)`` of the support centre, pixels from the image centre.
        half_size: ``(half width, half height)`` of a rectangle; the radius of a disc is
            ``half_size[0]``.
        angle: rotation of a rectangle, radians (counter-clockwise in image axes).
        base: RGB base colour in [0, 1].
        noise: ``(N_MODES, 6)`` rows ``(kx, ky, phase, amp_r, amp_g, amp_b)``; wave numbers in
            radians per pixel.
        stripes: ``(k1x, k1y, phase1, thresh1, k2x, k2y, phase2, thresh2)``: pattern
            ``[sin(k1·p + phase1) > thresh1] XOR [sin(k2·p + phase2) > thresh2]`` (a checker
            when ``k2 != 0``; stripes when ``k2 = 0`` and ``sin(phase2) <= thresh2``).
        stripe_colour: RGB added where the pattern is on (may be negative).
        shading: ``(N_SHADE, 5)`` rows ``(kx, ky, phase, amp_dc, amp_dr)``: view-dependent
            shading, a first-order model of a glossy surface. The view at offset
            ``(dr, dc)`` (view steps from the centre) sees its point ``(X, Y)`` brighter by
            ``Σ sin(kx X + ky Y + phase) (amp_dc dc + amp_dr dr)`` in every channel (zero
            in the centre view; the ground truth is unaffected).
    """

    plane: tuple[float, float, float]
    kind: int = WHOLE
    centre: tuple[float, float] = (0.0, 0.0)
    half_size: tuple[float, float] = (0.0, 0.0)
    angle: float = 0.0
    base: tuple[float, float, float] = (0.5, 0.5, 0.5)
    noise: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((N_MODES, 6)))
    stripes: tuple[float, ...] = (0.0, 0.0, -np.pi / 2, 0.0, 0.0, 0.0, -np.pi / 2, 0.0)
    stripe_colour: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shading: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((N_SHADE, 5)))


def _pack(surfaces: list[Surface]) -> dict[str, jax.Array]:
    f = np.float32
    table = np.array(
        [
            np.concatenate(
                [
                    s.base,
                    np.asarray(s.noise, float).reshape(-1),
                    s.stripes,
                    s.stripe_colour,
                    np.asarray(s.shading, float).reshape(-1),
                ]
            )
            for s in surfaces
        ],
        f,
    )
    if table.shape[1] != _N_TEX:
        raise ValueError(f"bad texture parameters: {table.shape[1]} values, expected {_N_TEX}")
    return {
        "plane": jnp.asarray(np.array([s.plane for s in surfaces], f)),
        "kind": jnp.asarray(np.array([s.kind for s in surfaces], np.int32)),
        "centre": jnp.asarray(np.array([s.centre for s in surfaces], f)),
        "half": jnp.asarray(np.array([s.half_size for s in surfaces], f)),
        "angle": jnp.asarray(np.array([s.angle for s in surfaces], f)),
        "texture": jnp.asarray(table),
    }


_N_TEX = 3 + 6 * N_MODES + 8 + 3 + 5 * N_SHADE  # base, noise, stripes + colour, shading


def _geometry(p, xs, ys, dr, dc):
    """Visible surface at view samples ``(xs, ys)`` (centred pixel coords, any shape).

    A loop over the (few) surfaces with running z-test: all element-wise, so XLA fuses it
    (argmax + take_along_axis over a stacked axis was ~4x slower on CPU).

    Returns ``(winner index, disparity, X, Y)`` with ``X, Y`` the centre-view coordinates of
    the visible point (``-inf`` disparity where no surface covers the sample).
    """
    plane, centre, half, kind = p["plane"], p["centre"], p["half"], p["kind"]
    ca, sa = jnp.cos(p["angle"]), jnp.sin(p["angle"])
    best = jnp.full(xs.shape, -jnp.inf, xs.dtype)
    w = jnp.zeros(xs.shape, jnp.int32)
    bx, by = xs, ys
    for k in range(plane.shape[0]):
        a, b, c = plane[k, 0], plane[k, 1], plane[k, 2]
        d = (a + b * xs + c * ys) / (1.0 - b * dc - c * dr)
        X = xs + dc * d
        Y = ys + dr * d
        u = X - centre[k, 0]
        v = Y - centre[k, 1]
        ru = ca[k] * u + sa[k] * v
        rv = -sa[k] * u + ca[k] * v
        in_rect = (jnp.abs(ru) <= half[k, 0]) & (jnp.abs(rv) <= half[k, 1])
        in_disc = u * u + v * v <= half[k, 0] * half[k, 0]
        inside = jnp.where(kind[k] == WHOLE, True, jnp.where(kind[k] == RECT, in_rect, in_disc))
        better = inside & (d > best)
        best = jnp.where(better, d, best)
        w = jnp.where(better, k, w)
        bx = jnp.where(better, X, bx)
        by = jnp.where(better, Y, by)
    return w, best, bx, by


def _sin(x):
    """sin(x) to ~1e-5 by range reduction + odd polynomial (XLA's CPU ``sin`` was ~50x
    slower here and dominated the rendering time)."""
    t = x * (1.0 / (2.0 * np.pi))
    t = t - jnp.floor(t + 0.5)  # [-0.5, 0.5)
    t = jnp.where(t > 0.25, 0.5 - t, jnp.where(t < -0.25, -0.5 - t, t))  # [-0.25, 0.25]
    z = t * (2.0 * np.pi)
    z2 = z * z
    return z * (1 + z2 * (-1 / 6 + z2 * (1 / 120 + z2 * (-1 / 5040 + z2 / 362880))))


def _texture(p, w, X, Y, dr=0.0, dc=0.0):
    """RGB ``(..., 3)`` of surface ``w`` at centre-view coordinates ``(X, Y)``, seen from the
    view at offset ``(dr, dc)`` (broadcast against ``X``; view-dependent shading).

    Per-sample texture parameters are selected with a ``where`` chain over the surfaces
    (element-wise and fused; per-sample gathers were ~4x slower on CPU).
    """
    T = p["texture"]
    R = [jnp.broadcast_to(T[0, j], X.shape) for j in range(_N_TEX)]
    for k in range(1, T.shape[0]):
        sel = w == k
        R = [jnp.where(sel, T[k, j], r) for j, r in enumerate(R)]
    col = R[0:3]
    for m in range(N_MODES):
        o = 3 + 6 * m
        s = _sin(R[o] * X + R[o + 1] * Y + R[o + 2])
        col = [col[i] + s * R[o + 3 + i] for i in range(3)]
    o = 3 + 6 * N_MODES
    on1 = _sin(R[o] * X + R[o + 1] * Y + R[o + 2]) > R[o + 3]
    on2 = _sin(R[o + 4] * X + R[o + 5] * Y + R[o + 6]) > R[o + 7]
    pattern = (on1 ^ on2).astype(X.dtype)
    col = [col[i] + pattern * R[o + 8 + i] for i in range(3)]
    for m in range(N_SHADE):
        q = o + 8 + 3 + 5 * m  # after the stripes and their colour
        shade = _sin(R[q] * X + R[q + 1] * Y + R[q + 2]) * (R[q + 3] * dc + R[q + 4] * dr)
        col = [c + shade for c in col]
    rgb = jnp.stack(col, axis=-1)
    return jnp.clip(rgb, 0.0, 1.0)


@functools.partial(jax.jit, static_argnames=("H", "W", "ss"))
def _render_geometry(p, offsets, *, H: int, W: int, ss: int):
    """GT at pixel centres ``(N, H, W)`` and the visible surface at the ``ss²`` sub-pixel
    samples (winner ``(N, ss², H, W)``, ``X``, ``Y``) of the views at ``offsets (N, 2)``."""
    cy, cx = (H - 1) / 2.0, (W - 1) / 2.0
    ys = jnp.arange(H, dtype=jnp.float32)[:, None] - cy
    xs = jnp.arange(W, dtype=jnp.float32)[None, :] - cx
    sub = (jnp.arange(ss, dtype=jnp.float32) + 0.5) / ss - 0.5
    sy, sx = jnp.meshgrid(sub, sub, indexing="ij")
    xq = jnp.broadcast_to(xs[None] + sx.reshape(-1, 1, 1), (ss * ss, H, W))
    yq = jnp.broadcast_to(ys[None] + sy.reshape(-1, 1, 1), (ss * ss, H, W))

    def one(off):
        dr, dc = off[0], off[1]
        _, gt, _, _ = _geometry(
            p, jnp.broadcast_to(xs, (H, W)), jnp.broadcast_to(ys, (H, W)), dr, dc
        )
        w, _, X, Y = _geometry(p, xq, yq, dr, dc)
        return gt, w, X, Y

    return jax.vmap(one)(offsets)


@jax.jit
def _render_colour(p, w, X, Y, offsets):
    """Mean texture colour over the sub-pixel axis 1, in linear light, encoded as sRGB:
    ``(N, ss², H, W)`` → ``(N, H, W, 3)``, the views at ``offsets (N, 2)``."""
    dr = offsets[:, 0, None, None, None]
    dc = offsets[:, 1, None, None, None]
    return linear_to_srgb(srgb_to_linear(_texture(p, w, X, Y, dr, dc)).mean(axis=1))


def _render(p, offsets, *, H: int, W: int, ss: int, chunk_pixels: int = 1 << 22):
    """Render views at ``offsets (N, 2)``: RGB ``(N, H, W, 3)`` and GT ``(N, H, W)``.

    Geometry and texture are two separately compiled functions on purpose: fused into one
    XLA CPU kernel, the geometry was recomputed for every use of its outputs in the texture
    (~20x slower). Views are processed in chunks of about ``chunk_pixels`` samples.
    """
    n = offsets.shape[0]
    step = max(1, min(n, chunk_pixels // (H * W * ss * ss)))
    n_chunks = -(-n // step)
    step = -(-n // n_chunks)  # equal chunks: one compilation
    padded = jnp.concatenate([offsets, jnp.repeat(offsets[-1:], n_chunks * step - n, axis=0)])
    rgbs, gts = [], []
    for i in range(n_chunks):
        chunk = padded[i * step : (i + 1) * step]
        gt, w, X, Y = _render_geometry(p, chunk, H=H, W=W, ss=ss)
        rgbs.append(_render_colour(p, w, X, Y, chunk))
        gts.append(gt)
    return jnp.concatenate(rgbs)[:n], jnp.concatenate(gts)[:n]


def _check_scene(surfaces, grid, size) -> tuple[int, int, int, int]:
    """``(U, V, H, W)`` of a scene to render; ValueError on an empty scene, bad grid or size."""
    U, V = (int(g) for g in grid)
    H, W = (int(s) for s in size)
    if not surfaces:
        raise ValueError("a scene needs at least one surface")
    if U < 3 or V < 3:
        raise ValueError(f"grid must be at least (3, 3); got {grid}")
    if H < 2 or W < 2:
        raise ValueError(f"size must be at least (2, 2); got {size}")
    return U, V, H, W


@functools.partial(jax.jit, static_argnames=("H", "W"))
def _render_ids(p, offsets, *, H: int, W: int):
    """Index of the visible surface at the pixel centres of the views at ``offsets (N, 2)``."""
    cy, cx = (H - 1) / 2.0, (W - 1) / 2.0
    ys = jnp.broadcast_to(jnp.arange(H, dtype=jnp.float32)[:, None] - cy, (H, W))
    xs = jnp.broadcast_to(jnp.arange(W, dtype=jnp.float32)[None, :] - cx, (H, W))
    return jax.vmap(lambda o: _geometry(p, xs, ys, o[0], o[1])[0])(offsets)


def render_object_ids(
    surfaces: list[Surface],
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
) -> jax.Array:
    """Per-view object-ID ground truth: the index of the surface visible at each pixel centre.

    The same z-test as the ground-truth disparity of `render_surfaces` (the nearest surface
    whose support contains its point wins), so IDs and ``gt_disparity`` agree pixel for pixel.
    Each surface is one object (index into ``surfaces``).

    Args:
        surfaces: the scene, as passed to `render_surfaces`.
        grid: ``(U, V)`` angular resolution (each >= 3).
        size: ``(H, W)`` view size in pixels.

    Returns:
        ``(U, V, H, W)`` int32 object IDs in ``[0, len(surfaces))``.

    Raises:
        ValueError: on an empty scene, a bad grid or size.
    """
    U, V, H, W = _check_scene(surfaces, grid, size)
    dr, dc = view_offsets(U, V)
    offsets = jnp.stack([dr.ravel(), dc.ravel()], axis=-1)
    ids = _render_ids(_pack(surfaces), offsets, H=H, W=W)
    return ids.reshape(U, V, H, W).astype(jnp.int32)


def render_surfaces(
    surfaces: list[Surface],
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
    supersample: int = 2,
    name: str = "synthetic",
    disparity_range: tuple[float, float] | None = None,
) -> LightField:
    """Render a light field of planar surfaces with exact ground truth in every view.

    Args:
        surfaces: the scene; at least one surface, and every pixel of every view must be
            covered (include a ``WHOLE`` background).
        grid: ``(U, V)`` angular resolution (each >= 3).
        size: ``(H, W)`` view size in pixels.
        supersample: colour samples per pixel along each axis (anti-aliasing), >= 1. An
            odd value makes the pixel centre, where the ground truth is taken, one of the
            samples; with an even value the pixels a straight occlusion boundary halves mix
            the two surfaces equally and their ground truth is not in their colour
            (`render_coverage`).
        name: scene name stored in the `LightField`.
        disparity_range: stored in the `LightField`; defaults to the range of the GT.

    Returns:
        A `LightField` with ``gt_disparity``/``gt_mask`` for all ``U × V`` views (mask all
        ``True``).

    Raises:
        ValueError: on an empty scene, bad grid/size/supersample, a surface folding over in
            some view (``1 - b dc - c dr <= 0.05``), or a view pixel no surface covers.
    """
    U, V, H, W = _check_scene(surfaces, grid, size)
    if supersample < 1:
        raise ValueError(f"supersample must be >= 1; got {supersample}")
    max_dr, max_dc = max(U // 2, U - 1 - U // 2), max(V // 2, V - 1 - V // 2)
    for i, s in enumerate(surfaces):
        _, b, c = s.plane
        if 1.0 - abs(b) * max_dc - abs(c) * max_dr <= 0.05:
            raise ValueError(f"surface {i} is too steep for a {U}x{V} grid: plane {s.plane}")
    dr, dc = view_offsets(U, V)
    offsets = jnp.stack([dr.ravel(), dc.ravel()], axis=-1)
    rgb, gt = _render(_pack(surfaces), offsets, H=H, W=W, ss=int(supersample))
    if not bool(jnp.isfinite(gt).all()):
        raise ValueError("some view pixels are covered by no surface; add a WHOLE background")
    rgb = rgb.reshape(U, V, H, W, 3)
    gt = gt.reshape(U, V, H, W)
    if disparity_range is None:
        disparity_range = (float(gt.min()), float(gt.max()))
    return LightField(
        views=rgb,
        view_mask=jnp.ones((U, V), bool),
        gt_disparity=gt,
        gt_mask=jnp.ones((U, V, H, W), bool),
        name=name,
        source=None,
        disparity_range=(float(disparity_range[0]), float(disparity_range[1])),
    )


@functools.partial(jax.jit, static_argnames=("H", "W", "ss"))
def _coverage(p, offsets, *, H: int, W: int, ss: int):
    """Share of the ``ss²`` colour samples of each pixel that see the surface visible at the
    pixel centre, ``(N, H, W)``, for the views at ``offsets (N, 2)``."""
    _, w, _, _ = _render_geometry(p, offsets, H=H, W=W, ss=ss)
    centre = _render_ids(p, offsets, H=H, W=W)
    return (w == centre[:, None]).mean(axis=1)


def render_coverage(
    surfaces: list[Surface],
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
    supersample: int = 2,
) -> jax.Array:
    """Per-view coverage of the ground-truth surface: the share of each pixel's colour
    samples that see the surface visible at the pixel centre.

    `render_surfaces` takes the ground-truth disparity at the pixel centre and the colour as
    the mean over ``supersample²`` samples; this is how much of that colour comes from the
    ground-truth surface. 1 inside a surface; below 1 on pixels an occlusion boundary crosses
    (mixed pixels). With an even ``supersample`` a straight boundary through the middle of
    a pixel gives coverage exactly 0.5 (two surfaces, equal colour weight), and which of
    them the pixel centre sees is not in the pixel's colour; with an odd ``supersample`` the centre
    is a colour sample and a straight boundary between two surfaces gives the centre's
    surface more than half the samples.

    Args:
        surfaces: the scene, as passed to `render_surfaces`.
        grid: ``(U, V)`` angular resolution (each >= 3).
        size: ``(H, W)`` view size in pixels.
        supersample: colour samples per pixel along each axis, >= 1 (as `render_surfaces`).

    Returns:
        ``(U, V, H, W)`` float32 in ``(0, 1]``, multiples of ``1 / supersample²``.

    Raises:
        ValueError: on an empty scene, a bad grid, size or supersample.
    """
    U, V, H, W = _check_scene(surfaces, grid, size)
    if supersample < 1:
        raise ValueError(f"supersample must be >= 1; got {supersample}")
    dr, dc = view_offsets(U, V)
    offsets = jnp.stack([dr.ravel(), dc.ravel()], axis=-1)
    p = _pack(surfaces)
    ss = int(supersample)
    step = max(1, min(U * V, (1 << 22) // (H * W * ss * ss)))
    parts = [_coverage(p, offsets[i : i + step], H=H, W=W, ss=ss) for i in range(0, U * V, step)]
    return jnp.concatenate(parts).reshape(U, V, H, W).astype(jnp.float32)


# ---- random scenes -------------------------------------------------------------------------


def _random_texture(rng: np.random.Generator, base=None) -> dict:
    base = rng.uniform(0.15, 0.85, 3) if base is None else np.asarray(base, float)
    noise = np.zeros((N_MODES, 6))
    for m in range(N_MODES):
        wavelength = rng.uniform(8.0, 60.0)
        theta = rng.uniform(0, np.pi)
        k = 2 * np.pi / wavelength
        noise[m, :3] = (k * np.cos(theta), k * np.sin(theta), rng.uniform(0, 2 * np.pi))
        noise[m, 3:] = rng.normal(0.0, 0.045, 3)
    kind = rng.integers(0, 3)  # 0: stripes, 1: checker, 2: sparse thin stripes
    period = rng.uniform(7.0, 24.0)
    theta = rng.uniform(0, np.pi)
    k = 2 * np.pi / period
    stripes = [k * np.cos(theta), k * np.sin(theta), rng.uniform(0, 2 * np.pi), 0.0]
    if kind == 1:
        stripes += [
            k * np.cos(theta + np.pi / 2),
            k * np.sin(theta + np.pi / 2),
            rng.uniform(0, 6),
            0.0,
        ]
    else:
        stripes += [0.0, 0.0, -np.pi / 2, 0.0]
        if kind == 2:
            stripes[3] = 0.7  # thin lines (~25% duty)
    amp = rng.uniform(0.15, 0.35)
    scol = amp * rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0, 3)
    return {
        "base": tuple(base),
        "noise": noise,
        "stripes": tuple(stripes),
        "stripe_colour": tuple(scol),
    }


def _fit_plane(a, b, c, box, lo, hi):
    """Shrink the slope (and clamp the offset) so that the plane stays in [lo, hi] on box."""
    x0, x1, y0, y1 = box
    a = float(np.clip(a, lo, hi))
    ext = max(abs(b * x) + abs(c * y) for x in (x0, x1) for y in (y0, y1))
    room = min(hi - a, a - lo)
    if ext > room:
        scale = room / ext if ext > 0 else 0.0
        b, c = b * scale, c * scale
    return a, b, c


def scene_surfaces(
    seed: int = 0,
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
    disparity_range: tuple[float, float] = (-2.0, 2.0),
    n_objects: int = 5,
) -> list[Surface]:
    """The surfaces of `make_scene` (same arguments, same random layout), without rendering.

    Use it with `render_object_ids` for per-view object-ID ground truth, or see
    `make_scene_with_objects`.

    Raises:
        ValueError: on ``d_min >= d_max`` or ``n_objects < 0``.
    """
    lo, hi = (float(v) for v in disparity_range)
    if not lo < hi:
        raise ValueError(
            f"disparity_range must be (d_min, d_max) with d_min < d_max; got {disparity_range}"
        )
    if n_objects < 0:
        raise ValueError(f"n_objects must be >= 0; got {n_objects}")
    U, V = (int(g) for g in grid)
    H, W = (int(s) for s in size)
    rng = np.random.default_rng(seed)
    span = hi - lo
    # Centre-view region any view can see: image +- maximal parallax.
    par = max(U // 2, V // 2) * max(abs(lo), abs(hi)) + 2.0
    full = (-W / 2 - par, W / 2 + par, -H / 2 - par, H / 2 + par)
    # Keep |b| dc + |c| dr well below 1 (no fold-over).
    smax = 0.25 / max(U // 2, V // 2, 1)
    surfaces: list[Surface] = []

    a, b, c = _fit_plane(
        lo + 0.08 * span,
        rng.uniform(-1, 1) * 0.08 * span / W,
        rng.uniform(-1, 1) * 0.08 * span / H,
        full,
        lo,
        hi,
    )
    surfaces.append(Surface(plane=(a, b, c), kind=WHOLE, **_random_texture(rng)))

    # Floor: from ~55% of the height to beyond the bottom, nearer at the bottom.
    ytop = rng.uniform(0.05, 0.2) * H
    box = (full[0], full[1], ytop, full[3])
    yc = 0.5 * (box[2] + box[3])
    hh = 0.5 * (box[3] - box[2])
    a0 = lo + rng.uniform(0.3, 0.4) * span
    c0 = min(0.3 * span / H, smax)
    a, b, c = _fit_plane(a0, 0.0, c0, (box[0], box[1], -hh, hh), lo, hi)
    surfaces.append(
        Surface(
            plane=(a - c * yc, b, c),
            kind=RECT,
            centre=(0.0, yc),
            half_size=(box[1], hh),
            **_random_texture(rng),
        )
    )

    for _ in range(n_objects):
        kind = RECT if rng.uniform() < 0.6 else DISC
        cxo, cyo = rng.uniform(-0.38, 0.38) * W, rng.uniform(-0.38, 0.3) * H
        if kind == RECT:
            half = (rng.uniform(0.06, 0.2) * W, rng.uniform(0.06, 0.2) * H)
            angle = rng.uniform(-0.6, 0.6) if rng.uniform() < 0.5 else 0.0
            bbox_r = float(np.hypot(*half))
        else:
            half = (rng.uniform(0.06, 0.15) * min(H, W),) * 2
            angle = 0.0
            bbox_r = half[0]
        depth = lo + rng.uniform(0.45, 0.95) * span
        slanted = rng.uniform() < 0.4
        b = rng.uniform(-1, 1) * 0.25 * span / W if slanted else 0.0
        c = rng.uniform(-1, 1) * 0.25 * span / H if slanted else 0.0
        b, c = float(np.clip(b, -smax, smax)), float(np.clip(c, -smax, smax))
        local = (-bbox_r, bbox_r, -bbox_r, bbox_r)
        a, b, c = _fit_plane(depth, b, c, local, lo + 0.02 * span, hi - 0.02 * span)
        surfaces.append(
            Surface(
                plane=(a - b * cxo - c * cyo, b, c),
                kind=kind,
                centre=(cxo, cyo),
                half_size=half,
                angle=angle,
                **_random_texture(rng),
            )
        )
    return surfaces


def make_scene(
    seed: int = 0,
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
    disparity_range: tuple[float, float] = (-2.0, 2.0),
    n_objects: int = 5,
    supersample: int = 2,
) -> LightField:
    """A random scene of textured planes and discs at several depths, with exact GT.

    Layout: a slightly slanted textured background at the far end of the range, a slanted
    "floor" rectangle over the lower part of the image (disparity growing downwards), and
    ``n_objects`` rectangles (rotated, some slanted) and discs at random positions and depths
    in front, which occlude each other and the background. Every surface has smooth colour
    noise and hard-edged stripes or a checkerboard, so EPIs have edges at texture boundaries
    and at occlusion boundaries. All disparities of every view lie within
    ``disparity_range``. Deterministic for a given ``seed`` and arguments.

    Args:
        seed: random seed (numpy ``default_rng``).
        grid: ``(U, V)`` angular resolution.
        size: ``(H, W)`` view size in pixels.
        disparity_range: ``(d_min, d_max)`` in pixels per view step, ``d_min < d_max``;
            stored as the light field's ``disparity_range``.
        n_objects: number of foreground rectangles/discs (>= 0).
        supersample: colour samples per pixel along each axis.

    Returns:
        A `LightField` named ``"synthetic-<seed>"`` with ``gt_disparity`` and ``gt_mask``
        ``(U, V, H, W)`` for every view.

    Raises:
        ValueError: on ``d_min >= d_max``, ``n_objects < 0`` or bad grid/size/supersample.
    """
    lo, hi = (float(v) for v in disparity_range)
    surfaces = scene_surfaces(
        seed, grid=grid, size=size, disparity_range=disparity_range, n_objects=n_objects
    )
    return render_surfaces(
        surfaces,
        grid=tuple(int(g) for g in grid),
        size=tuple(int(v) for v in size),
        supersample=supersample,
        name=f"synthetic-{seed}",
        disparity_range=(lo, hi),
    )


def make_scene_with_objects(
    seed: int = 0,
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
    disparity_range: tuple[float, float] = (-2.0, 2.0),
    n_objects: int = 5,
    supersample: int = 2,
) -> tuple[LightField, jax.Array]:
    """`make_scene` plus per-view object-ID ground truth (one ID per surface).

    Returns:
        ``(light_field, object_ids)``: the same `LightField` as `make_scene` with the same
        arguments, and ``(U, V, H, W)`` int32 IDs from `render_object_ids`.

    Raises:
        ValueError: as `make_scene`.
    """
    lf = make_scene(
        seed,
        grid=grid,
        size=size,
        disparity_range=disparity_range,
        n_objects=n_objects,
        supersample=supersample,
    )
    surfaces = scene_surfaces(
        seed, grid=grid, size=size, disparity_range=disparity_range, n_objects=n_objects
    )
    return lf, render_object_ids(surfaces, grid=lf.grid, size=lf.size)


def default_surfaces() -> list[Surface]:
    """The surfaces of `default_light_field` (for `render_object_ids`); deterministic."""
    rng = np.random.default_rng(20221)
    tex = lambda base: _random_texture(rng, base)
    surfaces = [
        # far wall, slightly slanted, thin stripes
        Surface(plane=(-1.2, 0.0008, 0.0), kind=WHOLE, **tex((0.55, 0.62, 0.75))),
        # floor: from y = +20 to the bottom, nearer at the bottom (d = -0.9 ... 0.0 at y=+80)
        Surface(
            plane=(-1.2, 0.0, 0.012),
            kind=RECT,
            centre=(0.0, 65.0),
            half_size=(200.0, 45.0),
            **tex((0.62, 0.52, 0.38)),
        ),
        # striped board at mid depth
        Surface(
            plane=(-0.3, 0.0, 0.0),
            kind=RECT,
            centre=(-25.0, -22.0),
            half_size=(36.0, 30.0),
            **tex((0.80, 0.35, 0.30)),
        ),
        # slanted panel (disparity growing to the right), partly behind the disc
        Surface(
            plane=(0.25, 0.008, 0.0),
            kind=RECT,
            centre=(38.0, 5.0),
            half_size=(22.0, 34.0),
            angle=0.15,
            **tex((0.35, 0.65, 0.40)),
        ),
        # disc in front of the board and the panel
        Surface(
            plane=(0.9, 0.0, 0.0),
            kind=DISC,
            centre=(12.0, -8.0),
            half_size=(20.0, 20.0),
            **tex((0.90, 0.80, 0.30)),
        ),
        # thin rotated bar, nearest
        Surface(
            plane=(1.35, 0.0, 0.0),
            kind=RECT,
            centre=(-30.0, 30.0),
            half_size=(40.0, 3.5),
            angle=-0.5,
            **tex((0.25, 0.30, 0.70)),
        ),
    ]
    return surfaces


@functools.lru_cache(maxsize=2)
def default_light_field() -> LightField:
    """The embedded default input of ``mvedge demo``: a 9×9×160×160 synthetic scene.

    A far textured wall, a slanted checkered floor, a striped board at mid depth, a slanted
    panel, a disc and a thin rotated bar in front (several mutual occlusions, thin structure,
    fronto-parallel and slanted surfaces); disparities within [-1.5, 1.5] pixels per view
    step; exact GT for every view. Deterministic; cached after the first call.

    Returns:
        A `LightField` named ``"synthetic-default"`` with ``disparity_range = (-1.5, 1.5)``.
    """
    H = W = 160
    return render_surfaces(
        default_surfaces(),
        grid=(9, 9),
        size=(H, W),
        supersample=3,
        name="synthetic-default",
        disparity_range=(-1.5, 1.5),
    )
