"""Raster images: decoding views to float RGB, parallel reads, area downscaling, PNG output."""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

#: File extensions recognised as view images (lower case, with the dot).
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm")


def aligned_zeros(shape: tuple[int, ...], dtype=np.float32, align: int = 64) -> np.ndarray:
    """``np.zeros`` whose data pointer is ``align``-byte aligned.

    On the CPU backend ``jax.device_put`` then wraps the buffer without copying it (a
    255 MB 9×9×512² light field is not duplicated); the caller must not modify the array
    after handing it to JAX.
    """
    n = int(np.prod(shape)) * np.dtype(dtype).itemsize
    buf = np.zeros(n + align, np.uint8)
    off = (-buf.ctypes.data) % align
    return buf[off : off + n].view(dtype).reshape(shape)


def check_regular_file(path: str, what: str = "image file") -> None:
    """Raise unless ``path`` is a regular file (after following symlinks).

    Reading a named pipe, a device or a socket could block forever or read endless data,
    so only regular files are opened.

    Raises:
        FileNotFoundError: if ``path`` does not exist.
        ValueError: if it is a folder, a named pipe, a device or a socket.
    """
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} not found: {path}") from None
    if not stat.S_ISREG(mode):
        kind = (
            "a folder"
            if stat.S_ISDIR(mode)
            else "a named pipe"
            if stat.S_ISFIFO(mode)
            else "a device"
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a socket"
            if stat.S_ISSOCK(mode)
            else "not a regular file"
        )
        raise ValueError(f"{what} {path} is {kind}, not a regular file; refusing to read it")


def _decode_channels(path: str) -> tuple[np.ndarray, int]:
    """`_decode`, also returning the file's channel count (1 grey, 2 grey+alpha, 3, 4)."""
    check_regular_file(path)
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(
            f"cannot decode image {path} ({os.path.getsize(path)} bytes): corrupt, truncated "
            "or not an image"
        )
    if img.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"unsupported image dtype {img.dtype} in {path}; expected 8 or 16 bit")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), 1
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB), 4
    if img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB), 3
    raise ValueError(f"unsupported channel count {img.shape[2]} in {path}; expected 1, 3 or 4")


def _decode(path: str) -> np.ndarray:
    """Decode an image file to uint8/uint16 ``(H, W, 3)`` RGB (alpha dropped, grey repeated).

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: not a regular file, not decodable, or an unsupported format.
    """
    return _decode_channels(path)[0]


def scaled_size(size: tuple[int, int], scale: float) -> tuple[int, int]:
    """``(H, W)`` after scaling by ``scale`` (rounded, at least 1 pixel)."""
    return max(1, round(size[0] * scale)), max(1, round(size[1] * scale))


