"""Output folder checks and the all-or-nothing output writer."""

import json

import numpy as np
import pytest

from mvedge_jax.io import OutputWriter, check_output_dir, read_pfm


def test_output_inside_input_is_refused(tmp_path):
    src = tmp_path / "scene"
    src.mkdir()
    with pytest.raises(ValueError, match="inside the input folder"):
        check_output_dir(src / "out", src, force=True)
    with pytest.raises(ValueError, match="is the input folder"):
        check_output_dir(src, src, force=True)


def test_existing_output_needs_force(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(ValueError, match="--force"):
        check_output_dir(out, None, force=False)
    assert check_output_dir(out, None, force=True) == out.resolve()


def test_writer_commits_all_files_at_once(tmp_path):
    out = tmp_path / "res"
    w = OutputWriter(out)
    w.pfm("disparity/centre.pfm", np.arange(12, dtype=np.float32).reshape(3, 4))
    w.png("centre.png", np.zeros((3, 4, 3), np.uint8))
    w.json("metrics.json", {"mse_x100": 1.5})
    w.npz("all.npz", disparity=np.ones((2, 2)))
    assert not out.exists()  # nothing visible before commit
    w.commit()
    assert np.array_equal(read_pfm(out / "disparity/centre.pfm"), np.arange(12).reshape(3, 4))
    assert json.loads((out / "metrics.json").read_text()) == {"mse_x100": 1.5}
    assert (out / "centre.png").is_file() and (out / "all.npz").is_file()
    assert not any(p.name.startswith(".res.") for p in tmp_path.iterdir())


def test_writer_abort_leaves_nothing(tmp_path):
    out = tmp_path / "res"
    w = OutputWriter(out)
    w.json("metrics.json", {})
    w.abort()
    assert list(tmp_path.iterdir()) == []
