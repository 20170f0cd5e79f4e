"""Faults that used to lose data or give silently wrong results: output safety, the loader,
the `LightField` contract and strict JSON."""

from __future__ import annotations

import json
import os
import stat
import threading
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.io import (
    OUTPUT_MARKER,
    DisparityRangeWarning,
    OutputError,
    OutputWriter,
    check_output_dir,
    load_light_field,
)
from mvedge_jax.lightfield import LightField

# ---- output location ---------------------------------------------------------------------


@pytest.fixture
def scene(tmp_path):
    """``tmp_path/data/scene`` with a user file: the input the output must never touch."""
    src = tmp_path / "data" / "scene"
    src.mkdir(parents=True)
    (src / "input_Cam000.png").write_bytes(b"user data")
    return src


@pytest.mark.parametrize("force", [False, True])
def test_output_that_contains_the_input_is_refused(scene, force):
    for out in (scene.parent, scene.parent.parent):
        with pytest.raises(OutputError, match="contains the input folder"):
            check_output_dir(out, scene, force=force)
    with pytest.raises(OutputError, match="is the input folder"):
        check_output_dir(scene, scene, force=force)
    with pytest.raises(OutputError, match="inside the input folder"):
        check_output_dir(scene / "out", scene, force=force)
    assert (scene / "input_Cam000.png").read_bytes() == b"user data"


def test_output_checks_resolve_symlinks(tmp_path, scene):
    link_scene = tmp_path / "link_scene"
    link_scene.symlink_to(scene)
    link_data = tmp_path / "link_data"
    link_data.symlink_to(scene.parent)
    with pytest.raises(OutputError, match="is the input folder"):
        check_output_dir(link_scene, scene, force=True)
    with pytest.raises(OutputError, match="contains the input folder"):
        check_output_dir(link_data, scene, force=True)
    with pytest.raises(OutputError, match="contains the input folder"):
        check_output_dir(scene.parent, link_scene, force=True)  # input given through a link


def test_force_replaces_only_folders_this_program_wrote(tmp_path):
    user = tmp_path / "photos"
    user.mkdir()
    (user / "holiday.jpg").write_bytes(b"precious")
    with pytest.raises(OutputError, match=f"no {OUTPUT_MARKER} file"):
        check_output_dir(user, None, force=True)
    with pytest.raises(OutputError, match=f"no {OUTPUT_MARKER} file"):
        OutputWriter(user, force=True)
    assert (user / "holiday.jpg").read_bytes() == b"precious"
    empty = tmp_path / "empty"
    empty.mkdir()
    assert check_output_dir(empty, None, force=True) == empty.resolve()  # nothing to lose


def test_every_output_folder_carries_the_marker_and_can_be_replaced(tmp_path):
    out = tmp_path / "res"
    w = OutputWriter(out)
    w.json("metrics.json", {"run": 1})
    w.commit()
    assert (out / OUTPUT_MARKER).is_file()
    with pytest.raises(OutputError, match="pass --force"):
        OutputWriter(out)
    w = OutputWriter(out, force=True)
    w.json("metrics.json", {"run": 2})
    assert json.loads((out / "metrics.json").read_text()) == {"run": 1}  # old until commit
    w.commit()
    assert json.loads((out / "metrics.json").read_text()) == {"run": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]  # no staging, lock, aside


@pytest.mark.parametrize("case", ["file_at_path", "under_a_file", "unwritable"])
def test_unwritable_output_locations_fail_before_any_work(tmp_path, case):
    if case == "file_at_path":
        out = tmp_path / "out.txt"
        out.write_text("keep me")
        match = "not a folder"
    elif case == "under_a_file":
        (tmp_path / "file").write_text("x")
        out = tmp_path / "file" / "sub" / "out"
        match = "is a file, not a folder"
    else:
        out = "/proc/mvedge-no-such-dir/out"  # /proc refuses new folders even to root
        match = "cannot write into /proc"
    with pytest.raises(OutputError, match=match):
        check_output_dir(out, None, force=True)
    if case == "file_at_path":
        assert (tmp_path / "out.txt").read_text() == "keep me"


