"""COLMAP sparse models, text (``cameras.txt``, ``images.txt``, ``points3D.txt``) and binary
(``cameras.bin``, ``images.bin``, ``points3D.bin``).

Conventions (COLMAP): an image's pose maps world to camera coordinates,
``X_cam = R(q) X_world + t`` with the unit quaternion ``q = (qw, qx, qy, qz)``; the camera looks
along ``+z``; image coordinates put the centre of the top-left pixel at ``(0.5, 0.5)``. This
reader keeps COLMAP's numbers unchanged; `ColmapCamera.pixel_offset` (0.5) is what to subtract
to get this project's convention (pixel centres at integers).

References:
    Schönberger & Frahm, "Structure-from-Motion Revisited", CVPR 2016; COLMAP documentation,
    "Output format" (text and binary models). Thesis Sec. 7.2.2 (sparse COLMAP points as input).
"""

from __future__ import annotations

import dataclasses
import os
import struct

import numpy as np

# model name → number of parameters (COLMAP's camera models)
CAMERA_MODELS: dict[str, int] = {
    "SIMPLE_PINHOLE": 3,  # f, cx, cy
    "PINHOLE": 4,  # fx, fy, cx, cy
    "SIMPLE_RADIAL": 4,  # f, cx, cy, k
    "RADIAL": 5,  # f, cx, cy, k1, k2
    "OPENCV": 8,  # fx, fy, cx, cy, k1, k2, p1, p2
    "OPENCV_FISHEYE": 8,  # fx, fy, cx, cy, k1, k2, k3, k4
    "FULL_OPENCV": 12,  # fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6
    "FOV": 5,  # fx, fy, cx, cy, omega
    "SIMPLE_RADIAL_FISHEYE": 4,  # f, cx, cy, k
    "RADIAL_FISHEYE": 5,  # f, cx, cy, k1, k2
    "THIN_PRISM_FISHEYE": 12,  # fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1
}


# Camera models whose parameters start with one focal length ``f, cx, cy, ...``; the others
# start with ``fx, fy, cx, cy, ...``.
_ONE_FOCAL_MODELS = (
    "SIMPLE_PINHOLE",
    "SIMPLE_RADIAL",
    "RADIAL",
    "SIMPLE_RADIAL_FISHEYE",
    "RADIAL_FISHEYE",
)


@dataclasses.dataclass(frozen=True)
class ColmapCamera:
    """One camera (intrinsics).

    Attributes:
        camera_id: COLMAP id.
        model: model name (a key of `CAMERA_MODELS`).
        width, height: image size in pixels.
        params: ``(P,)`` float64 model parameters in COLMAP's order.
    """

    camera_id: int
    model: str
    width: int
    height: int
    params: np.ndarray

    pixel_offset = 0.5  # COLMAP pixel centres sit at (i + 0.5); ours at integers

    @property
    def focal(self) -> tuple[float, float]:
        """``(fx, fy)`` in pixels."""
        p = self.params
        if self.model in _ONE_FOCAL_MODELS:
            return float(p[0]), float(p[0])
        return float(p[0]), float(p[1])

    @property
    def principal_point(self) -> tuple[float, float]:
        """``(cx, cy)`` in COLMAP pixel coordinates."""
        p = self.params
        if self.model in _ONE_FOCAL_MODELS:
            return float(p[1]), float(p[2])
        return float(p[2]), float(p[3])

    def calibration_matrix(self) -> np.ndarray:
        """``(3, 3)`` pinhole matrix K (distortion not included), COLMAP pixel coordinates."""
        (fx, fy), (cx, cy) = self.focal, self.principal_point
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def distortion(self) -> np.ndarray:
        """The parameters after focal length and principal point (empty for pinholes)."""
        n = (
            3
            if self.model
            in (
                "SIMPLE_PINHOLE",
                "SIMPLE_RADIAL",
                "RADIAL",
                "SIMPLE_RADIAL_FISHEYE",
                "RADIAL_FISHEYE",
            )
            else 4
        )
        return np.asarray(self.params[n:], np.float64)


