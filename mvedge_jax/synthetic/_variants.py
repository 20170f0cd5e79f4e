"""Synthetic scenes that stress one difficulty each: textureless regions, slanted planes, thin
structures, a wide disparity range.

Built from the public `Surface` / `render_surfaces` / `make_scene` of ``_scene.py``, so each
has exact ground truth in every view. Small by default (9×9×128²): the whole chain runs in
seconds on them, so they serve as validation scenes beside the HCI ones (leave-one-scene-out
in ``experiments/reproduce_ch6.py``, region/stage error split in
``experiments/error_split.py``).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..lightfield import LightField
from ._scene import (
    DISC,
    N_SHADE,
    RECT,
    WHOLE,
    Surface,
    make_scene,
    render_surfaces,
    scene_surfaces,
)

VARIANTS = ("textureless", "slanted", "thin", "wide", "glossy")

#: GT disparity range requested of `make_scene` for the ``"wide"`` variant.
WIDE_RANGE = (-4.0, 4.0)

_N_MODES = 6  # rows of `Surface.noise`

#: The glossy variant's view-dependent shading amplitude per view step and mode, its
#: sinusoids' wavelengths (pixels), and its render noise: measured on HCI antinous (flat,
#: faintly textured pixels, ground-truth disparity; docs/ACCURACY.md, "View-dependent
#: shading"): the part of a view's difference to the centre view smoother than 8 px grows by
#: ~0.0004 per channel and view step and is mostly smoother than 32 px (of 512), and what
#: is left after removing the part smoother than 2 px is noise-like, 0.0015 mean absolute
#: difference (the same measurement on this variant gives 0.0020 / 0.0015 at 4 view steps).
GLOSS_AMPLITUDE = 5e-4
GLOSS_WAVELENGTH = (40.0, 120.0)
GLOSS_NOISE = 2.5e-3


def _glossy_texture(rng: np.random.Generator, base) -> dict:
    """Faint texture (median colour gradient about 0.003 per pixel, as antinous' floor and
    statue) with view-dependent shading (`Surface.shading`)."""
    tex = _textured(rng, base, contrast=0.01, noise_amp=0.008)
    shading = np.zeros((N_SHADE, 5))
    for m in range(N_SHADE):
        k = 2 * np.pi / rng.uniform(*GLOSS_WAVELENGTH)
        t = rng.uniform(0, np.pi)
        shading[m, :3] = (k * np.cos(t), k * np.sin(t), rng.uniform(0, 2 * np.pi))
        shading[m, 3:] = GLOSS_AMPLITUDE * rng.choice([-1.0, 1.0], 2)
    return {**tex, "shading": shading}


def _textured(
    rng: np.random.Generator, base, *, period=(7.0, 20.0), contrast=0.3, noise_amp=0.05
) -> dict:
    """Texture fields of a `Surface`: smooth colour noise (amplitudes normal with standard
    deviation ``noise_amp``) plus hard-edged stripes or a checker (colour ``contrast``)."""
    noise = np.zeros((_N_MODES, 6))
    for m in range(_N_MODES):
        k = 2 * np.pi / rng.uniform(8.0, 50.0)
        t = rng.uniform(0, np.pi)
        noise[m, :3] = (k * np.cos(t), k * np.sin(t), rng.uniform(0, 2 * np.pi))
        noise[m, 3:] = rng.normal(0.0, noise_amp, 3)
    k = 2 * np.pi / rng.uniform(*period)
    t = rng.uniform(0, np.pi)
    stripes = [k * np.cos(t), k * np.sin(t), rng.uniform(0, 2 * np.pi), 0.0]
    if rng.uniform() < 0.5:  # checker
        stripes += [-k * np.sin(t), k * np.cos(t), rng.uniform(0, 2 * np.pi), 0.0]
    else:
        stripes += [0.0, 0.0, -np.pi / 2, 0.0]
    colour = contrast * rng.choice([-1.0, 1.0]) * rng.uniform(0.6, 1.0, 3)
    return {
        "base": tuple(float(b) for b in base),
        "noise": noise,
        "stripes": tuple(float(s) for s in stripes),
        "stripe_colour": tuple(float(c) for c in colour),
    }


def _flat(base) -> dict:
    """A textureless surface: one colour, no noise, no stripes."""
    return {"base": tuple(float(b) for b in base)}


def _textureless(rng, H, W) -> list[Surface]:
    # Far textured wall; a large uniform slanted floor; a uniform disc and a uniform panel in
    # front of textured surfaces; one textured board: the interiors of the uniform surfaces
    # carry no edge, only their outlines do.
    return [
        Surface(plane=(-1.6, 0.0, 0.0), kind=WHOLE, **_textured(rng, (0.55, 0.6, 0.7))),
        Surface(  # from 0.1 H below the centre to beyond the bottom; d = -1.5 at its top
            plane=(-1.5 - 0.012 * 0.1 * H, 0.0, 0.012),
            kind=RECT,
            centre=(0.0, 0.1 * H + 0.5 * H),
            half_size=(W, 0.5 * H),
            **_flat((0.75, 0.62, 0.45)),
        ),
        Surface(
            plane=(-0.4, 0.0, 0.0),
            kind=RECT,
            centre=(-0.22 * W, -0.12 * H),
            half_size=(0.22 * W, 0.2 * H),
            **_textured(rng, (0.8, 0.35, 0.3)),
        ),
        Surface(
            plane=(0.6, 0.0, 0.0),
            kind=DISC,
            centre=(0.2 * W, -0.15 * H),
            half_size=(0.17 * W, 0.17 * W),
            **_flat((0.3, 0.45, 0.8)),
        ),
        Surface(
            plane=(1.2, 0.004, 0.0),
            kind=RECT,
            centre=(-0.05 * W, 0.2 * H),
            half_size=(0.14 * W, 0.09 * H),
            angle=0.2,
            **_flat((0.9, 0.85, 0.35)),
        ),
    ]


def _slanted(rng, H, W) -> list[Surface]:
    # Every surface slanted; slopes up to 0.05 per pixel (3 px of disparity over 64 px).
    def plane(a, b, c, cx, cy):  # disparity a at (cx, cy)
        return (a - b * cx - c * cy, b, c)

    return [
        Surface(plane=(-1.0, 0.006, -0.004), kind=WHOLE, **_textured(rng, (0.5, 0.6, 0.7))),
        Surface(
            plane=plane(0.0, 0.03, 0.0, -0.2 * W, -0.15 * H),
            kind=RECT,
            centre=(-0.2 * W, -0.15 * H),
            half_size=(0.2 * W, 0.22 * H),
            angle=0.1,
            **_textured(rng, (0.8, 0.4, 0.3)),
        ),
        Surface(
            plane=plane(0.8, -0.02, 0.035, 0.22 * W, 0.05 * H),
            kind=RECT,
            centre=(0.22 * W, 0.05 * H),
            half_size=(0.16 * W, 0.28 * H),
            angle=-0.25,
            **_textured(rng, (0.35, 0.7, 0.4)),
        ),
        Surface(
            plane=plane(1.4, 0.045, 0.02, -0.1 * W, 0.28 * H),
            kind=DISC,
            centre=(-0.1 * W, 0.28 * H),
            half_size=(0.14 * W, 0.14 * W),
            **_textured(rng, (0.85, 0.8, 0.35)),
        ),
    ]


def _thin(rng, H, W) -> list[Surface]:
    # Bars 2–5 px wide at several depths and angles in front of a textured wall and board.
    out = [
        Surface(plane=(-1.2, 0.0, 0.0), kind=WHOLE, **_textured(rng, (0.55, 0.55, 0.65))),
        Surface(
            plane=(-0.5, 0.0, 0.0),
            kind=RECT,
            centre=(0.2 * W, 0.15 * H),
            half_size=(0.25 * W, 0.25 * H),
            **_textured(rng, (0.7, 0.5, 0.35)),
        ),
    ]
    bars = [  # (x, y, half length, half width, angle, disparity, colour)
        (-0.25 * W, 0.0, 0.45 * H, 1.0, 1.45, 0.3, (0.9, 0.2, 0.2)),
        (0.05 * W, -0.1 * H, 0.45 * W, 1.5, 0.0, 0.9, (0.2, 0.8, 0.3)),
        (0.2 * W, 0.1 * H, 0.4 * H, 2.5, 0.6, 1.5, (0.2, 0.3, 0.9)),
        (-0.05 * W, 0.3 * H, 0.35 * W, 1.0, -0.3, 1.1, (0.95, 0.9, 0.2)),
    ]
    for x, y, hl, hw, ang, d, col in bars:
        out.append(
            Surface(
                plane=(d, 0.0, 0.0),
                kind=RECT,
                centre=(x, y),
                half_size=(hl, hw),
                angle=ang,
                **_textured(rng, col, period=(5.0, 9.0), contrast=0.15),
            )
        )
    return out


def _glossy(rng, H, W) -> list[Surface]:
    # Antinous-like: faint, glossy surfaces (a back wall, a slanted floor, a statue-like
    # panel and disc, a board in front), told apart by their base colours.
    return [
        Surface(plane=(-1.4, 0.0, 0.0), kind=WHOLE, **_glossy_texture(rng, (0.55, 0.55, 0.6))),
        Surface(  # from 0.05 H below the centre to beyond the bottom; d = -1.3 at its top
            plane=(-1.3 - 0.02 * 0.05 * H, 0.0, 0.02),
            kind=RECT,
            centre=(0.0, 0.05 * H + 0.5 * H),
            half_size=(W, 0.5 * H),
            **_glossy_texture(rng, (0.7, 0.65, 0.55)),
        ),
        Surface(
            plane=(0.2, 0.0, 0.0),
            kind=RECT,
            centre=(-0.15 * W, -0.05 * H),
            half_size=(0.12 * W, 0.3 * H),
            angle=0.05,
            **_glossy_texture(rng, (0.8, 0.78, 0.72)),
        ),
        Surface(
            plane=(0.9, 0.0, 0.0),
            kind=DISC,
            centre=(-0.15 * W, -0.3 * H),
            half_size=(0.1 * W, 0.1 * W),
            **_glossy_texture(rng, (0.82, 0.8, 0.75)),
        ),
        Surface(
            plane=(1.5, -0.005, 0.0),
            kind=RECT,
            centre=(0.25 * W, 0.25 * H),
            half_size=(0.15 * W, 0.08 * H),
            angle=-0.15,
            **_glossy_texture(rng, (0.45, 0.35, 0.3)),
        ),
    ]


def variant_scene(
    kind: str,
    seed: int = 0,
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
    supersample: int = 3,
) -> LightField:
    """A synthetic light field that stresses one difficulty, with exact GT in every view.

    * ``"textureless"``: uniform-colour surfaces (a slanted floor, a disc, a panel) among
      textured ones; their interiors have no edge; disparities in [−1.6, 1.25].
    * ``"slanted"``: every surface slanted, slopes up to 0.045 px per view step per pixel;
      disparities in about [−1.7, 2.4].
    * ``"thin"``: bars 2–5 px wide at disparities 0.3–1.5 in front of a textured wall (−1.2)
      and board (−0.5).
    * ``"wide"``: `make_scene` with ``disparity_range = (−4, 4)`` (GT within ±4 px per view
      step, about [−3.5, 2.8] for seed 0: parallax up to 14 px at the corner views of a
      9×9 grid).
    * ``"glossy"``: HCI-render-like photometry (`GLOSS_AMPLITUDE`, `GLOSS_WAVELENGTH`,
      `GLOSS_NOISE`, measured on antinous): faint textures, view-dependent shading
      (`Surface.shading`) and Gaussian render noise of standard deviation `GLOSS_NOISE`
      (seeded); a back wall, a slanted floor and three objects; disparities in
      [−1.40, 1.44].

    Textures are random (``seed``); the geometry of the first three is fixed. Built from
    `Surface` and `render_surfaces` (`make_scene` for ``"wide"``).

    Args:
        kind: one of `VARIANTS`.
        seed: random seed of the textures (and of the layout of ``"wide"``).
        grid: ``(U, V)`` angular resolution.
        size: ``(H, W)`` view size in pixels (the geometry scales with it; bar widths do
            not).
        supersample: colour samples per pixel along each axis (anti-aliasing). Odd by
            default, as the default scene's, so that a pixel's ground truth (its centre's
            surface) is the surface of most of its colour samples at a straight boundary
            (`render_coverage`; with 2, 63–79 % of the variants' pixels that an occlusion
            boundary crosses mix two surfaces half and half, and the side their centre is
            on is not in their colour).

    Returns:
        A `LightField` named ``"synthetic-<kind>"`` with ``gt_disparity`` and ``gt_mask``
        ``(U, V, H, W)`` and its GT range as ``disparity_range`` (``(−4, 4)`` for ``"wide"``).

    Raises:
        ValueError: on an unknown kind or bad grid/size/supersample.

    References:
        Issue 19 (validation scenes); thesis Ch. 6 (textureless interiors are the ceiling of
        interpolation from sparse edges).
    """
    if kind not in VARIANTS:
        raise ValueError(f"unknown synthetic variant {kind!r}; use one of {VARIANTS}")
    if kind == "wide":
        lf = make_scene(
            seed, grid=grid, size=size, disparity_range=WIDE_RANGE, supersample=supersample
        )
        return dataclasses.replace(lf, name="synthetic-wide")
    rng = np.random.default_rng(seed)
    surfaces = _build(kind, rng, size)
    lf = render_surfaces(
        surfaces, grid=grid, size=size, supersample=supersample, name=f"synthetic-{kind}"
    )
    if kind == "glossy":
        noise = rng.normal(0.0, GLOSS_NOISE, lf.views.shape).astype(np.float32)
        lf = dataclasses.replace(lf, views=jnp.clip(lf.views + noise, 0.0, 1.0))
    return lf


def _build(kind: str, rng: np.random.Generator, size) -> list[Surface]:
    H, W = (int(s) for s in size)
    build = {"textureless": _textureless, "slanted": _slanted, "thin": _thin, "glossy": _glossy}
    return build[kind](rng, H, W)


def variant_surfaces(
    kind: str,
    seed: int = 0,
    *,
    grid: tuple[int, int] = (9, 9),
    size: tuple[int, int] = (128, 128),
) -> list[Surface]:
    """The surfaces of `variant_scene` (same arguments, same layout and textures), without
    rendering: for `render_coverage` or `render_object_ids`.

    The glossy variant's render noise is added to the rendered views and is not part of the
    surfaces.

    Raises:
        ValueError: on an unknown kind.
    """
    if kind not in VARIANTS:
        raise ValueError(f"unknown synthetic variant {kind!r}; use one of {VARIANTS}")
    if kind == "wide":
        return scene_surfaces(seed, grid=grid, size=size, disparity_range=WIDE_RANGE)
    return _build(kind, np.random.default_rng(seed), size)


def variant_scenes(seed: int = 0, **kwargs) -> dict[str, LightField]:
    """Every variant of `VARIANTS`: ``{kind: variant_scene(kind, seed, **kwargs)}``.

    Args:
        seed: passed to `variant_scene`.
        **kwargs: ``grid``, ``size``, ``supersample`` of `variant_scene`.

    Returns:
        ``{kind: LightField}`` in the order of `VARIANTS`.

    Raises:
        ValueError: as `variant_scene`.
    """
    return {k: variant_scene(k, seed, **kwargs) for k in VARIANTS}
