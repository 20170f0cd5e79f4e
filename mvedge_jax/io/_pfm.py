"""PFM (portable float map) read and write."""

from __future__ import annotations

import os

import numpy as np

from ._images import check_regular_file


def read_pfm(path: str | os.PathLike) -> np.ndarray:
    """Read a PFM file.

    PFM stores rows bottom-to-top; the returned array is top-to-bottom (image order).

    Args:
        path: file path.

    Returns:
        ``(H, W)`` float32 for greyscale (``Pf``) or ``(H, W, 3)`` float32 for colour (``PF``).

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if the header is malformed, the data is truncated, or the path is not a
            regular file (a named pipe is never opened).
    """
    path = os.fspath(path)
    check_regular_file(path, "PFM file")
    with open(path, "rb") as f:
        data = f.read()
    # Header: three whitespace-separated tokens, each ended by a single whitespace byte.
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4 and pos < len(data):
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace():
            pos += 1
        tokens.append(data[start:pos])
        if len(tokens) == 4:
            break
    if len(tokens) < 4:
        raise ValueError(f"corrupt PFM header in {path}: expected 'PF|Pf W H scale'")
    pos += 1  # the single whitespace byte after the scale
    magic, w_tok, h_tok, s_tok = tokens
    if magic not in (b"PF", b"Pf"):
        raise ValueError(f"not a PFM file (magic {magic!r}): {path}")
    try:
        width, height, scale = int(w_tok), int(h_tok), float(s_tok)
    except ValueError as e:
        raise ValueError(f"corrupt PFM header in {path}: {e}") from None
    if width <= 0 or height <= 0 or scale == 0:
        raise ValueError(f"corrupt PFM header in {path}: size {width}x{height}, scale {scale}")
    channels = 3 if magic == b"PF" else 1
    dtype = "<f4" if scale < 0 else ">f4"
    count = width * height * channels
    if len(data) - pos < 4 * count:
        raise ValueError(
            f"truncated PFM {path}: expected {4 * count} bytes of data, found {len(data) - pos}"
        )
    arr = np.frombuffer(data, dtype=dtype, count=count, offset=pos).astype(np.float32)
    arr = arr.reshape((height, width, channels) if channels == 3 else (height, width))
    return np.ascontiguousarray(arr[::-1])


def write_pfm(path: str | os.PathLike, image: np.ndarray, *, little_endian: bool = True) -> None:
    """Write a PFM file (rows stored bottom-to-top, as the format requires).

    Args:
        path: destination file; its parent folder must exist.
        image: ``(H, W)`` or ``(H, W, 3)`` array, written as float32.
        little_endian: byte order of the data (negative scale in the header when True).

    Raises:
        ValueError: if ``image`` is not 2-D or ``(H, W, 3)``.
    """
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        magic = b"Pf"
    elif image.ndim == 3 and image.shape[2] == 3:
        magic = b"PF"
    else:
        raise ValueError(f"write_pfm expects (H, W) or (H, W, 3); got shape {image.shape}")
    h, w = image.shape[:2]
    dtype = "<f4" if little_endian else ">f4"
    scale = -1.0 if little_endian else 1.0
    with open(os.fspath(path), "wb") as f:
        f.write(magic + b"\n" + f"{w} {h}\n{scale}\n".encode())
        f.write(np.ascontiguousarray(image[::-1]).astype(dtype).tobytes())
