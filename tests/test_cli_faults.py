"""``mvedge depth`` / ``demo`` under faults: outputs that would destroy the input, replace
a user's folder, half-written or concurrent outputs, kills, bad configs.

The pipeline itself is replaced by fast stand-ins (`fake_pipeline`): what is under test is
the file handling around it. One real end-to-end run is marked slow.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

import mvedge_jax.cli as cli
from mvedge_jax.io import OUTPUT_MARKER, OutputWriter

ROOT = Path(__file__).resolve().parents[1]


def write_scene(folder: Path, U: int = 3, V: int = 3, size: int = 32, drange=(-1.0, 1.0)):
    """A tiny HCI 4D folder of textured views (``input_CamNNN.png``, ``parameters.cfg``)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    tex = rng.integers(20, 235, (size + 2 * U, size + 2 * V, 3), dtype=np.uint8)
    for r in range(U):
        for c in range(V):
            view = tex[r : r + size, c : c + size]
            assert cv2.imwrite(str(folder / f"input_Cam{V * r + c:03d}.png"), view)
    cfg = f"[extrinsics]\nnum_cams_x = {V}\nnum_cams_y = {U}\n\n[meta]\n"
    if drange is not None:
        cfg += f"disp_min = {drange[0]}\ndisp_max = {drange[1]}\n"
    (folder / "parameters.cfg").write_text(cfg)
    return folder


def listing(folder: Path) -> dict:
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
    }


@pytest.fixture
def fake_pipeline(monkeypatch):
    """`estimate_disparity` and `write_outputs` replaced by instant stand-ins; records the
    calls (``loads``, ``runs``) and can be told to fail (``fail_write``) or to act mid-run
    (``during``)."""
    import mvedge_jax.io as mvedge_io
    import mvedge_jax.pipeline as pl

    state = SimpleNamespace(loads=0, runs=0, fail_write=False, during=None)
    real_load = mvedge_io.load_light_field_with_info

    def load(*args, **kwargs):
        state.loads += 1
        return real_load(*args, **kwargs)

    def estimate(lf, config=None, *, key=None, progress=None):
        state.runs += 1
        if state.during is not None:
            state.during()
        return SimpleNamespace(name=lf.name)

    def write(writer, lf, result, *, seconds_total, initial=None, optimize_info=None, **kw):
        writer.pfm("disparity/view_00_00.pfm", np.zeros((4, 4), np.float32))
        metrics = {"seconds_per_stage": {}, "mse_x100": float("inf"), "warnings": ["w1"]}
        writer.json("metrics.json", metrics)
        if state.fail_write:
            raise OSError(28, "No space left on device")
        return metrics

    monkeypatch.setattr(mvedge_io, "load_light_field_with_info", load)
    monkeypatch.setattr(pl, "estimate_disparity", estimate)
    monkeypatch.setattr(pl, "write_outputs", write)
    return state


def depth(*args):
    return CliRunner().invoke(cli.main, ["depth", *map(str, args)])


def assert_clean_error(res, message):
    assert res.exit_code == 1, res.output
    assert message in res.output, res.output
    assert "Traceback" not in res.output
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit)


# ---- data loss -----------------------------------------------------------------------------


@pytest.mark.parametrize("force", [[], ["--force"]])
@pytest.mark.parametrize("where", ["parent", "itself", "inside", "link_to_parent"])
def test_output_never_touches_the_input(tmp_path, fake_pipeline, force, where):
    scene = write_scene(tmp_path / "data" / "scene")
    (tmp_path / "link").symlink_to(tmp_path / "data")
    out = {
        "parent": tmp_path / "data",
        "itself": scene,
        "inside": scene / "out",
        "link_to_parent": tmp_path / "link",
    }[where]
    before = listing(tmp_path / "data")
    res = depth(scene, "--out", out, *force)
    assert_clean_error(res, "input folder")
    assert listing(tmp_path / "data") == before
    assert fake_pipeline.loads == 0 and fake_pipeline.runs == 0