def test_read_only_folder_is_refused(tmp_path):
    # /proc takes no new entries, not even from root
    with pytest.raises(OutputError, match="cannot write into /proc"):
        check_output_dir(Path("/proc") / "mvedge_out", None, force=False)
    if os.geteuid() == 0:
        return  # root ignores folder permissions: the /proc case above is its read-only place
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(OutputError, match="cannot write into"):
            check_output_dir(ro / "out", None, force=False)
    finally:
        ro.chmod(0o755)


def test_second_writer_on_the_same_output_fails_fast(tmp_path):
    out = tmp_path / "res"
    first = OutputWriter(out)
    with pytest.raises(OutputError, match="another mvedge run is writing"):
        OutputWriter(out)
    first.json("metrics.json", {})
    first.commit()
    second = OutputWriter(out, force=True)  # the lock is free again
    second.abort()
    assert (out / "metrics.json").is_file()


def test_abort_removes_staging_lock_and_created_parents(tmp_path):
    out = tmp_path / "new" / "deeper" / "res"
    w = OutputWriter(out)
    w.json("metrics.json", {})
    w.abort()
    assert list(tmp_path.iterdir()) == []


def test_destination_is_complete_even_if_renames_fail_during_commit(tmp_path, monkeypatch):
    """A crash between the steps of the commit (simulated by failing renames) must leave the
    complete old output or the complete new one, never a missing or mangled folder."""
    out = tmp_path / "res"
    with OutputWriter(out) as w:
        w.json("metrics.json", {"run": 1})
        w.commit()
    w = OutputWriter(out, force=True)
    w.json("metrics.json", {"run": 2})

    def crash(*args):
        raise OSError("killed")

    monkeypatch.setattr(os, "replace", crash)
    monkeypatch.setattr(os, "rename", crash)
    try:
        w.commit()
    except OSError:
        pass
    monkeypatch.undo()
    assert json.loads((out / "metrics.json").read_text())["run"] in (1, 2)
    assert (out / OUTPUT_MARKER).is_file()


def test_failure_inside_with_block_leaves_old_output(tmp_path):
    out = tmp_path / "res"
    with OutputWriter(out) as w:
        w.json("metrics.json", {"run": 1})
        w.commit()
    with pytest.raises(RuntimeError), OutputWriter(out, force=True) as w:
        w.json("metrics.json", {"run": 2})
        raise RuntimeError("killed during the run")
    assert json.loads((out / "metrics.json").read_text()) == {"run": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_stale_staging_of_a_killed_run_is_removed(tmp_path):
    out = tmp_path / "res"
    w = OutputWriter(out)
    stale = w.tmp
    # as if SIGKILLed: the lock is released by the kernel, staging folder and lock file stay
    os.close(w._lock_fd)
    w._lock_fd, w.tmp, w.committed = None, None, True
    assert stale.is_dir() and (tmp_path / ".res.lock").exists()
    w2 = OutputWriter(out)
    assert not stale.exists()
    w2.abort()
    assert list(tmp_path.iterdir()) == []


def test_output_folder_gets_normal_permissions(tmp_path):
    out = tmp_path / "res"
    w = OutputWriter(out)
    w.json("metrics.json", {})
    w.commit()
    umask = os.umask(0o022)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~umask


def test_metrics_json_is_strict(tmp_path):
    out = tmp_path / "res"
    w = OutputWriter(out)
    w.json(
        "metrics.json",
        {"mse_x100": float("inf"), "per_view": [1.0, float("nan")], "n": np.int64(3)},
    )
    w.commit()
    text = (out / "metrics.json").read_text()
    assert "Infinity" not in text and "NaN" not in text
    data = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard {c}"))
    assert data["mse_x100"] is None and data["per_view"] == [1.0, None] and data["n"] == 3
    assert data["non_finite_values"] == ["mse_x100", "per_view[1]"]


def test_writer_rejects_names_that_leave_the_output(tmp_path):
    w = OutputWriter(tmp_path / "res")
    with pytest.raises(ValueError, match="leaves the output folder"):
        w.json("../escape.json", {})
    w.abort()


# ---- loader ------------------------------------------------------------------------------


def test_ambiguous_camera_files_name_both(tmp_path, synth):
    v = synth.views(3, 3, 16, 16)
    folder = synth.hci4d(tmp_path / "s", v)
    synth.rgb(folder / "input_Cam4.png", v[0, 0])
    with pytest.raises(ValueError, match=r"input_Cam004.png and input_Cam4.png"):
        load_light_field(folder)


def test_grey_view_among_colour_views(tmp_path, synth):
    import cv2

    v = synth.views(3, 3, 16, 16)
    folder = synth.hci4d(tmp_path / "s", v)
    cv2.imwrite(str(folder / "input_Cam001.png"), v[0, 1, :, :, 0])
    with pytest.raises(ValueError, match=r"mix grey and colour.*input_Cam001.png \(grey\)"):
        load_light_field(folder)


def test_transpose_on_hci_is_an_error(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 5, 16, 16))
    with pytest.raises(ValueError, match="transpose applies to view grids only"):
        load_light_field(folder, transpose=True)
    assert load_light_field(folder, transpose=False).grid == (3, 5)


