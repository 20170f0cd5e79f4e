"""Builders of small synthetic light-field folders (in tmp_path) for the io tests."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import cv2
import numpy as np
import pytest


def synth_views(U: int, V: int, H: int, W: int, *, d: int = 1, seed: int = 0) -> np.ndarray:
    """``(U, V, H, W, 3)`` uint8 views of a fronto-parallel textured plane at integer
    disparity ``d``: ``centre(x, y) = view[r, c](x - dc d, y - dr d)`` (SPEC §0)."""
    rng = np.random.default_rng(seed)
    m = d * max(U, V)
    tex = cv2.GaussianBlur(rng.normal(size=(H + 2 * m, W + 2 * m, 3)).astype(np.float32), (0, 0), 2)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    tex = np.round(20 + 215 * tex).astype(np.uint8)
    out = np.empty((U, V, H, W, 3), np.uint8)
    for r in range(U):
        for c in range(V):
            dr, dc = r - U // 2, c - V // 2
            # view(x', y') = tex(x' + dc d, y' + dr d)  ⇒  view(x - dc d) = tex(x) = centre(x)
            out[r, c] = tex[m + dr * d : m + dr * d + H, m + dc * d : m + dc * d + W]
    return out


def write_rgb(path: Path, img: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))


def write_grid(
    folder: Path,
    views: np.ndarray,
    name: Callable[[int, int], str] = lambda r, c: f"{r:02d}_{c:02d}.png",
    skip: Iterable[tuple[int, int]] = (),
) -> Path:
    """Write ``views[r, c]`` to ``folder / name(r, c)`` (0-based r, c)."""
    skip = set(skip)
    folder.mkdir(parents=True, exist_ok=True)
    for r in range(views.shape[0]):
        for c in range(views.shape[1]):
            if (r, c) not in skip:
                write_rgb(folder / name(r, c), views[r, c])
    return folder


def write_hci4d(
    folder: Path,
    views: np.ndarray,
    *,
    gt: np.ndarray | None = None,
    drange: tuple[float, float] | None = (-2.0, 2.0),
    skip: Iterable[tuple[int, int]] = (),
) -> Path:
    """An HCI 4D folder: input_CamNNN.png (k = V*row + col), parameters.cfg, gt_disp_lowres.pfm."""
    from mvedge_jax.io import write_pfm

    U, V = views.shape[:2]
    write_grid(folder, views, lambda r, c: f"input_Cam{V * r + c:03d}.png", skip)
    cfg = (
        f"[extrinsics]\nnum_cams_x = {V}\nnum_cams_y = {U}\nbaseline_mm = 10.0\n\n"
        "[meta]\nscene = synth\n"
    )
    if drange is not None:
        cfg += f"disp_min = {drange[0]}\ndisp_max = {drange[1]}\n"
    (folder / "parameters.cfg").write_text(cfg)
    if gt is not None:
        write_pfm(folder / "gt_disp_lowres.pfm", gt)
    return folder


HCI_OLD_CONST = {"dH": 614.4, "focalLength": 9.375, "shift": 288.0}


def write_hci_old(
    folder: Path,
    views: np.ndarray,
    disparity: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    focal_length: float = HCI_OLD_CONST["focalLength"],
) -> Path:
    """An old-HCI folder: lf/RR_CC.png, attributes.dat, depth.bin (from ``disparity``), mask.png."""
    U, V, H, W = views.shape[:4]
    write_grid(folder / "lf", views)
    dH, shift = HCI_OLD_CONST["dH"], HCI_OLD_CONST["shift"]
    if focal_length == 0:
        depth = disparity.astype("<f4")
    else:
        depth = (dH * focal_length / (disparity.astype(np.float64) + shift)).astype("<f4")
    depth.tofile(folder / "depth.bin")
    (folder / "attributes.dat").write_text(
        f"{W} //xRes\n{H} //yRes\n{V} //hRes\n{U} //vRes\n{dH:e} //dH\n{shift:g} //shift\n"
        f"{focal_length:f} //focalLength\n-3.5 //min_disp\n4.5 //max_disp\n"
    )
    if mask is not None:
        assert cv2.imwrite(str(folder / "mask.png"), mask.astype(np.uint8) * 255)
    return folder


def listing(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``folder`` with (size, mtime_ns): to check nothing was written."""
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
    }


@pytest.fixture
def synth():
    """The folder builders: ``synth.views``, ``.grid``, ``.hci4d``, ``.hci_old``, ``.rgb``."""

    class _S:
        views = staticmethod(synth_views)
        grid = staticmethod(write_grid)
        hci4d = staticmethod(write_hci4d)
        hci_old = staticmethod(write_hci_old)
        rgb = staticmethod(write_rgb)
        listing = staticmethod(listing)
        HCI_OLD = HCI_OLD_CONST

    return _S
