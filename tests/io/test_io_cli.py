"""``mvedge info`` through click's CliRunner, on real folders and on bad input."""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner

from mvedge_jax.cli import main
from mvedge_jax.io import write_pfm


def _run(*args: str):
    return CliRunner().invoke(main, list(args))


def _field(output: str, key: str) -> str:
    m = re.search(rf"^{re.escape(key)}\s+(.*)$", output, re.MULTILINE)
    assert m, f"no '{key}' line in:\n{output}"
    return m.group(1)


def test_info_still_life(data_dir):
    res = _run("info", str(data_dir / "hci_old/stillLife_lf_3x3"))
    assert res.exit_code == 0, res.output
    out = res.output
    assert _field(out, "layout").startswith("hci_old  (lf/RR_CC.png + attributes.dat)")
    assert _field(out, "grid").startswith("3x3 views (U x V), 9 of 9 present, centre (1, 1)")
    assert _field(out, "size") == "768x768 px (H x W)"
    assert _field(out, "ground truth") == (
        "centre view (1, 1): disparity [-10.827, 10.252] px/view, 100.0% valid"
    )
    assert _field(out, "disparity range") == "[-10.827, 16.158] px/view (metadata)"
    assert re.fullmatch(r"\d+\.\d\d s", _field(out, "load time"))


def test_info_partial_grid_with_crop_and_scale(data_dir):
    res = _run(
        "info",
        str(data_dir / "hci4d/training_partial/dino_star33"),
        "--views",
        "5x5",
        "--scale",
        "0.25",
    )
    assert res.exit_code == 0, res.output
    out = res.output
    assert _field(out, "layout").startswith("hci4d")
    assert _field(out, "grid") == (
        "5x5 views (U x V), 17 of 25 present, centre (2, 2); central crop of the 9x9 grid "
        "(rows 2-6, cols 2-6)"
    )
    lines = out.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("views present"))
    grid = [
        line.split(maxsplit=2)[-1] if k == 0 else line.strip()
        for k, line in enumerate(lines[i : i + 5])
    ]
    assert grid == ["# . # . #", ". # # # .", "# # # # #", ". # # # .", "# . # . #"]
    assert _field(out, "size") == "128x128 px (H x W), scaled by 0.25 from 512x512"
    assert _field(out, "ground truth") == "none"
    assert _field(out, "disparity range") == "[-0.475, 0.475] px/view (metadata)"


def test_info_view_grid_notes(data_dir):
    res = _run("info", str(data_dir / "real/stanford_gantry_3x3/lego_knights"), "--scale", "0.25")
    assert res.exit_code == 0, res.output
    assert _field(res.output, "layout") == "view_grid  (RR_CC.png)"
    assert _field(res.output, "size") == "256x256 px (H x W), scaled by 0.25 from 1024x1024"
    assert _field(res.output, "notes") == "file rows 09-11, cols 08-10"
    assert "file indices are (row, col)" in res.output
    assert _field(res.output, "disparity range") == "unknown (no metadata)"


def test_info_transpose_flag(tmp_path, synth):
    v = synth.views(3, 5, 16, 24)
    folder = synth.grid(tmp_path / "g", v)
    res = _run("info", str(folder), "--transpose")
    assert res.exit_code == 0, res.output
    assert _field(res.output, "grid").startswith("5x3 views")
    assert "file indices swapped on request" in res.output
    res = _run("info", str(folder), "--no-transpose")
    assert _field(res.output, "grid").startswith("3x5 views")


@pytest.mark.parametrize(
    "args, code, message",
    [
        (["info", "{tmp}/missing"], 1, "Error: light field folder not found"),
        (["info", "{tmp}"], 1, "Error: no recognised light-field layout"),
        (
            ["info", "{hci}", "--views", "11x11"],
            1,
            "Error: views=11x11 is larger than the 9x9 grid",
        ),
        (["info", "{hci}", "--views", "7by7"], 2, "expected UxV"),
        (["info", "{hci}", "--scale", "2"], 2, "--scale"),
        (["info"], 2, "Missing argument 'PATH'"),
    ],
)
def test_info_bad_input(tmp_path, synth, args, code, message):
    hci = synth.hci4d(tmp_path / "hci", synth.views(9, 9, 16, 16))
    empty = tmp_path / "empty"
    empty.mkdir()
    args = [a.format(tmp=empty, hci=hci) for a in args]
    res = _run(*args)
    assert res.exit_code == code, res.output
    assert message in res.output
    assert "Traceback" not in res.output


def test_group_lists_info():
    res = _run("--help")
    assert res.exit_code == 0 and "info" in res.output


def test_info_many_gt_views_are_summarised(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "h", synth.views(3, 3, 16, 16))
    for k in range(9):
        write_pfm(folder / f"gt_disp_lowres_Cam{k:03d}.pfm", np.full((16, 16), k, np.float32))
    res = _run("info", str(folder))
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("ground truth"))
    assert "centre view (1, 1): disparity [4.000, 4.000] px/view, 100.0% valid" in lines[i]
    assert "view (0, 0): disparity [0.000, 0.000]" in lines[i + 1]
    assert "view (0, 1): disparity [1.000, 1.000]" in lines[i + 2]
    assert "and 6 more views: disparity [2.000, 8.000] px/view, 100.0% valid" in lines[i + 3]
