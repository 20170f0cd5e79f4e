"""`mvedge eval`, batch `mvedge depth` (folders, globs, summary, field formats, progress) and
the message for a missing JAX platform.

Batch runs replace the pipeline by the ground truth plus noise (`fake_result`): the plumbing
is under test here, the pipeline in test_pipeline.py."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_outputs import fake_result

import mvedge_jax.pipeline as pipeline
from mvedge_jax.cli import evaluate_disparity, main
from mvedge_jax.io import read_pfm, write_pfm
from mvedge_jax.metrics import depth_metrics

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def fake_pipeline(monkeypatch):
    """`estimate_disparity` → GT + noise, reporting every stage like the real driver."""

    def estimate(lf, config=None, *, key=None, progress=None):
        for stage in pipeline.STAGES:
            for event in ("compile", "run", "done"):
                if progress:
                    progress(stage, event)
        return fake_result(lf)

    monkeypatch.setattr(pipeline, "estimate_disparity", estimate)


def test_eval_both_protocols(tmp_path):
    rng = np.random.default_rng(1)
    gt = rng.uniform(-1, 1, (64, 64)).astype(np.float32)
    pred = gt.copy()
    pred[:5] += 0.5  # errors only inside the 15-px border
    pred[40, 40] = np.nan
    write_pfm(tmp_path / "gt.pfm", gt)
    np.save(tmp_path / "pred.npy", pred)
    res = CliRunner().invoke(
        main, ["eval", str(tmp_path / "pred.npy"), str(tmp_path / "gt.pfm"), "--json"]
    )
    assert res.exit_code == 0, res.output
    scores = json.loads(res.stdout)
    assert scores["hci_protocol"]["mse_x100"] == pytest.approx(0.0, abs=1e-9)
    ok = np.isfinite(pred)
    want = depth_metrics(np.where(ok, pred, 0), gt, ok)
    assert scores["full_frame"]["mse_x100"] == pytest.approx(want["mse_x100"], rel=1e-5)
    assert scores["full_frame"]["badpix_0.07"] == pytest.approx(100 * 5 * 64 / (64 * 64 - 1))
    assert scores["pixels"] == {"full_frame": 64 * 64 - 1, "hci_protocol": 34 * 34 - 1}
    assert scores["invalid_prediction_pixels"] == 1
    table = CliRunner().invoke(main, ["eval", str(tmp_path / "pred.npy"), str(tmp_path / "gt.pfm")])
    assert table.exit_code == 0 and "HCI (border 15)" in table.output and "mse_x100" in table.output


def test_eval_reads_the_disparity_npz_of_mvedge_depth(tmp_path):
    d = np.zeros((3, 3, 40, 40), np.float32)
    d[1, 1] = 0.25
    np.savez(tmp_path / "disparity.npz", disparity=d)
    np.save(tmp_path / "gt.npy", np.zeros((40, 40), np.float32))
    s = evaluate_disparity(np.full((40, 40), 0.25, np.float32), np.zeros((40, 40)), border=2)
    res = CliRunner().invoke(
        main,
        [
            "eval",
            str(tmp_path / "disparity.npz"),
            str(tmp_path / "gt.npy"),
            "--json",
            "--border",
            "2",
        ],
    )
    assert res.exit_code == 0, res.output
    assert (
        json.loads(res.stdout)["hci_protocol"]["mse_x100"]
        == pytest.approx(s["hci_protocol"]["mse_x100"])
        == pytest.approx(100 * 0.25**2)
    )


def test_eval_against_a_light_field_folder(data_dir):
    folder = data_dir / "hci4d" / "stratified" / "backgammon"
    res = CliRunner().invoke(
        main, ["eval", str(folder / "gt_disp_lowres.pfm"), str(folder), "--json"]
    )
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["full_frame"]["mse_x100"] == 0.0


@pytest.mark.parametrize(
    ("pred", "message"),
    [
        ("missing.pfm", "not found"),
        ("pred.txt", "unknown disparity format"),
        ("small.npy", "shape"),
    ],
)
def test_eval_bad_input(tmp_path, pred, message):
    (tmp_path / "pred.txt").write_text("1 2 3")
    np.save(tmp_path / "small.npy", np.zeros((10, 10)))
    np.save(tmp_path / "gt.npy", np.zeros((20, 20)))
    res = CliRunner().invoke(main, ["eval", str(tmp_path / pred), str(tmp_path / "gt.npy")])
    assert res.exit_code != 0 and message in res.output


def test_batch_depth_over_a_glob_with_summary_and_formats(data_dir, tmp_path, fake_pipeline):
    pattern = str(data_dir / "hci4d" / "*" / "[ab]*")  # antinous and backgammon
    out = tmp_path / "runs"
    args = ["depth", pattern, "--views", "3x3", "--scale", "0.125", "--out", str(out)]
    res = CliRunner().invoke(main, [*args, "--format", "hci", "--depth", "--ply"])
    assert res.exit_code == 0, res.output
    assert "device: " in res.output and "100%" in res.output
    for scene in ("antinous", "backgammon"):
        m = json.loads((out / scene / "metrics.json").read_text())
        assert m["provenance"]["scale"] == 0.125 and m["scene"] == scene
        assert m["provenance"]["seconds_load"] > 0
        for f in ("centre_disparity.png", "centre_view.ply", f"disp_maps/{scene}.pfm"):
            assert (out / scene / f).is_file(), f
        np.testing.assert_array_equal(
            read_pfm(out / "summary" / "disp_maps" / f"{scene}.pfm"),
            read_pfm(out / scene / "disp_maps" / f"{scene}.pfm"),
        )
        assert (out / "summary" / "runtimes" / f"{scene}.txt").is_file()
    with open(out / "summary" / "scenes.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["scene"] for r in rows] == ["antinous", "backgammon"]
    assert all(r["status"] == "ok" and 0 < float(r["mse_x100"]) < 1 for r in rows)
    again = CliRunner().invoke(main, args)  # outputs exist: refused before any work
    assert again.exit_code != 0 and "--force" in again.output


def test_batch_reports_a_failed_scene_and_keeps_the_others(data_dir, tmp_path, fake_pipeline):
    good = data_dir / "hci4d" / "stratified" / "backgammon"
    res = CliRunner().invoke(
        main,
        [
            "depth",
            str(good),
            str(tmp_path / "nothing_here"),
            "--scale",
            "0.125",
            "--views",
            "3",
            "--out",
            str(tmp_path / "o"),
        ],
    )
    assert res.exit_code != 0 and "1 of 2 scenes failed" in res.output
    assert (tmp_path / "o" / "backgammon" / "metrics.json").is_file()
    rows = (tmp_path / "o" / "summary" / "scenes.csv").read_text()
    assert "failed" in rows and "nothing_here" in rows


def test_depth_without_a_camera_is_refused(data_dir, tmp_path):
    res = CliRunner().invoke(
        main,
        [
            "depth",
            str(data_dir / "hci_old" / "stillLife_lf_3x3"),
            "--ply",
            "--out",
            str(tmp_path / "o"),
        ],
    )
    assert res.exit_code != 0 and "parameters.cfg" in res.output
    assert not (tmp_path / "o").exists()


def test_missing_platform_gives_a_clear_message(tmp_path):
    env = {**os.environ, "JAX_PLATFORMS": "cuda", "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "mvedge_jax.cli", "demo", "--out", str(tmp_path / "o")],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    if proc.returncode == 0:  # a CUDA machine: the run must then say it used the GPU
        assert "cuda" in (proc.stdout + proc.stderr).lower(), proc.stdout[-2000:]
        return
    assert "JAX_PLATFORMS='cuda'" in proc.stderr and '".[cuda]"' in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