def resize_area(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Resize ``(H, W[, C])`` float32 to ``size = (H', W')`` with ``cv2.INTER_AREA``."""
    if tuple(image.shape[:2]) == tuple(size):
        return image
    return cv2.resize(image, (size[1], size[0]), interpolation=cv2.INTER_AREA)


def read_rgb(path: str | os.PathLike, *, scale: float | None = None) -> np.ndarray:
    """Read one view as float32 RGB in [0, 1].

    Args:
        path: an 8- or 16-bit image (grey, RGB or RGBA; alpha is dropped).
        scale: optional spatial scale factor in (0, 1]; downscaled with ``cv2.INTER_AREA``.

    Returns:
        ``(H, W, 3)`` float32 RGB in [0, 1] (``H, W`` after scaling).

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if the file cannot be decoded or has an unsupported format.
    """
    img = _decode(os.fspath(path))
    out = img.astype(np.float32)
    out /= np.float32(65535.0 if img.dtype == np.uint16 else 255.0)
    if scale is not None and scale != 1.0:
        out = resize_area(out, scaled_size(out.shape[:2], scale))
    return out


def read_views(
    paths: Sequence[str], *, scale: float | None = None, workers: int | None = None
) -> np.ndarray:
    """Read many same-sized views in parallel (a thread pool; OpenCV releases the GIL).

    Args:
        paths: ``N`` image files.
        scale: optional spatial scale factor in (0, 1] (``cv2.INTER_AREA``).
        workers: number of threads (default ``min(8, cpu_count)``).

    Returns:
        ``(N, H, W, 3)`` float32 RGB in [0, 1].

    Raises:
        FileNotFoundError: if a file is missing.
        ValueError: if a file cannot be decoded or the views differ in size (the message
            lists the sizes found and the files that have them).
    """
    return _read_views(paths, scale=scale, workers=workers)[0]


def _read_views(
    paths: Sequence[str],
    *,
    scale: float | None = None,
    workers: int | None = None,
    slots: Sequence[int] | None = None,
    n_slots: int | None = None,
    min_size: int = 1,
) -> tuple[np.ndarray, tuple[int, int]]:
    """`read_views`, also returning the original ``(H, W)`` (that of ``paths[0]``).

    With ``slots``/``n_slots`` the result is ``(n_slots, H, W, 3)`` with image ``i`` at
    ``slots[i]`` and zeros elsewhere (read straight into place, no second copy).

    Raises:
        ValueError: also if the views (after scaling) are smaller than ``min_size`` pixels
            in a direction (checked on the first view, before anything is allocated), or
            grey views are mixed with colour views.
    """
    if not paths:
        raise ValueError("read_views: no image paths given")
    workers = workers or min(8, os.cpu_count() or 1)
    slots = list(range(len(paths))) if slots is None else list(slots)
    n_slots = len(paths) if n_slots is None else n_slots
    first, first_channels = _decode_channels(paths[0])
    size = first.shape[:2]
    out_size = scaled_size(size, scale) if scale is not None else size
    _check_min_size(paths[0], size, out_size, scale, min_size)
    out = aligned_zeros((n_slots, *out_size, 3), np.float32)
    shapes: dict[int, tuple[int, ...]] = {}
    channels: dict[int, int] = {}

    def one(i: int) -> None:
        img, channels[i] = (first, first_channels) if i == 0 else _decode_channels(paths[i])
        shapes[i] = img.shape[:2]
        if img.shape[:2] != size:
            return  # reported below with every mismatching file
        k = np.float32(65535.0 if img.dtype == np.uint16 else 255.0)
        if out_size == size:
            np.divide(img, k, out=out[slots[i]], dtype=np.float32)
        else:
            f = img.astype(np.float32)
            f /= k
            out[slots[i]] = resize_area(f, out_size)

    if workers > 1 and len(paths) > 1:
        with ThreadPoolExecutor(max_workers=workers) as ex:
            list(ex.map(one, range(len(paths))))
    else:
        for i in range(len(paths)):
            one(i)
    bad = [i for i in range(len(paths)) if shapes[i] != size]
    if bad:
        h0, w0 = size
        odd = ", ".join(
            f"{os.path.basename(paths[i])} is {shapes[i][0]}x{shapes[i][1]}" for i in bad[:4]
        )
        more = f" and {len(bad) - 4} more" if len(bad) > 4 else ""
        raise ValueError(
            f"views have different sizes in {os.path.dirname(paths[0])}: "
            f"{os.path.basename(paths[0])} is {h0}x{w0} (HxW) but {odd}{more}"
        )
    _check_channels(paths, channels)
    return out, (int(size[0]), int(size[1]))


_CHANNEL_NAMES = {1: "grey", 2: "grey + alpha", 3: "RGB", 4: "RGBA"}


def _check_channels(paths: Sequence[str], channels: dict[int, int]) -> None:
    """Grey views among colour views (or the reverse) are an error, naming the files."""
    grey = [i for i in range(len(paths)) if channels[i] < 3]
    colour = [i for i in range(len(paths)) if channels[i] >= 3]
    if grey and colour:
        few, many = (grey, colour) if len(grey) <= len(colour) else (colour, grey)
        odd = ", ".join(
            f"{os.path.basename(paths[i])} ({_CHANNEL_NAMES[channels[i]]})" for i in few[:4]
        )
        more = f" and {len(few) - 4} more" if len(few) > 4 else ""
        raise ValueError(
            f"views mix grey and colour images in {os.path.dirname(paths[0])}: {odd}{more}, "
            f"but {os.path.basename(paths[many[0]])} is {_CHANNEL_NAMES[channels[many[0]]]}; "
            "every view must have the same colour format"
        )


def _check_min_size(
    path: str,
    size: tuple[int, int],
    out_size: tuple[int, int],
    scale: float | None,
    min_size: int,
) -> None:
    if min(out_size) >= min_size:
        return
    h, w = size
    if tuple(out_size) != tuple(size):
        raise ValueError(
            f"scale {scale:g} makes the {h}x{w} (HxW) views of {os.path.dirname(path)} "
            f"{out_size[0]}x{out_size[1]} px, below the minimum of {min_size}x{min_size} px; "
            "use a larger scale"
        )
    raise ValueError(
        f"views in {os.path.dirname(path)} are {h}x{w} px (HxW, {os.path.basename(path)}), "
        f"below the minimum of {min_size}x{min_size} px for depth estimation"
    )


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an image as PNG.

    Args:
        path: destination ``.png`` file; its parent folder must exist.
        image: ``(H, W)`` grey or ``(H, W, 3)`` RGB; uint8/uint16 written as is, floating
            point taken as [0, 1] (clipped) and written as 8 bit.

    Raises:
        FileNotFoundError: if the destination folder does not exist.
        ValueError: on other shapes or dtypes, non-finite float values, or a failed write.
    """
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
        raise ValueError(f"write_png expects (H, W) or (H, W, 3); got shape {arr.shape}")
    if np.issubdtype(arr.dtype, np.floating):
        if not np.isfinite(arr).all():
            raise ValueError("write_png: image contains NaN or Inf")
        arr = np.round(np.clip(arr, 0.0, 1.0) * 255.0).astype(np.uint8)
    elif arr.dtype == np.bool_:
        arr = arr.astype(np.uint8) * 255
    elif arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"write_png: unsupported dtype {arr.dtype}; use uint8, uint16 or float")
    if arr.ndim == 3:
        arr = cv2.cvtColor(np.ascontiguousarray(arr), cv2.COLOR_RGB2BGR)
    path = os.fspath(path)
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise FileNotFoundError(f"write_png: folder does not exist: {parent}")
    if not path.lower().endswith(".png"):
        raise ValueError(f"write_png: destination must end in .png; got {path}")
    if not cv2.imwrite(path, arr):
        raise ValueError(f"write_png: could not write {path}")
