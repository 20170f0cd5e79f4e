"""COLMAP text models (io/_colmap.py) and sparse depth for a reference view (Sec. 7.2.2),
on a synthetic multi-view scene ray-traced with known pinhole cameras."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.diff import (
    ModelConfig,
    RenderConfig,
    initial_params,
    intrinsics,
    predict,
    project_points,
    relative_pose,
    sparse_depth_points,
    warp_by_depth,
)
from mvedge_jax.io._colmap import (
    ColmapCamera,
    ColmapImage,
    ColmapModel,
    ColmapPoints,
    qvec_to_rotmat,
    read_colmap_binary,
    read_colmap_cameras,
    read_colmap_cameras_binary,
    read_colmap_model,
    read_colmap_text,
    rotmat_to_qvec,
    write_colmap_binary,
    write_colmap_text,
)

H, W, F = 48, 64, 60.0
FG_Z, BG_Z = 6.0, 10.0
FG_BOX = (-1.2, 0.3, -0.7, 0.9)  # x0, x1, y0, y1 of the near rectangle (world)


def _rot_y(deg):
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def _tex(X, Y, fg):
    if fg:
        return np.stack(
            [0.5 + 0.4 * np.sin(7 * X), 0.3 + 0.3 * np.cos(5 * Y), 0.6 + 0.2 * np.sin(3 * (X + Y))],
            -1,
        )
    return np.stack(
        [
            0.4 + 0.3 * np.sin(3 * X + 2 * Y),
            0.5 + 0.35 * np.sin(4 * Y),
            0.5 + 0.3 * np.cos(2.5 * X),
        ],
        -1,
    )


def _render(R, t):
    """Ray-trace one view (pixel centres at integers): colour and camera-space depth."""
    K = np.array([[F, 0, W / 2 - 0.5], [0, F, H / 2 - 0.5], [0, 0, 1.0]])
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    d_cam = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.linalg.inv(K).T
    d_w = d_cam @ R  # Rᵀ d
    C = -R.T @ t
    s_bg = (BG_Z - C[2]) / d_w[..., 2]
    s_fg = (FG_Z - C[2]) / d_w[..., 2]
    P_bg = C + s_bg[..., None] * d_w
    P_fg = C + s_fg[..., None] * d_w
    x0, x1, y0, y1 = FG_BOX
    hit = (P_fg[..., 0] > x0) & (P_fg[..., 0] < x1) & (P_fg[..., 1] > y0) & (P_fg[..., 1] < y1)
    col = np.where(
        hit[..., None],
        _tex(P_fg[..., 0], P_fg[..., 1], True),
        _tex(P_bg[..., 0], P_bg[..., 1], False),
    )
    P = np.where(hit[..., None], P_fg, P_bg)
    depth = (P @ R.T + t)[..., 2]
    return col.astype(np.float32), depth


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    poses = [
        (np.eye(3), np.zeros(3)),
        (_rot_y(2.0), np.array([-0.6, 0.0, 0.0])),
        (_rot_y(-2.0), np.array([0.6, 0.05, 0.0])),
        (np.eye(3), np.array([0.0, -0.5, 0.1])),
    ]
    views = [_render(R, t) for R, t in poses]
    # sparse 3-D points on both surfaces
    rng = np.random.default_rng(0)
    x0, x1, y0, y1 = FG_BOX
    fg = np.stack(
        [
            rng.uniform(x0 + 0.05, x1 - 0.05, 80),
            rng.uniform(y0 + 0.05, y1 - 0.05, 80),
            np.full(80, FG_Z),
        ],
        1,
    )
    bg = np.stack([rng.uniform(-3, 3, 250), rng.uniform(-2.2, 2.2, 250), np.full(250, BG_Z)], 1)
    xyz = np.concatenate([fg, bg])
    cam = ColmapCamera(1, "PINHOLE", W, H, np.array([F, F, W / 2, H / 2]))
    obs = {i: [] for i in range(len(poses))}
    tracks = [[] for _ in range(len(xyz))]
    for i, (R, t) in enumerate(poses):
        im = ColmapImage(
            i + 1, rotmat_to_qvec(R), t, 1, f"v{i}.png", np.zeros((0, 2)), np.zeros(0, np.int64)
        )
        pos, z = project_points(xyz, cam, im)
        xi, yi = np.round(pos[:, 0]).astype(int), np.round(pos[:, 1]).astype(int)
        inside = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H) & (z > 0)
        for p in np.flatnonzero(inside):
            if abs(views[i][1][yi[p], xi[p]] - z[p]) < 1e-3 * z[p] + 1e-2:  # visible
                tracks[p].append((i + 1, len(obs[i])))
                obs[i].append((pos[p, 0] + 0.5, pos[p, 1] + 0.5, p + 1))
    keep = [p for p in range(len(xyz)) if len(tracks[p]) >= 1]
    images = {}
    for i, (R, t) in enumerate(poses):
        o = np.array(obs[i]).reshape(-1, 3)
        images[i + 1] = ColmapImage(
            i + 1, rotmat_to_qvec(R), t, 1, f"v{i}.png", o[:, :2], o[:, 2].astype(np.int64)
        )
    pts = ColmapPoints(
        ids=np.array([p + 1 for p in keep]),
        xyz=xyz[keep],
        rgb=np.full((len(keep), 3), 128, np.uint8),
        error=np.full(len(keep), 0.5),
        track_length=np.array([len(tracks[p]) for p in keep]),
        tracks=tuple(np.array(tracks[p], np.int64).reshape(-1, 2) for p in keep),
    )
    folder = tmp_path_factory.mktemp("colmap")
    write_colmap_text(ColmapModel({1: cam}, images, pts), folder)
    return folder, views, poses


def test_read_roundtrip_and_geometry(scene):
    folder, views, poses = scene
    model = read_colmap_text(folder)
    assert set(model.images) == {1, 2, 3, 4} and model.cameras[1].model == "PINHOLE"
    im = model.images[2]
    np.testing.assert_allclose(im.rotation, poses[1][0], atol=1e-9)
    np.testing.assert_allclose(im.tvec, poses[1][1], atol=1e-12)
    assert len(model.points3d) > 200 and model.points3d.xyz.shape[1] == 3
    # every observation reprojects onto its keypoint (COLMAP coordinates)
    P = model.points3d
    for k in range(len(im.xys)):
        pid = im.point3d_ids[k]
        xyz = P.xyz[np.flatnonzero(P.ids == pid)[0]]
        pos, _ = project_points(xyz[None], model.cameras[1], im)
        np.testing.assert_allclose(pos[0] + 0.5, im.xys[k], atol=1e-6)


def test_sparse_depth_matches_the_rendered_depth(scene):
    folder, views, _ = scene
    model = read_colmap_text(folder)
    sd = sparse_depth_points(model, "v0.png", observed_only=True, min_track_length=2)
    assert sd.shape == (H, W) and sd.position.shape[0] > 100
    pos = np.asarray(sd.position)
    xi, yi = np.round(pos[:, 0]).astype(int), np.round(pos[:, 1]).astype(int)
    gt = views[0][1][yi, xi]
    np.testing.assert_allclose(np.asarray(sd.depth), gt, rtol=1e-4)
    assert set(np.round(np.asarray(sd.depth), 3)) <= {FG_Z, BG_Z}
    # all points (also those hidden in v0) project in front of the camera, inside the image
    every = sparse_depth_points(model, 1, min_track_length=1)
    assert every.position.shape[0] >= sd.position.shape[0]


def test_diffused_sparse_depth_approximates_the_dense_depth(scene):
    folder, views, _ = scene
    model = read_colmap_text(folder)
    sd = sparse_depth_points(model, "v0.png", observed_only=True)
    img, depth = views[0]
    cfg = ModelConfig(render=RenderConfig(nearer="larger"), q_scale=0.0)
    p = initial_params(sd.position, sd.inverse_depth, img, cfg)
    inv = np.asarray(eqx.filter_jit(predict)(p, cfg).disparity)
    err = np.abs(1.0 / inv - depth)
    # away from the occlusion boundary the plane depths are recovered
    assert np.median(err) < 0.05 and np.mean(err < 0.5) > 0.9


def test_warp_by_depth_reproduces_the_reference_view(scene):
    folder, views, _ = scene
    model = read_colmap_text(folder)
    ref, src = model.images[1], model.images[2]
    K = intrinsics(model.cameras[1])
    R, t = relative_pose(ref, src)
    warped, valid = warp_by_depth(jnp.asarray(views[1][0]), jnp.asarray(views[0][1]), K, K, R, t)
    err = np.abs(np.asarray(warped) - views[0][0]).mean(-1)
    v = np.asarray(valid) > 0
    assert v.mean() > 0.7
    assert np.median(err[v]) < 0.01 and np.mean(err[v] < 0.05) > 0.9


def test_bad_colmap_files(tmp_path):
    p = tmp_path / "cameras.txt"
    p.write_text("# comment\n1 SIMPLE_PINHOLE 10 8 5.0 5.0 4.0\n2 OPENCV 10 8 1 2 3 4 0 0 0 0\n")
    cams = read_colmap_cameras(p)
    assert cams[1].focal == (5.0, 5.0) and cams[2].principal_point == (3.0, 4.0)
    p.write_text("1 PINHOLE 10 8 5.0 5.0 4.0\n")
    with pytest.raises(ValueError, match="PINHOLE needs 4"):
        read_colmap_cameras(p)
    p.write_text("1 WEIRD 10 8 5.0\n")
    with pytest.raises(ValueError, match="unknown camera model"):
        read_colmap_cameras(p)
    with pytest.raises(FileNotFoundError, match="images.txt"):
        read_colmap_text(tmp_path)
    with pytest.raises(FileNotFoundError):
        read_colmap_text(tmp_path / "nope")
    R = qvec_to_rotmat(rotmat_to_qvec(_rot_y(30.0)))
    np.testing.assert_allclose(R, _rot_y(30.0), atol=1e-12)


def _assert_same_model(a: ColmapModel, b: ColmapModel) -> None:
    assert a.cameras.keys() == b.cameras.keys() and a.images.keys() == b.images.keys()
    for k, c in a.cameras.items():
        d = b.cameras[k]
        assert (c.model, c.width, c.height) == (d.model, d.width, d.height)
        np.testing.assert_array_equal(c.params, d.params)
    for k, im in a.images.items():
        jm = b.images[k]
        assert (im.name, im.camera_id) == (jm.name, jm.camera_id)
        np.testing.assert_array_equal(im.qvec, jm.qvec)
        np.testing.assert_array_equal(im.tvec, jm.tvec)
        np.testing.assert_array_equal(im.xys, jm.xys)
        np.testing.assert_array_equal(im.point3d_ids, jm.point3d_ids)
    P, Q = a.points3d, b.points3d
    for f in ("ids", "xyz", "rgb", "error", "track_length"):
        np.testing.assert_array_equal(getattr(P, f), getattr(Q, f))
    for s, t in zip(P.tracks, Q.tracks, strict=True):
        np.testing.assert_array_equal(s, t)


def test_binary_model_round_trips_and_matches_text(scene, tmp_path):
    folder, _, _ = scene
    text = read_colmap_text(folder)
    write_colmap_binary(text, tmp_path / "bin")
    assert sorted(p.name for p in (tmp_path / "bin").iterdir()) == [
        "cameras.bin",
        "images.bin",
        "points3D.bin",
    ]
    binary = read_colmap_binary(tmp_path / "bin")
    _assert_same_model(text, binary)
    _assert_same_model(text, read_colmap_model(tmp_path / "bin"))
    _assert_same_model(text, read_colmap_model(folder))  # text folder
    # the first bytes are COLMAP's: uint64 count, then int32 id, int32 model id 1 (PINHOLE)
    raw = (tmp_path / "bin" / "cameras.bin").read_bytes()
    assert raw[:8] == (1).to_bytes(8, "little") and raw[12:16] == (1).to_bytes(4, "little")


def test_bad_binary_models(scene, tmp_path):
    folder, _, _ = scene
    write_colmap_binary(read_colmap_text(folder), tmp_path)
    cams = tmp_path / "cameras.bin"
    raw = cams.read_bytes()
    cams.write_bytes(raw[:-4])
    with pytest.raises(ValueError, match="truncated"):
        read_colmap_cameras_binary(cams)
    cams.write_bytes(raw + b"xx")
    with pytest.raises(ValueError, match="trailing bytes"):
        read_colmap_cameras_binary(cams)
    cams.write_bytes(raw[:12] + (99).to_bytes(4, "little") + raw[16:])
    with pytest.raises(ValueError, match="unknown model id 99"):
        read_colmap_cameras_binary(cams)
    (tmp_path / "points3D.bin").unlink()
    with pytest.raises(FileNotFoundError, match="points3D.bin"):
        read_colmap_binary(tmp_path)
    with pytest.raises(FileNotFoundError, match="not a COLMAP model"):
        read_colmap_model(tmp_path)
