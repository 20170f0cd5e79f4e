"""`mvedge superpixels` on a real light field (HCI backgammon, reduced): every output."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from mvedge_jax.cli import main


@pytest.fixture(scope="module")
def backgammon(data_dir):
    return str(data_dir / "hci4d" / "stratified" / "backgammon")


@pytest.fixture(scope="module")
def sp_run(backgammon, tmp_path_factory):
    out = tmp_path_factory.mktemp("sp") / "out"
    args = [
        "superpixels", backgammon, "--views", "5", "--scale", "0.125", "--size", "8",
        "--seed-candidates", "2", "--out", str(out),
    ]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    return out, res.output


def test_superpixels_cli_writes_every_output(sp_run):
    out, output = sp_run
    U = V = 5
    H = W = 64
    with np.load(out / "labels.npz") as f:
        labels, disparity = f["labels"], f["disparity"]
    assert labels.shape == (U, V, H, W) and labels.dtype == np.int32
    assert disparity.shape == (U, V, H, W) and np.isfinite(disparity).all()
    assert (labels >= 0).all()
    assert len(list((out / "views").glob("*.png"))) == U * V
    for png in ("labels_centre.png", "sweep.png", "views/02_02.png"):
        img = cv2.imread(str(out / png))
        assert img is not None and img.size > 0, png
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["seed_candidates"] == 2
    assert metrics["dense_disparity"] is True
    assert metrics["grid"] == [U, V] and metrics["size_px"] == [H, W]
    assert metrics["n_labels_used"] == np.unique(labels).size
    # backgammon has a centre-view ground truth: the view-consistency metrics are there
    assert 0 < metrics["self_similarity_error"] < 5
    assert 1 <= metrics["labels_per_pixel"] < 2
    assert 0 < metrics["compactness"] <= 1
    assert "wrote" in output


def test_superpixels_cli_keeps_an_existing_folder(sp_run, backgammon):
    out, _ = sp_run
    before = (out / "metrics.json").read_bytes()
    res = CliRunner().invoke(
        main, ["superpixels", backgammon, "--views", "5", "--scale", "0.125", "--out", str(out)]
    )
    assert res.exit_code != 0
    assert "--force" in res.output
    assert (out / "metrics.json").read_bytes() == before


def test_superpixels_cli_rejects_bad_seed_candidates(backgammon, tmp_path):
    res = CliRunner().invoke(
        main, ["superpixels", backgammon, "--seed-candidates", "9", "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 2
    assert "seed-candidates" in res.output
    assert not (tmp_path / "o").exists()
