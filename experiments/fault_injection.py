"""Fault injection for ``mvedge depth`` and the library (issue 18: never lose the user's data,
atomic outputs, no silent wrong results).

Builds a small copy of a real scene in a temporary folder (the central 5x5 views of HCI
backgammon, cropped to 64x64 px, with its ground truth, as an HCI 4D folder; the shared data
is only read), then tries each fault on a fresh copy and classifies the outcome:

- clear error: the run stopped with a one-line ``Error: ...`` naming the problem (or, where
  the fault is only suspicious, finished with a ``warning: ...`` and a correct result);
- traceback: a Python traceback, an unexpected exception, a kill or a hang;
- silent wrong: exit 0 where an error (or a warning) was due, or a wrong result;
- partial output: after a failed run the output differs from before (a new, half-written or
  deleted folder), or staging folders, lock files or created parent folders remain;
- input modified: any file of the input copy changed or disappeared.

Prints one line per fault and, last, exactly one summary line
``N faults tried: A clear errors / B tracebacks / C silent wrong / D partial output /
E input modified``.

Usage::

    PYTHONPATH=. python experiments/fault_injection.py [--data ../shared/data] [--keep]

A handful of faults run the whole pipeline (about a minute each on a busy 2-core CPU, less
with the persistent compilation cache warm); the rest fail before any computation.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mvedge_jax.io import OutputWriter, read_pfm, write_pfm  # noqa: E402

CATEGORIES = ("clear", "traceback", "silent", "partial", "input")


# ---- scene copies --------------------------------------------------------------------------


def make_base(data: Path, dest: Path, size: int = 64, grid: int = 5) -> Path:
    """Central ``grid``×``grid`` views of backgammon cropped to ``size`` px, as HCI 4D."""
    src = data / "hci4d" / "stratified" / "backgammon"
    dest.mkdir(parents=True)
    y0, x0 = 300, 200  # a textured region (board edge and pieces)
    r0 = 4 - grid // 2
    for r in range(grid):
        for c in range(grid):
            img = cv2.imread(str(src / f"input_Cam{9 * (r0 + r) + (r0 + c):03d}.png"))
            cv2.imwrite(
                str(dest / f"input_Cam{grid * r + c:03d}.png"), img[y0 : y0 + size, x0 : x0 + size]
            )
    gt = read_pfm(src / "gt_disp_lowres.pfm")
    write_pfm(dest / "gt_disp_lowres.pfm", gt[y0 : y0 + size, x0 : x0 + size])
    (dest / "parameters.cfg").write_text(
        f"[extrinsics]\nnum_cams_x = {grid}\nnum_cams_y = {grid}\n\n"
        "[meta]\ndisp_min = -1.6\ndisp_max = 0.6\n"
    )
    return dest


def snapshot(folder: Path) -> dict:
    """Every file under ``folder``: (size, sha1)."""
    if not folder.exists():
        return {}
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(folder))] = (p.stat().st_size, _sha1(p))
        elif not p.is_dir():
            out[str(p.relative_to(folder))] = ("special",)
    return out


def _sha1(p: Path) -> str:
    return hashlib.sha1(p.read_bytes()).hexdigest()


def debris(parent: Path) -> list[str]:
    """Staging folders, set-aside folders and lock files left in ``parent``."""
    if not parent.is_dir():
        return []
    return sorted(
        p.name
        for p in parent.iterdir()
        if p.name.startswith(".")
        and (".stage-" in p.name or ".old-" in p.name or p.name.endswith(".lock"))
    )


# ---- running -------------------------------------------------------------------------------


def cli(*args, timeout: float = 900.0, popen: bool = False):
    cmd = [sys.executable, "-m", "mvedge_jax.cli", *map(str, args)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    if popen:
        return subprocess.Popen(
            cmd, env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
    try:
        p = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
        return p.returncode, p.stdout + p.stderr, False
    except subprocess.TimeoutExpired as e:
        out = (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        return None, out, True


class Case:
    """One fault: ``setup(work) -> dict`` builds the copies and returns the CLI arguments
    and what to expect; the harness runs and classifies."""

    def __init__(self, name, fn):
        self.name, self.fn = name, fn


def classify_cli(
    rc,
    output,
    timed_out,
    *,
    inputs: dict[Path, dict],
    out: Path | None,
    out_before: dict | None,
    created_root: Path | None = None,
    expect: str = "error",
    match: str = "",
    check=None,
) -> tuple[str, str]:
    for folder, before in inputs.items():
        if snapshot(folder) != before:
            return "input", f"input {folder.name} changed"
    if out is not None and expect == "error":
        after = snapshot(out) if out.exists() else None
        if after != out_before:
            return "partial", "output changed by a failed run"
    if out is not None:
        left = debris(out.parent)
        if left:
            return "partial", f"left {left}"
    if created_root is not None and created_root.exists():
        return "partial", f"left created folder {created_root}"
    if timed_out:
        return "traceback", "hang (timed out)"
    if "Traceback" in output or rc not in (0, 1, 2):
        return "traceback", output.strip().splitlines()[-1] if output.strip() else f"rc {rc}"
    if expect == "error":
        if rc == 0:
            return "silent", "exit 0"
        if match not in output or "Error:" not in output:
            return "silent", f"unexpected message: {output.strip()[-200:]}"
        return "clear", output.strip().splitlines()[-1][:150]
    if expect == "warn":
        if rc != 0:
            return "silent", f"failed: {output.strip()[-200:]}"
        if "warning:" not in output or match not in output:
            return "silent", "no warning"
    if check is not None:
        problem = check(output)
        if problem:
            return "silent", problem
    if expect == "warn":
        line = next(ln for ln in output.splitlines() if ln.startswith("warning:"))
        return "clear", line[:150]
    return "clear", "ok"


def api_case(fn, exc=ValueError, match=""):
    """An in-process fault: ``fn`` must raise ``exc`` with ``match`` in its message (or
    return True for a flagged result)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            value = fn()
    except exc as e:
        if match in str(e):
            return "clear", str(e)[:150]
        return "silent", f"wrong message: {e}"
    except Exception as e:  # noqa: BLE001 - any other exception is a failure
        return "traceback", f"{type(e).__name__}: {e}"[:150]
    if value is True:
        return "clear", "flagged"
    return "silent", f"accepted: {value!r}"[:150]