def qvec_to_rotmat(q) -> np.ndarray:
    """Rotation matrix of a quaternion ``(qw, qx, qy, qz)`` (normalised first)."""
    q = np.asarray(q, np.float64)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n == 0:
        raise ValueError(f"invalid quaternion {q}")
    w, x, y, z = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotmat_to_qvec(R) -> np.ndarray:
    """Unit quaternion ``(qw, qx, qy, qz)`` with ``qw >= 0`` of a rotation matrix.

    Shepperd's method: the largest of the four squared components is taken from the
    diagonal, the other three from the off-diagonal sums/differences.
    """
    R = np.asarray(R, np.float64)
    tr = np.trace(R)
    cands = np.array([1 + tr, 1 + 2 * R[0, 0] - tr, 1 + 2 * R[1, 1] - tr, 1 + 2 * R[2, 2] - tr])
    i = int(np.argmax(cands))
    s = 2.0 * np.sqrt(max(cands[i], 1e-300))
    if i == 0:
        q = [s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif i == 1:
        q = [(R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif i == 2:
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s]
    else:
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4]
    q = np.asarray(q) / np.linalg.norm(q)
    return -q if q[0] < 0 else q


@dataclasses.dataclass(frozen=True)
class ColmapImage:
    """One registered image (extrinsics and 2-D observations).

    Attributes:
        image_id: COLMAP id.
        qvec: ``(4,)`` world-to-camera rotation quaternion ``(qw, qx, qy, qz)``.
        tvec: ``(3,)`` world-to-camera translation.
        camera_id: id of its `ColmapCamera`.
        name: image file name.
        xys: ``(M, 2)`` observed keypoints in COLMAP pixel coordinates.
        point3d_ids: ``(M,)`` int64 id of the 3-D point of each keypoint (-1: none).
    """

    image_id: int
    qvec: np.ndarray
    tvec: np.ndarray
    camera_id: int
    name: str
    xys: np.ndarray
    point3d_ids: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        """``(3, 3)`` world-to-camera rotation R."""
        return qvec_to_rotmat(self.qvec)

    @property
    def centre(self) -> np.ndarray:
        """``(3,)`` camera centre in world coordinates, ``-Rᵀ t``."""
        return -self.rotation.T @ self.tvec


@dataclasses.dataclass(frozen=True)
class ColmapPoints:
    """The sparse 3-D points.

    Attributes:
        ids: ``(P,)`` int64 point ids.
        xyz: ``(P, 3)`` float64 world positions.
        rgb: ``(P, 3)`` uint8 colours.
        error: ``(P,)`` float64 reprojection errors (pixels).
        track_length: ``(P,)`` int64 number of observations.
        tracks: tuple of ``(L, 2)`` int64 arrays of ``(image_id, point2d_idx)`` per point.
    """

    ids: np.ndarray
    xyz: np.ndarray
    rgb: np.ndarray
    error: np.ndarray
    track_length: np.ndarray
    tracks: tuple

    def __len__(self) -> int:
        return int(self.ids.shape[0])


@dataclasses.dataclass(frozen=True)
class ColmapModel:
    """A sparse reconstruction: cameras, images and points."""

    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    points3d: ColmapPoints

    def image_by_name(self, name: str) -> ColmapImage:
        """The image called ``name``.

        Raises:
            KeyError: listing the available names.
        """
        for im in self.images.values():
            if im.name == name:
                return im
        raise KeyError(
            f"no image named {name!r}; have {sorted(i.name for i in self.images.values())}"
        )


def _data_lines(path: str):
    """Non-comment lines of a COLMAP text file, with their 1-based line numbers."""
    with open(path, encoding="utf-8") as f:
        for k, line in enumerate(f, 1):
            s = line.strip()
            if s and not s.startswith("#"):
                yield k, s


def _existing(path: str | os.PathLike, what: str) -> str:
    """``path`` as a string; FileNotFoundError naming the COLMAP file (``what``) if missing."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"COLMAP {what} file not found: {path}")
    return path


def _require(folder: str, name: str) -> str:
    path = os.path.join(folder, name)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"COLMAP text model file missing: {path}")
    return path


def _parse_error(path, lineno, what, line) -> ValueError:
    return ValueError(f"{path}:{lineno}: {what}: {line[:120]!r}")


def read_colmap_cameras(path: str | os.PathLike) -> dict[int, ColmapCamera]:
    """Parse ``cameras.txt``.

    Raises:
        FileNotFoundError: if the file is missing.
        ValueError: on an unknown model, a wrong parameter count or a malformed line.
    """
    path = _existing(path, "cameras")
    cams: dict[int, ColmapCamera] = {}
    for k, line in _data_lines(path):
        tok = line.split()
        if len(tok) < 4:
            raise _parse_error(path, k, "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...", line)
        model = tok[1]
        if model not in CAMERA_MODELS:
            raise _parse_error(path, k, f"unknown camera model {model!r}", line)
        try:
            cid, w, h = int(tok[0]), int(tok[2]), int(tok[3])
            params = np.array([float(t) for t in tok[4:]], np.float64)
        except ValueError as err:
            raise _parse_error(path, k, "not a number", line) from err
        if params.shape[0] != CAMERA_MODELS[model]:
            raise _parse_error(
                path,
                k,
                f"{model} needs {CAMERA_MODELS[model]} parameters, got {params.shape[0]}",
                line,
            )
        if w <= 0 or h <= 0:
            raise _parse_error(path, k, f"invalid image size {w}x{h}", line)
        cams[cid] = ColmapCamera(cid, model, w, h, params)
    return cams


def read_colmap_images(path: str | os.PathLike) -> dict[int, ColmapImage]:
    """Parse ``images.txt`` (two lines per image; the keypoint line may be empty).

    Raises:
        FileNotFoundError: if the file is missing.
        ValueError: on a malformed line.
    """
    path = _existing(path, "images")
    images: dict[int, ColmapImage] = {}
    with open(path, encoding="utf-8") as f:
        lines = [
            (k, ln.rstrip("\n")) for k, ln in enumerate(f, 1) if not ln.lstrip().startswith("#")
        ]
    # drop blank lines only where they cannot be an empty keypoint line
    i = 0
    while i < len(lines):
        k, head = lines[i]
        if not head.strip():
            i += 1
            continue
        tok = head.split()
        if len(tok) < 10:
            raise _parse_error(
                path, k, "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME", head
            )
        try:
            iid = int(tok[0])
            q = np.array([float(t) for t in tok[1:5]])
            t = np.array([float(v) for v in tok[5:8]])
            cid = int(tok[8])
        except ValueError as err:
            raise _parse_error(path, k, "not a number", head) from err
        name = " ".join(tok[9:])
        pts = lines[i + 1][1].split() if i + 1 < len(lines) else []
        if len(pts) % 3:
            raise _parse_error(
                path, lines[i + 1][0], "POINTS2D must be triples X Y POINT3D_ID", lines[i + 1][1]
            )
        try:
            arr = np.array([float(v) for v in pts], np.float64).reshape(-1, 3)
        except ValueError as err:
            raise _parse_error(path, lines[i + 1][0], "not a number", lines[i + 1][1]) from err
        images[iid] = ColmapImage(
            iid, q, t, cid, name, arr[:, :2].copy(), arr[:, 2].astype(np.int64)
        )
        i += 2
    return images


def read_colmap_points3d(path: str | os.PathLike) -> ColmapPoints:
    """Parse ``points3D.txt``.

    Raises:
        FileNotFoundError: if the file is missing.
        ValueError: on a malformed line.
    """
    path = _existing(path, "points")
    ids, xyz, rgb, err, tracks = [], [], [], [], []
    for k, line in _data_lines(path):
        tok = line.split()
        if len(tok) < 8 or (len(tok) - 8) % 2:
            raise _parse_error(path, k, "expected POINT3D_ID X Y Z R G B ERROR TRACK[]", line)
        try:
            ids.append(int(tok[0]))
            xyz.append([float(v) for v in tok[1:4]])
            rgb.append([int(v) for v in tok[4:7]])
            err.append(float(tok[7]))
            tracks.append(np.array([int(v) for v in tok[8:]], np.int64).reshape(-1, 2))
        except ValueError as e:
            raise _parse_error(path, k, "not a number", line) from e
    return ColmapPoints(
        ids=np.array(ids, np.int64),
        xyz=np.array(xyz, np.float64).reshape(-1, 3),
        rgb=np.array(rgb, np.uint8).reshape(-1, 3),
        error=np.array(err, np.float64),
        track_length=np.array([len(t) for t in tracks], np.int64),
        tracks=tuple(tracks),
    )


def read_colmap_text(folder: str | os.PathLike) -> ColmapModel:
    """Read a COLMAP text model folder (``cameras.txt``, ``images.txt``, ``points3D.txt``).

    Args:
        folder: the model folder (e.g. ``sparse/0`` after ``colmap model_converter
            --output_type TXT``).

    Returns:
        A `ColmapModel`.

    Raises:
        FileNotFoundError: if the folder or one of the three files is missing.
        ValueError: on malformed files, or images that reference unknown cameras.

    References:
        COLMAP documentation, "Output format"; thesis Sec. 7.2.2.
    """
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"COLMAP model folder not found: {folder}")
    paths = [_require(folder, n) for n in ("cameras.txt", "images.txt", "points3D.txt")]
    cams = read_colmap_cameras(paths[0])
    images = read_colmap_images(paths[1])
    points = read_colmap_points3d(paths[2])
    missing = sorted({im.camera_id for im in images.values()} - set(cams))
    if missing:
        raise ValueError(f"images.txt references cameras {missing} absent from cameras.txt")
    return ColmapModel(cameras=cams, images=images, points3d=points)


def write_colmap_text(model: ColmapModel, folder: str | os.PathLike) -> None:
    """Write a `ColmapModel` as COLMAP text files (round-trips with `read_colmap_text`).

    Args:
        model: the model.
        folder: output folder (created if needed).
    """
    folder = os.fspath(folder)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, "cameras.txt"), "w", encoding="utf-8") as f:
        f.write("# Camera list with one line of data per camera:\n")
        f.write("#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n")
        for c in model.cameras.values():
            ps = " ".join(repr(float(v)) for v in c.params)
            f.write(f"{c.camera_id} {c.model} {c.width} {c.height} {ps}\n")
    with open(os.path.join(folder, "images.txt"), "w", encoding="utf-8") as f:
        f.write("# Image list with two lines of data per image:\n")
        f.write("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n")
        f.write("#   POINTS2D[] as (X, Y, POINT3D_ID)\n")
        for im in model.images.values():
            q = " ".join(repr(float(v)) for v in im.qvec)
            t = " ".join(repr(float(v)) for v in im.tvec)
            f.write(f"{im.image_id} {q} {t} {im.camera_id} {im.name}\n")
            f.write(
                " ".join(
                    f"{x!r} {y!r} {int(p)}"
                    for (x, y), p in zip(im.xys.tolist(), im.point3d_ids.tolist(), strict=True)
                )
                + "\n"
            )
    with open(os.path.join(folder, "points3D.txt"), "w", encoding="utf-8") as f:
        f.write("# 3D point list with one line of data per point:\n")
        f.write("#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n")
        P = model.points3d
        for i in range(len(P)):
            x, y, z = (repr(float(v)) for v in P.xyz[i])
            r, g, b = (int(v) for v in P.rgb[i])
            tr = " ".join(f"{int(a)} {int(b_)}" for a, b_ in P.tracks[i].tolist())
            f.write(f"{int(P.ids[i])} {x} {y} {z} {r} {g} {b} {float(P.error[i])!r} {tr}\n")


# COLMAP's numeric camera model ids (``CameraModelId`` in colmap/sensor/models.h)
CAMERA_MODEL_IDS: dict[int, str] = {
    0: "SIMPLE_PINHOLE",
    1: "PINHOLE",
    2: "SIMPLE_RADIAL",
    3: "RADIAL",
    4: "OPENCV",
    5: "OPENCV_FISHEYE",
    6: "FULL_OPENCV",
    7: "FOV",
    8: "SIMPLE_RADIAL_FISHEYE",
    9: "RADIAL_FISHEYE",
    10: "THIN_PRISM_FISHEYE",
}
_MODEL_ID = {name: i for i, name in CAMERA_MODEL_IDS.items()}

_POINT2D = np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")])
_TRACK = np.dtype([("image_id", "<i4"), ("point2d_idx", "<i4")])


class _Reader:
    """Little-endian reads from a bytes buffer with error messages that name the file."""

    def __init__(self, path: str):
        self.path = path
        with open(path, "rb") as f:
            self.buf = f.read()
        self.pos = 0

    def take(self, n: int) -> bytes:
        if self.pos + n > len(self.buf):
            raise ValueError(
                f"{self.path}: truncated COLMAP binary file (needed {n} bytes at offset "
                f"{self.pos}, file has {len(self.buf)})"
            )
        out = self.buf[self.pos : self.pos + n]
        self.pos += n
        return out

    def unpack(self, fmt: str) -> tuple:
        return struct.unpack("<" + fmt, self.take(struct.calcsize("<" + fmt)))

    def array(self, dtype: np.dtype, count: int) -> np.ndarray:
        return np.frombuffer(self.take(dtype.itemsize * count), dtype=dtype, count=count)

    def name(self) -> str:
        end = self.buf.find(b"\x00", self.pos)
        if end < 0:
            raise ValueError(f"{self.path}: unterminated image name at offset {self.pos}")
        out = self.buf[self.pos : end].decode("utf-8")
        self.pos = end + 1
        return out

    def done(self) -> None:
        if self.pos != len(self.buf):
            raise ValueError(
                f"{self.path}: {len(self.buf) - self.pos} unexpected trailing bytes after the "
                "last record"
            )


def read_colmap_cameras_binary(path: str | os.PathLike) -> dict[int, ColmapCamera]:
    """Parse ``cameras.bin``.

    Layout (little-endian): ``uint64 count``; per camera ``int32 camera_id, int32 model_id,
    uint64 width, uint64 height, float64 params[P]`` (``P`` fixed by the model).

    Raises:
        FileNotFoundError: if the file is missing.
        ValueError: on an unknown model id, invalid size or a truncated file.
    """
    path = _existing(path, "cameras")
    r = _Reader(path)
    (count,) = r.unpack("Q")
    cams: dict[int, ColmapCamera] = {}
    for _ in range(count):
        cid, mid, w, h = r.unpack("iiQQ")
        if mid not in CAMERA_MODEL_IDS:
            raise ValueError(
                f"{path}: camera {cid} has unknown model id {mid}; known: {CAMERA_MODEL_IDS}"
            )
        model = CAMERA_MODEL_IDS[mid]
        params = np.array(r.unpack("d" * CAMERA_MODELS[model]), np.float64)
        if w <= 0 or h <= 0:
            raise ValueError(f"{path}: camera {cid} has invalid image size {w}x{h}")
        cams[cid] = ColmapCamera(cid, model, int(w), int(h), params)
    r.done()
    return cams


def read_colmap_images_binary(path: str | os.PathLike) -> dict[int, ColmapImage]:
    """Parse ``images.bin``.

    Layout (little-endian): ``uint64 count``; per image ``int32 image_id, float64 qvec[4],
    float64 tvec[3], int32 camera_id``, the NUL-terminated name, ``uint64 n`` and ``n``
    records ``float64 x, float64 y, int64 point3d_id``.

    Raises:
        FileNotFoundError: if the file is missing.
        ValueError: on a truncated or malformed file.
    """
    path = _existing(path, "images")
    r = _Reader(path)
    (count,) = r.unpack("Q")
    images: dict[int, ColmapImage] = {}
    for _ in range(count):
        rec = r.unpack("i7di")
        iid, q, t, cid = rec[0], np.array(rec[1:5]), np.array(rec[5:8]), rec[8]
        name = r.name()
        (n,) = r.unpack("Q")
        pts = r.array(_POINT2D, n)
        xys = np.stack([pts["x"], pts["y"]], axis=1).astype(np.float64)
        images[iid] = ColmapImage(iid, q, t, cid, name, xys, pts["id"].astype(np.int64))
    r.done()
    return images


def read_colmap_points3d_binary(path: str | os.PathLike) -> ColmapPoints:
    """Parse ``points3D.bin``.

    Layout (little-endian): ``uint64 count``; per point ``uint64 point3d_id, float64 xyz[3],
    uint8 rgb[3], float64 error, uint64 track_length`` and ``track_length`` records
    ``int32 image_id, int32 point2d_idx``.

    Raises:
        FileNotFoundError: if the file is missing.
        ValueError: on a truncated or malformed file.
    """
    path = _existing(path, "points")
    r = _Reader(path)
    (count,) = r.unpack("Q")
    ids = np.empty(count, np.int64)
    xyz = np.empty((count, 3), np.float64)
    rgb = np.empty((count, 3), np.uint8)
    err = np.empty(count, np.float64)
    tracks = []
    for k in range(count):
        rec = r.unpack("Q3d3Bd")
        ids[k], xyz[k], rgb[k], err[k] = rec[0], rec[1:4], rec[4:7], rec[7]
        (n,) = r.unpack("Q")
        tr = r.array(_TRACK, n)
        tracks.append(np.stack([tr["image_id"], tr["point2d_idx"]], axis=1).astype(np.int64))
    r.done()
    return ColmapPoints(
        ids=ids,
        xyz=xyz,
        rgb=rgb,
        error=err,
        track_length=np.array([len(t) for t in tracks], np.int64),
        tracks=tuple(tracks),
    )


def _check_cameras(model: ColmapModel, source: str) -> ColmapModel:
    missing = sorted({im.camera_id for im in model.images.values()} - set(model.cameras))
    if missing:
        raise ValueError(f"{source}: images reference cameras {missing} absent from the model")
    return model


def read_colmap_binary(folder: str | os.PathLike) -> ColmapModel:
    """Read a COLMAP binary model folder (``cameras.bin``, ``images.bin``, ``points3D.bin``).

    Args:
        folder: the model folder (e.g. ``sparse/0`` as written by ``colmap mapper``).

    Returns:
        A `ColmapModel` (the same numbers as `read_colmap_text` of the converted model).

    Raises:
        FileNotFoundError: if the folder or one of the three files is missing.
        ValueError: on malformed files, or images that reference unknown cameras.

    References:
        COLMAP documentation, "Output format" (binary models; ``read_write_model.py``);
        thesis Sec. 7.2.2.
    """
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"COLMAP model folder not found: {folder}")
    paths = [os.path.join(folder, n) for n in ("cameras.bin", "images.bin", "points3D.bin")]
    for p in paths:
        if not os.path.isfile(p):
            raise FileNotFoundError(f"COLMAP binary model file missing: {p}")
    model = ColmapModel(
        cameras=read_colmap_cameras_binary(paths[0]),
        images=read_colmap_images_binary(paths[1]),
        points3d=read_colmap_points3d_binary(paths[2]),
    )
    return _check_cameras(model, folder)


def write_colmap_binary(model: ColmapModel, folder: str | os.PathLike) -> None:
    """Write a `ColmapModel` as COLMAP binary files (round-trips with `read_colmap_binary`).

    Args:
        model: the model.
        folder: output folder (created if needed).

    Raises:
        ValueError: for a camera model without a COLMAP model id.
    """
    folder = os.fspath(folder)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, "cameras.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(model.cameras)))
        for c in model.cameras.values():
            if c.model not in _MODEL_ID:
                raise ValueError(f"camera model {c.model} has no COLMAP binary id")
            f.write(struct.pack("<iiQQ", c.camera_id, _MODEL_ID[c.model], c.width, c.height))
            f.write(np.asarray(c.params, "<f8").tobytes())
    with open(os.path.join(folder, "images.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(model.images)))
        for im in model.images.values():
            f.write(struct.pack("<i7di", im.image_id, *im.qvec, *im.tvec, im.camera_id))
            f.write(im.name.encode("utf-8") + b"\x00")
            pts = np.empty(len(im.point3d_ids), _POINT2D)
            pts["x"], pts["y"] = im.xys[:, 0], im.xys[:, 1]
            pts["id"] = im.point3d_ids
            f.write(struct.pack("<Q", len(pts)) + pts.tobytes())
    with open(os.path.join(folder, "points3D.bin"), "wb") as f:
        P = model.points3d
        f.write(struct.pack("<Q", len(P)))
        for i in range(len(P)):
            f.write(struct.pack("<Q3d3Bd", int(P.ids[i]), *P.xyz[i], *P.rgb[i], P.error[i]))
            tr = np.empty(len(P.tracks[i]), _TRACK)
            tr["image_id"], tr["point2d_idx"] = P.tracks[i][:, 0], P.tracks[i][:, 1]
            f.write(struct.pack("<Q", len(tr)) + tr.tobytes())


def read_colmap_model(folder: str | os.PathLike) -> ColmapModel:
    """Read a COLMAP model folder in either format: binary when ``cameras.bin``,
    ``images.bin`` and ``points3D.bin`` are all there, else text.

    Args:
        folder: the model folder.

    Returns:
        A `ColmapModel`.

    Raises:
        FileNotFoundError: if the folder holds neither a complete binary nor a complete text
            model (the message lists what is there).
        ValueError: on malformed files.

    References:
        COLMAP documentation, "Output format".
    """
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"COLMAP model folder not found: {folder}")
    names = ("cameras", "images", "points3D")
    if all(os.path.isfile(os.path.join(folder, n + ".bin")) for n in names):
        return read_colmap_binary(folder)
    if all(os.path.isfile(os.path.join(folder, n + ".txt")) for n in names):
        return read_colmap_text(folder)
    raise FileNotFoundError(
        f"{folder} is not a COLMAP model: need cameras, images and points3D as .bin or .txt; "
        f"found {sorted(os.listdir(folder))}"
    )