@pytest.mark.parametrize("size", [1, 3, 15])
def test_views_below_the_minimum_size(tmp_path, synth, size):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, size, size))
    with pytest.raises(ValueError, match=r"below the minimum of 16x16 px"):
        load_light_field(folder)


@pytest.mark.parametrize("scale", [1e-300, 0.2])
def test_scale_below_the_minimum_size(tmp_path, synth, scale):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, 64, 64))
    with pytest.raises(ValueError, match=r"scale .* below the minimum of 16x16 px"):
        load_light_field(folder, scale=scale)
    assert load_light_field(folder, scale=0.25).size == (16, 16)


def test_implausible_metadata_range_is_ignored_with_a_warning(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, 32, 32), drange=(-1000.0, 1000.0))
    with pytest.warns(DisparityRangeWarning, match=r"\[-1000, 1000\].*implausible.*ignored"):
        lf = load_light_field(folder)
    assert lf.disparity_range is None


def test_metadata_range_narrower_than_gt_is_warned(tmp_path, synth):
    gt = np.full((32, 32), 3.0, np.float32)
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, 32, 32), gt=gt, drange=(-1.0, 1.0))
    with pytest.warns(DisparityRangeWarning, match=r"narrower than its ground truth.*\[-1, 1\]"):
        lf = load_light_field(folder)
    assert lf.disparity_range == (-1.0, 1.0)


def test_named_pipe_view_is_refused_without_hanging(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, 16, 16))
    fifo = folder / "input_Cam001.png"
    fifo.unlink()
    os.mkfifo(fifo)
    result = {}

    def load():
        try:
            load_light_field(folder)
        except Exception as e:  # noqa: BLE001 - reported below
            result["error"] = e

    t = threading.Thread(target=load, daemon=True)
    t.start()
    t.join(20)
    if t.is_alive():  # unblock the reader before failing
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
        t.join(5)
        pytest.fail("the loader hung on a named pipe")
    assert isinstance(result.get("error"), ValueError), result
    assert "named pipe" in str(result["error"])


# ---- LightField contract -----------------------------------------------------------------


def _lf(views, **kw):
    U, V = views.shape[:2]
    return LightField(views=views, view_mask=jnp.ones((U, V), bool), **kw)


def test_lightfield_refuses_uint8_and_0_255_floats():
    v = np.random.default_rng(0).integers(0, 256, (3, 3, 8, 8, 3), dtype=np.uint8)
    with pytest.raises(ValueError, match="divide 8-bit images by 255"):
        _lf(jnp.asarray(v))
    with pytest.raises(ValueError, match=r"must be in \[0, 1\].*0-255"):
        _lf(jnp.asarray(v, jnp.float32))
    with pytest.raises(ValueError, match="NaN/Inf"):
        _lf(jnp.full((3, 3, 8, 8, 3), jnp.nan))
    _lf(jnp.asarray(v, jnp.float32) / 255)


def test_lightfield_refuses_nan_ground_truth_at_valid_pixels():
    views = jnp.full((3, 3, 8, 8, 3), 0.5)
    gt = np.zeros((3, 3, 8, 8), np.float32)
    gt[1, 1, 2, 3] = np.nan
    mask = np.ones_like(gt, bool)
    with pytest.raises(ValueError, match=r"NaN/Inf values where gt_mask is True.*y=2, x=3"):
        _lf(views, gt_disparity=jnp.asarray(gt), gt_mask=jnp.asarray(mask))
    mask[1, 1, 2, 3] = False
    _lf(views, gt_disparity=jnp.asarray(gt), gt_mask=jnp.asarray(mask))