# ---- the faults ----------------------------------------------------------------------------


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--data", default=os.environ.get("MVEDGE_DATA", str(ROOT.parent / "shared" / "data"))
    )
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    args = ap.parse_args(argv)
    data = Path(args.data)
    work = Path(tempfile.mkdtemp(prefix="mvedge_faults_"))
    shared_before = snapshot(data / "hci4d" / "stratified" / "backgammon")
    base = make_base(data, work / "base")
    results: list[tuple[str, str, str]] = []
    counter = [0]

    def fresh(name="scene") -> Path:
        counter[0] += 1
        d = work / f"case{counter[0]:02d}"
        d.mkdir()
        return Path(shutil.copytree(base, d / "data" / name))

    def record(name, outcome):
        results.append((name, *outcome))
        print(f"[{outcome[0]:>9}] {name}: {outcome[1]}", flush=True)

    def run_error(
        name,
        scene,
        out,
        *extra,
        match="",
        force=True,
        expect="error",
        check=None,
        protect=(),
        holder=None,
    ):
        """Run ``depth`` on ``scene`` into ``out``. The case's ``data`` folder (the input and
        its parent) and ``protect`` (a user's folders) must survive unchanged; after a
        failure ``out`` must be as before, and no debris or created parent may remain."""
        real = Path(os.path.realpath(scene))
        data_dir = next(p for p in [real, *real.parents] if p.name == "data")
        inputs = {p: snapshot(p) for p in (data_dir, *protect)}
        out_before = snapshot(out) if out.exists() else None
        created, p = None, out.parent
        while not os.path.lexists(p):
            created, p = p, p.parent
        args_ = ["depth", scene, "--out", out, *(["--force"] if force else []), *extra]
        rc, output, to = cli(*args_, timeout=900 if expect != "error" else 300)
        if holder is not None:  # the other run finishes (its lock and staging go)
            holder.abort()
        outcome = classify_cli(
            rc,
            output,
            to,
            inputs=inputs,
            out=out,
            out_before=out_before,
            created_root=created,
            expect=expect,
            match=match,
            check=check,
        )
        record(name, outcome)
        return rc, output

    # -- 1. data loss: output is / contains / is inside the input, also through symlinks
    for force in (True, False):
        tag = " --force" if force else ""
        s = fresh()
        run_error(f"out = input{tag}", s, s, match="is the input folder", force=force)
        s = fresh()
        run_error(
            f"out = parent of input{tag}", s, s.parent, match="contains the input", force=force
        )
        s = fresh()
        run_error(f"out inside input{tag}", s, s / "out", match="inside the input", force=force)
        s = fresh()
        (s.parent.parent / "link").symlink_to(s)
        run_error(
            f"out = symlink to input{tag}",
            s,
            s.parent.parent / "link",
            match="is the input folder",
            force=force,
        )
    s = fresh()
    (s.parent.parent / "link").symlink_to(s.parent)
    run_error(
        "out = symlink to the data folder --force",
        s,
        s.parent.parent / "link",
        match="contains the input",
    )
    s = fresh()
    (s.parent.parent / "scene_link").symlink_to(s)
    run_error(
        "input through a symlink, out = real input --force",
        s.parent.parent / "scene_link",
        s,
        match="is the input folder",
    )
    # -- --force on folders this program did not write
    s = fresh()
    user = s.parent.parent / "thesis"
    user.mkdir()
    (user / "chapter.tex").write_text("months of work")
    run_error(
        "--force on a user's folder", s, user, match="was not written by mvedge", protect=[user]
    )
    s = fresh()
    f = s.parent.parent / "notes.txt"
    f.write_text("keep")
    run_error("--force on a regular file", s, f, match="not a folder")
    s = fresh()
    user = s.parent.parent / "existing"
    user.mkdir()
    (user / "a.txt").write_text("a")
    run_error(
        "existing folder without --force",
        s,
        user,
        match="pass --force",
        force=False,
        protect=[user],
    )

    # -- 2. output location problems found before any work
    s = fresh()
    (s.parent.parent / "file").write_text("x")
    run_error(
        "out under a regular file",
        s,
        s.parent.parent / "file" / "sub" / "out",
        match="is a file, not a folder",
    )
    s = fresh()
    run_error(
        "out in a read-only location (/proc)",
        s,
        Path("/proc/mvedge_fault/out"),
        match="cannot write into /proc",
    )
    s = fresh()
    run_error(
        "failed run creates no parent folders",
        s,
        s.parent.parent / "new" / "deep" / "out",
        "--views",
        "99",
        match="larger than the 5x5 grid",
    )

    # -- baseline: a complete run (the old output for the replace / kill / lock faults)
    s_ok = fresh()
    out_ok = s_ok.parent.parent / "out"
    rc, output, _ = cli("depth", s_ok, "--out", out_ok)
    if rc != 0:
        print(output)
        raise SystemExit("baseline run failed; cannot continue")
    base_metrics = json.loads((out_ok / "metrics.json").read_text())
    print(
        f"[ baseline] BadPix(0.07) {base_metrics['badpix_0.07']:.2f}%, "
        f"MSE×100 {base_metrics['mse_x100']:.3f}",
        flush=True,
    )

    # -- concurrency: a second run on a locked output fails fast
    holder = OutputWriter(out_ok, force=True)  # another run, holding the output
    try:
        run_error(
            "concurrent run on the same output",
            s_ok,
            out_ok,
            match="another mvedge run is writing",
            holder=holder,
        )
    finally:
        holder.abort()

    # -- SIGTERM during a --force re-run: old output intact, no debris
    before = snapshot(out_ok)
    proc = cli("depth", s_ok, "--out", out_ok, "--force", popen=True)
    deadline = time.time() + 120
    while not list(out_ok.parent.glob(".out.stage-*")) and time.time() < deadline:
        time.sleep(0.1)
    time.sleep(3.0)  # well into loading / compiling
    proc.send_signal(signal.SIGTERM)
    try:
        output = proc.communicate(timeout=120)[0]
        rc, to = proc.returncode, False
    except subprocess.TimeoutExpired:
        proc.kill()
        output, rc, to = proc.communicate()[0], None, True
    outcome = classify_cli(
        rc,
        output,
        to,
        inputs={s_ok: snapshot(s_ok)},
        out=out_ok,
        out_before=before,
        expect="error",
        match="Aborted",
    )
    if outcome[0] == "silent" and rc == 1 and "Aborted" in output:
        outcome = ("clear", "Aborted!")
    record("SIGTERM during a --force run", outcome)

    # -- SIGKILL: leftovers are removed by the next run on that output
    proc = cli("depth", s_ok, "--out", out_ok, "--force", popen=True)
    deadline = time.time() + 120
    while not list(out_ok.parent.glob(".out.stage-*")) and time.time() < deadline:
        time.sleep(0.1)
    proc.kill()
    proc.communicate()
    run_error(
        "next run after a SIGKILLed one cleans its staging",
        s_ok,
        out_ok,
        "--views",
        "99",
        match="larger than the 5x5 grid",
    )

    # -- 3. loader faults
    s = fresh()
    shutil.copy(s / "input_Cam012.png", s / "input_Cam12.png")
    img = cv2.imread(str(s / "input_Cam000.png"))
    cv2.imwrite(str(s / "input_Cam12.png"), img)  # a different image claiming the centre
    run_error(
        "input_Cam12.png beside input_Cam012.png",
        s,
        s.parent.parent / "out",
        match="input_Cam012.png and input_Cam12.png",
    )
    s = fresh()
    grey = cv2.imread(str(s / "input_Cam007.png"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(s / "input_Cam007.png"), grey)
    run_error("grayscale view among RGB", s, s.parent.parent / "out", match="mix grey and colour")
    s = fresh()
    run_error(
        "--transpose on HCI 4D",
        s,
        s.parent.parent / "out",
        "--transpose",
        match="transpose applies to view grids only",
    )
    for px in (1, 3):
        s = fresh()
        for p in s.glob("input_Cam*.png"):
            cv2.imwrite(str(p), cv2.imread(str(p))[:px, :px])
        write_pfm(s / "gt_disp_lowres.pfm", np.zeros((px, px), np.float32))
        run_error(
            f"{px}x{px}-pixel views",
            s,
            s.parent.parent / "out",
            match="below the minimum of 16x16 px",
        )
    for scale in ("1e-300", "0.1"):
        s = fresh()
        run_error(
            f"--scale {scale}",
            s,
            s.parent.parent / "out",
            "--scale",
            scale,
            match="below the minimum of 16x16 px",
        )
    s = fresh()
    (s / "input_Cam003.png").unlink()
    os.mkfifo(s / "input_Cam003.png")
    run_error("a view that is a named pipe", s, s.parent.parent / "out", match="named pipe")
    s = fresh()
    (s / "input_Cam012.png").unlink()
    os.symlink("/dev/zero", s / "input_Cam012.png")
    run_error("the centre view is /dev/zero", s, s.parent.parent / "out", match="a device")

    def near_baseline(output):
        m = json.loads((Path(output_holder[0]) / "metrics.json").read_text())
        if m["badpix_0.07"] > base_metrics["badpix_0.07"] + 5.0:
            b = base_metrics["badpix_0.07"]
            return f"BadPix(0.07) {m['badpix_0.07']:.1f}% vs baseline {b:.1f}%"
        return None

    output_holder = [None]
    s = fresh()
    (s / "parameters.cfg").write_text(
        "[extrinsics]\nnum_cams_x = 5\nnum_cams_y = 5\n\n"
        "[meta]\ndisp_min = -1000\ndisp_max = 1000\n"
    )
    output_holder[0] = s.parent.parent / "out"
    run_error(
        "parameters.cfg range ±1000",
        s,
        s.parent.parent / "out",
        expect="warn",
        match="implausible",
        check=near_baseline,
    )
    s = fresh()
    (s / "parameters.cfg").write_text(
        "[extrinsics]\nnum_cams_x = 5\nnum_cams_y = 5\n\n[meta]\ndisp_min = -0.1\ndisp_max = 0.1\n"
    )
    output_holder[0] = s.parent.parent / "out"
    run_error(
        "parameters.cfg range narrower than the scene",
        s,
        s.parent.parent / "out",
        expect="warn",
        match="narrower than its ground truth",
    )
    s = fresh()
    (s / "parameters.cfg").write_text(
        "[extrinsics]\nnum_cams_x = 5\nnum_cams_y = 5\n\n[meta]\ndisp_min = -0.1\ndisp_max = 0.1\n"
    )
    (s / "gt_disp_lowres.pfm").unlink()  # nothing to compare the range with but the labels
    output_holder[0] = s.parent.parent / "out"
    run_error(
        "parameters.cfg range narrower than the scene, no ground truth",
        s,
        s.parent.parent / "out",
        expect="warn",
        match="probably wider than the one used",
    )
    s = fresh()
    for p in s.glob("input_Cam*.png"):
        cv2.imwrite(str(p), np.full((64, 64, 3), 128, np.uint8))
    run_error(
        "a blank light field (no edge points)", s, s.parent.parent / "out", match="no edge point"
    )

    # -- 4. config faults (checked before the scene is loaded)
    configs = {
        'bool as the string "false"': (
            '[edges.label]\nnms = "false"\n',
            "edges.label.nms expects true or false",
        ),
        "array where a number is expected": (
            "[edges.filter]\npresmooth_sigma = [0.8, 0.9]\n",
            "edges.filter.presmooth_sigma expects a number",
        ),
        "float where an int is expected": (
            "[edges.filter]\nn_filters = 61.5\n",
            "edges.filter.n_filters expects an integer",
        ),
        "unknown key": ("[surface]\nsmoothness = 2\n", "unknown key surface.smoothness"),
        "unknown table": ("[edge]\nn_filters = 61\n", "unknown config tables"),
        "nan value": ("[surface]\noffset = nan\n", "surface.offset must be a finite number"),
        "out-of-range value": ("[optimize]\niterations = -1\n", "iterations must be >= 0"),
        "d_max_fallback = 1e6": ("[edges.filter]\nd_max_fallback = 1e6\n", "d_max_fallback"),
        "d_max = 1e6": ("[edges.filter]\nd_max = 1e6\n", "d_max must be > 0 and <= 64"),
        "invalid TOML": ("[edges\nn_filters = 61\n", "is not valid TOML"),
    }
    for name, (text, match) in configs.items():
        s = fresh()
        if "fallback" in name:  # no metadata range: the fallback sets the filter bank
            (s / "parameters.cfg").write_text("[extrinsics]\nnum_cams_x = 5\nnum_cams_y = 5\n")
        cfg = s.parent.parent / "cfg.toml"
        cfg.write_text(text)
        run_error(f"config: {name}", s, s.parent.parent / "out", "--config", cfg, match=match)
    s = fresh()
    cfg = s.parent.parent / "cfgdir"
    cfg.mkdir()
    run_error("config: a folder", s, s.parent.parent / "out", "--config", cfg, match="is a folder")
    s = fresh()
    cfg = s.parent.parent / "cfg.bin"
    cfg.write_bytes(bytes(range(256)) * 8)
    run_error(
        "config: a binary file",
        s,
        s.parent.parent / "out",
        "--config",
        cfg,
        match="is not valid TOML",
    )

    # -- 5/6. library faults (in-process)
    import jax
    import jax.numpy as jnp

    from mvedge_jax.lightfield import LightField
    from mvedge_jax.solve import MAX_STEPS, NONFINITE, SolverConfig, solve_poisson

    rng = np.random.default_rng(0)
    u8 = rng.integers(0, 256, (3, 3, 16, 16, 3), dtype=np.uint8)
    mask = jnp.ones((3, 3), bool)
    record(
        "LightField from uint8 views",
        api_case(lambda: LightField(views=jnp.asarray(u8), view_mask=mask), match="divide 8-bit"),
    )
    record(
        "LightField from 0-255 float views",
        api_case(
            lambda: LightField(views=jnp.asarray(u8, jnp.float32), view_mask=mask), match="[0, 1]"
        ),
    )
    gt = np.zeros((3, 3, 16, 16), np.float32)
    gt[1, 1, 0, 0] = np.nan
    record(
        "LightField with NaN ground truth",
        api_case(
            lambda: LightField(
                views=jnp.asarray(u8 / 255.0, jnp.float32),
                view_mask=mask,
                gt_disparity=jnp.asarray(gt),
                gt_mask=jnp.ones(gt.shape, bool),
            ),
            match="NaN/Inf",
        ),
    )
    lam = np.ones((8, 8), np.float32)
    S = rng.normal(size=(8, 8)).astype(np.float32)
    wx, wy = np.ones((8, 7), np.float32), np.ones((7, 8), np.float32)
    bad = lam.copy()
    bad[2, 2] = np.nan
    record(
        "solver: NaN data weight", api_case(lambda: solve_poisson(bad, S, wx, wy), match="NaN/Inf")
    )
    badt = S.copy()
    badt[0, 0] = np.inf
    record(
        "solver: Inf target", api_case(lambda: solve_poisson(lam, badt, wx, wy), match="NaN/Inf")
    )
    record(
        "solver: negative weights",
        api_case(lambda: solve_poisson(lam, S, -wx, wy), match="negative"),
    )
    record(
        "solver under jit: NaN target flagged",
        api_case(
            lambda: (
                int(jax.jit(solve_poisson)(lam, np.where(badt > 1e30, np.nan, badt), wx, wy).status)
                == NONFINITE
            )
        ),
    )
    record(
        "solver: iteration cap flagged",
        api_case(
            lambda: (
                int(
                    solve_poisson(
                        lam * 0 + (np.arange(64).reshape(8, 8) == 0),
                        S,
                        wx * 100,
                        wy * 100,
                        config=SolverConfig(max_iters=1, preconditioner="none"),
                    ).status
                )
                == MAX_STEPS
            )
        ),
    )

    def strict_json():
        w = OutputWriter(work / "json_out")
        w.json("metrics.json", {"mse_x100": float("inf")})
        w.commit()
        text = (work / "json_out" / "metrics.json").read_text()
        return "Infinity" not in text and json.loads(text)["mse_x100"] is None

    record("metrics.json with an infinite value", api_case(strict_json))

    if snapshot(data / "hci4d" / "stratified" / "backgammon") != shared_before:
        record("shared data untouched", ("input", "the shared data changed!"))
    counts = {c: sum(1 for _, k, _ in results if k == c) for c in CATEGORIES}
    if not args.keep:
        with contextlib.suppress(OSError):
            shutil.rmtree(work)
    else:
        print(f"kept {work}")
    print(
        f"{len(results)} faults tried: {counts['clear']} clear errors / {counts['traceback']} "
        f"tracebacks / {counts['silent']} silent wrong / {counts['partial']} partial output / "
        f"{counts['input']} input modified"
    )
    return 0 if counts["clear"] == len(results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
