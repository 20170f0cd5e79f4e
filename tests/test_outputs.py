"""`write_outputs` and the field formats: figures, strict provenance, the HCI submission
layout, metric depth and the PLY point cloud, each read back (round trips).

The pipeline itself is not run here (test_pipeline.py does): a `Result` is built from the
ground truth plus known noise, so these tests take seconds."""

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest
from PIL import Image
from plyfile import PlyData

from mvedge_jax.edges import HORIZONTAL, VERTICAL, EdgeSet
from mvedge_jax.io import (
    HciCamera,
    OutputWriter,
    depth_to_points,
    disparity_to_depth,
    load_light_field_with_info,
    read_hci_camera,
    read_pfm,
    write_ply,
)
from mvedge_jax.pipeline import (
    FIGURES,
    PipelineConfig,
    Result,
    config_to_json,
    provenance,
    strict_json,
    write_outputs,
)


def fake_result(lf, noise: float = 0.02, seed: int = 0) -> Result:
    """The ground truth plus Gaussian noise, with a few edge points on the centre EPIs."""
    gt = np.asarray(lf.gt_disparity)
    rng = np.random.default_rng(seed)
    disp = (gt + rng.normal(0, noise, gt.shape)).astype(np.float32)
    H, W = lf.size
    n = 8
    xs = np.linspace(4, W - 5, n).astype(np.float32)
    d = np.linspace(-1, 1, n).astype(np.float32)
    A = lf.grid[1]
    edges = EdgeSet(
        x=jnp.asarray(np.concatenate([xs, np.full(n, W // 2, np.float32)])),
        y=jnp.asarray(np.concatenate([np.full(n, H // 2, np.float32), xs])),
        disparity=jnp.asarray(np.tile(d, 2)),
        confidence=jnp.ones(2 * n, jnp.float32),
        visible=jnp.ones(2 * n, bool),
        lab=jnp.zeros((2 * n, 3), jnp.float32),
        direction=jnp.asarray([HORIZONTAL] * n + [VERTICAL] * n, jnp.int32),
        # positions on the first and last angular rows: x - dc·d with dc = ∓(A // 2)
        intercepts=jnp.asarray(
            np.stack([np.tile(xs + A // 2 * d, 2), np.tile(xs - A // 2 * d, 2)], axis=1)
        ),
        valid=jnp.ones(2 * n, bool),
        n_dropped=jnp.zeros((), jnp.int32),
    )
    return Result(
        disparity=jnp.asarray(disp),
        edges=edges,
        surface=None,
        reconstruction=None,
        seconds_per_stage={"edges": 0.5, "surface": 0.25, "reconstruct": 1.0},
        compile_seconds=3.0,
    )


@pytest.fixture(scope="module")
def backgammon_small(data_dir):
    path = data_dir / "hci4d" / "stratified" / "backgammon"
    lf, info = load_light_field_with_info(path, views=(3, 3), scale=0.125)
    return lf, info, read_hci_camera(path)


@pytest.fixture(scope="module")
def written(backgammon_small, tmp_path_factory):
    lf, info, camera = backgammon_small
    out = tmp_path_factory.mktemp("outputs") / "backgammon"
    writer = OutputWriter(out)
    prov = provenance(lf, PipelineConfig(), seed=7, scale=info.scale, window=info.window)
    metrics = write_outputs(
        writer,
        lf,
        fake_result(lf),
        seconds_total=12.5,
        provenance=prov,
        hci=True,
        camera=camera,
        depth=True,
        ply=True,
    )
    writer.commit()
    return out, lf, camera, metrics


def test_every_figure_has_a_colour_bar_range_and_units(written):
    out, *_ = written
    for name in (*FIGURES, "error_map.png", "badpix_0.07.png", "centre_depth.png"):
        text = Image.open(out / name).text
        lo, hi = float(text["vmin"]), float(text["vmax"])
        assert lo < hi and "[" in text["units"], (name, text)
        assert len(text["colorbar_bbox"].split()) == 4
    epi = Image.open(out / "epi_horizontal.png").text["Title"]
    assert "pixel row y = 32" in epi and "centre row of views (u = 1)" in epi
    assert "pixel column x = 32" in Image.open(out / "epi_vertical.png").text["Title"]
    disp = Image.open(out / "centre_disparity.png").text
    mosaic = Image.open(out / "mosaic.png").text
    assert (disp["vmin"], disp["vmax"], disp["colormap"]) == (
        mosaic["vmin"],
        mosaic["vmax"],
        mosaic["colormap"],
    )  # one colour scale for disparity across the outputs


def test_metrics_json_is_strict_and_has_provenance(written):
    out, lf, _, metrics = written
    text = (out / "metrics.json").read_text()
    m = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON: {c}"))
    p = m["provenance"]
    assert p["input"] == lf.source and p["scene"] == "backgammon"
    assert p["views"]["grid"] == [3, 3] and p["views"]["mask"] == ["###"] * 3
    assert p["views"]["window_of_file_grid"] == [3, 3, 3, 3]
    assert p["scale"] == 0.125 and "scaled by 0.125" in p["units"]
    assert p["seed"] == 7 and p["mvedge_jax_version"] and p["jax_version"]
    assert p["backend"] == "cpu" and p["device"]
    assert p["deterministic"] is True  # CPU runs always are
    cfg = p["config"]
    assert cfg["_type"] == "PipelineConfig"
    assert set(cfg) >= {"edges", "surface", "reconstruct", "optimize"}
    assert cfg["reconstruct"]["_type"] == "ReconstructConfig"
    assert cfg["reconstruct"]["centre"]["_type"] == "CentreConfig"
    assert m["seconds_total"] == 12.5 and m["seconds_per_stage"]["reconstruct"] == 1.0
    assert m["seconds_write"] > 0
    # noise 0.02 px: MSE×100 ≈ 100 · 0.02² = 0.04
    assert m["mse_x100"] == pytest.approx(0.04, rel=0.25)


def test_hci_layout_round_trip(written):
    out, lf, _, metrics = written
    rc, cc = lf.centre_index
    centre = read_pfm(out / "disp_maps" / "backgammon.pfm")
    saved = read_pfm(out / "disparity" / f"view_{rc:02d}_{cc:02d}.pfm")
    np.testing.assert_array_equal(centre, saved)
    runtime = float((out / "runtimes" / "backgammon.txt").read_text())
    assert runtime == pytest.approx(1.75) == metrics["hci_runtime_seconds"]


def test_depth_round_trip(written):
    out, lf, camera, _ = written
    rc, cc = lf.centre_index
    disp = read_pfm(out / "disparity" / f"view_{rc:02d}_{cc:02d}.pfm")
    depth = read_pfm(out / "depth" / f"view_{rc:02d}_{cc:02d}.pfm")
    # the toolkit's inverse, depth2disp, at the scaled resolution gives the disparity back
    f = camera.baseline_mm / 1000 * camera.focal_length_mm * max(lf.size)
    back = (f * camera.focus_distance_m / depth - f) / camera.focus_distance_m
    back /= camera.sensor_size_mm
    np.testing.assert_allclose(back, disp, atol=2e-4)
    assert 8.0 < float(np.median(depth)) < 16.0  # backgammon lies ~10 m from the camera


def test_ply_round_trip(written):
    out, lf, camera, metrics = written
    ply = PlyData.read(str(out / "centre_view.ply"))
    v = ply["vertex"]
    H, W = lf.size
    assert v.count == metrics["ply_points"] == H * W
    rgb = np.stack([v["red"], v["green"], v["blue"]], -1).reshape(H, W, 3)
    want = np.round(np.clip(np.asarray(lf.centre_view), 0, 1) * 255)
    np.testing.assert_array_equal(rgb, want.astype(np.uint8))
    z = np.asarray(v["z"]).reshape(H, W)
    depth = read_pfm(out / "depth" / "view_01_01.pfm")
    np.testing.assert_allclose(-z, depth * 1000.0, rtol=1e-5)


def test_camera_of_backgammon(data_dir):
    cam = read_hci_camera(data_dir / "hci4d" / "stratified" / "backgammon")
    assert cam == HciCamera(100.0, 35.0, 30.0, pytest.approx(8.3), (512, 512))
    assert read_hci_camera(data_dir / "hci_old" / "stillLife_lf_3x3") is None


def test_disparity_to_depth_relation():
    cam = HciCamera(100.0, 35.0, 30.0, 8.3, (512, 512))
    d = np.zeros((512, 512))
    d[0, 1], d[1, 0], d[1, 1], d[2, 2] = -1.7, 1.0, np.nan, -20.0
    z = disparity_to_depth(d, cam)
    assert z[0, 0] == pytest.approx(8.3)  # zero disparity: the focus plane
    want = 1 / (35_000 * -1.7 / (30 * 100 * 512) + 1 / 8.3)  # ≈ 12.2 m
    assert z[0, 1] == pytest.approx(want, rel=1e-6)
    assert z[0, 1] > z[0, 0] > z[1, 0]  # larger disparity is nearer
    assert math.isnan(z[1, 1]) and math.isnan(z[2, 2])  # NaN in; beyond infinity
    # a map scaled by s has disparity and size scaled by s: the same depth
    full = np.full((64, 64), -0.1)
    half = np.full((32, 32), -0.05)
    z_full, z_half = disparity_to_depth(full, cam), disparity_to_depth(half, cam)
    assert np.isfinite(z_full).all()
    np.testing.assert_allclose(z_full[:32, :32], z_half, rtol=1e-6)
    with pytest.raises(ValueError, match="expects"):
        disparity_to_depth(np.zeros(3), cam)


def test_write_ply_drops_nan_points(tmp_path):
    cam = HciCamera(100.0, 35.0, 30.0, 8.3, (4, 4))
    depth = np.full((4, 4), 2.0, np.float32)
    depth[0, 0] = np.nan
    pts = depth_to_points(depth, cam)
    assert pts[1, 0, 0] < 0 < pts[1, 3, 0] and pts[0, 1, 1] > 0 > pts[3, 1, 1]
    n = write_ply(tmp_path / "p.ply", pts, np.zeros((4, 4, 3), np.uint8))
    assert n == 15 == PlyData.read(str(tmp_path / "p.ply"))["vertex"].count
    with pytest.raises(ValueError, match="one shape"):
        write_ply(tmp_path / "q.ply", pts, np.zeros((4, 3, 3), np.uint8))


def test_depth_and_ply_need_a_camera(backgammon_small, tmp_path):
    lf, _, _ = backgammon_small
    writer = OutputWriter(tmp_path / "o")
    with pytest.raises(ValueError, match="parameters.cfg"):
        write_outputs(writer, lf, fake_result(lf), seconds_total=1.0, ply=True)
    writer.abort()


def test_config_to_json_and_strict_json():
    cfg = config_to_json(PipelineConfig())
    json.dumps(cfg, allow_nan=False)
    assert cfg["surface"]["_type"] == "SurfaceConfig"
    assert config_to_json(jnp.asarray(2.5)) == 2.5 and config_to_json(float("inf")) == "inf"
    assert config_to_json((np.float32(1.0), jnp.arange(2))) == [1.0, [0, 1]]
    assert strict_json({"a": float("nan"), "b": [np.float32(1.5), np.int64(2)]}) == {
        "a": None,
        "b": [1.5, 2],
    }