def test_force_refuses_a_folder_this_program_did_not_write(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    user = tmp_path / "thesis"
    user.mkdir()
    (user / "chapter1.tex").write_text("months of work")
    res = depth(scene, "--out", user, "--force")
    assert_clean_error(res, f"no {OUTPUT_MARKER} file")
    assert (user / "chapter1.tex").read_text() == "months of work"
    assert fake_pipeline.loads == 0


def test_force_replaces_an_earlier_output(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    out = tmp_path / "out"
    assert depth(scene, "--out", out).exit_code == 0
    assert (out / OUTPUT_MARKER).is_file()
    assert_clean_error(depth(scene, "--out", out), "pass --force")
    res = depth(scene, "--out", out, "--force")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "scene"]


# ---- atomic output, concurrency, kills ------------------------------------------------------


def test_failed_write_leaves_old_output_and_no_debris(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    out = tmp_path / "out"
    assert depth(scene, "--out", out).exit_code == 0
    before = listing(out)
    fake_pipeline.fail_write = True
    res = depth(scene, "--out", out, "--force")
    assert res.exit_code != 0
    assert listing(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "scene"]


def test_failed_run_removes_the_parent_folders_it_created(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    fake_pipeline.fail_write = True
    res = depth(scene, "--out", tmp_path / "new" / "deep" / "out")
    assert res.exit_code != 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene"]


def test_concurrent_run_fails_fast(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    out = tmp_path / "out"
    holder = OutputWriter(out)  # another run holds the output
    try:
        res = depth(scene, "--out", out)
        assert_clean_error(res, "another mvedge run is writing")
        assert fake_pipeline.loads == 0
    finally:
        holder.abort()


@pytest.mark.parametrize("case", ["file_at_path", "under_a_file", "proc"])
def test_unwritable_output_fails_before_loading(tmp_path, fake_pipeline, case):
    scene = write_scene(tmp_path / "scene")
    (tmp_path / "file").write_text("keep")
    out, message = {
        "file_at_path": (tmp_path / "file", "not a folder"),
        "under_a_file": (tmp_path / "file" / "out", "is a file, not a folder"),
        "proc": ("/proc/mvedge-no-such-dir/out", "cannot write into /proc"),
    }[case]
    res = depth(scene, "--out", out, "--force")
    assert_clean_error(res, message)
    assert fake_pipeline.loads == 0
    assert (tmp_path / "file").read_text() == "keep"


_SIGTERM_CHILD = textwrap.dedent(
    """
    import sys, time
    from types import SimpleNamespace
    import numpy as np
    import mvedge_jax.cli as cli
    import mvedge_jax.pipeline as pl

    def estimate(lf, config=None, **kw):
        print("computing", flush=True)
        time.sleep(60)

    def write(writer, lf, result, **kw):
        writer.json("metrics.json", {"seconds_per_stage": {}})
        return {"seconds_per_stage": {}}

    pl.estimate_disparity, pl.write_outputs = estimate, write
    cli.main(sys.argv[1:])
    """
)


def test_sigterm_cleans_up_like_ctrl_c(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    out = tmp_path / "out"
    assert depth(scene, "--out", out).exit_code == 0
    before = listing(out)
    proc = subprocess.Popen(
        [sys.executable, "-c", _SIGTERM_CHILD, "depth", scene, "--out", out, "--force"],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        deadline = time.time() + 60
        while not list(tmp_path.glob(".out.stage-*")) and time.time() < deadline:
            time.sleep(0.1)
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        output = proc.communicate(timeout=60)[0]
    finally:
        proc.kill()
    assert proc.returncode == 1, output
    assert "Aborted" in output and "Traceback" not in output
    assert listing(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "scene"]


# ---- config ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[edges.label]\nnms = 'false'\n", "edges.label.nms expects true or false"),
        (
            "[edges.filter]\npresmooth_sigma = [1.0, 2.0]\n",
            "edges.filter.presmooth_sigma expects a number",
        ),
        ("[edges.filter]\nn_filters = 7.5\n", "edges.filter.n_filters expects an integer"),
        ("[surface]\nno_such_key = 1\n", "unknown key surface.no_such_key"),
        ("[reconstruct]\nomega = 1.0\n", "unknown key reconstruct.omega"),
        ("[reconstruct.centre]\nno_such_key = 1\n", "unknown key reconstruct.centre.no_such_key"),
        (
            "[edges.filter]\nd_max_fallback = nan\n",
            "edges.filter.d_max_fallback must be a finite number",
        ),
        ("[optimize.model.render]\ntile_levels = [[64, 'x']]\n", "tile_levels[0][1]"),
    ],
)
def test_bad_config_values_fail_before_loading(tmp_path, fake_pipeline, text, message):
    scene = write_scene(tmp_path / "scene")
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    res = depth(scene, "--out", tmp_path / "out", "--config", cfg)
    assert_clean_error(res, message)
    assert str(cfg) in res.output
    assert fake_pipeline.loads == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "scene"]


@pytest.mark.parametrize("kind", ["folder", "binary"])
def test_unreadable_config_file(tmp_path, fake_pipeline, kind):
    scene = write_scene(tmp_path / "scene")
    cfg = tmp_path / "cfg"
    if kind == "folder":
        cfg.mkdir()
        message = "is a folder"
    else:
        cfg.write_bytes(bytes(range(256)) * 4)
        message = "is not valid TOML"
    res = depth(scene, "--out", tmp_path / "out", "--config", cfg)
    assert_clean_error(res, message)
    assert fake_pipeline.loads == 0


def test_huge_filter_bank_is_refused_before_loading(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene", U=9, V=9, size=16, drange=None)
    cfg = tmp_path / "big.toml"
    cfg.write_text("[edges.filter]\nd_max_fallback = 1e6\n")
    res = depth(scene, "--out", tmp_path / "out", "--config", cfg)
    assert_clean_error(res, "d_max_fallback")
    assert "d_max_fallback must be > 0 and <= 64" in res.output
    assert fake_pipeline.loads == 0


def test_huge_filter_bank_is_refused_by_the_api_before_allocating():
    from mvedge_jax.edges import EdgeConfig, FilterConfig
    from mvedge_jax.pipeline import PipelineConfig, estimate_disparity
    from mvedge_jax.pipeline._checks import ConfigError
    from mvedge_jax.synthetic import default_light_field

    lf = default_light_field()
    # refused when the config is built, before anything is allocated
    with pytest.raises(ValueError, match=r"FilterConfig\.d_max must be .*<= 64"):
        PipelineConfig(edges=EdgeConfig(filter=FilterConfig(d_max=1e6)))
    # a bank within the bounds that would still not fit is refused by the memory check
    with pytest.raises(ConfigError):
        huge = EdgeConfig(filter=FilterConfig(n_filters=5_000_000))
        estimate_disparity(lf, PipelineConfig(edges=huge))


# ---- loader faults through the CLI ----------------------------------------------------------


def test_transpose_on_hci_through_the_cli(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    res = depth(scene, "--out", tmp_path / "out", "--transpose")
    assert_clean_error(res, "transpose applies to view grids only")
    assert fake_pipeline.runs == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene"]


def test_tiny_scale_through_the_cli(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene")
    res = depth(scene, "--out", tmp_path / "out", "--scale", "1e-300")
    assert_clean_error(res, "below the minimum of 16x16 px")
    assert fake_pipeline.runs == 0


def test_range_warning_and_run_warnings_reach_the_console(tmp_path, fake_pipeline):
    scene = write_scene(tmp_path / "scene", drange=(-1000.0, 1000.0))
    res = depth(scene, "--out", tmp_path / "out")
    assert res.exit_code == 0, res.output
    assert "warning: the metadata disparity range [-1000, 1000]" in res.output
    assert "warning: w1" in res.output
    data = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert data["mse_x100"] is None  # strict JSON: no bare Infinity


# ---- the real pipeline ----------------------------------------------------------------------


@pytest.mark.slow
def test_real_run_reports_solver_status_and_refuses_a_flat_scene(tmp_path):
    scene = write_scene(tmp_path / "scene", U=5, V=5)
    res = depth(scene, "--out", tmp_path / "out")
    assert res.exit_code == 0, res.output
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    for stage in ("surface", "reconstruct.centre", "reconstruct.epi", "reconstruct.fill"):
        assert metrics["solver"][stage]["status"] == "converged", stage
    assert metrics["warnings"] == []
    flat = write_scene(tmp_path / "flat")
    for k in range(9):
        cv2.imwrite(str(flat / f"input_Cam{k:03d}.png"), np.full((32, 32, 3), 128, np.uint8))
    res = depth(flat, "--out", tmp_path / "flat_out")
    assert_clean_error(res, "no edge point")
    assert not (tmp_path / "flat_out").exists()
