"""Where the main job's run time goes on XLA's CPU backend: thunk seconds by step and line.

Usage::

    python experiments/profile_chain.py [SCENE] [--depth 3] [--top 30] [--json OUT.json]
        [--optimize]

``SCENE`` is a light-field folder (default: HCI backgammon under ``$MVEDGE_DATA`` or
``../shared/data``) or ``synthetic`` (the embedded default light field). In one process:
`estimate_disparity` is compiled (the persistent cache off, so that XLA compiles and dumps
each program's optimised HLO to a temporary folder), run once more warm, and run a third
time under `jax.profiler` (with ``--optimize``: `optimize_disparity` on the chain's result
instead, compiled by its first call and traced in its second, each a few minutes on a 2-core
CPU). XLA:CPU records every thunk it executes (one fused kernel, a
gather, a convolution, ...) with its program and HLO instruction; the instruction's stack
frames in the dump name the Python lines that built it. Each thunk's wall time is charged
to its innermost `mvedge_jax` source line, and printed three ways, largest first:

* by step: the `mvedge_jax` call path below the pipeline's stage functions, cut at
  ``--depth`` frames (``reconstruct_stage > reconstruct > _propagate``);
* by function: the innermost `mvedge_jax` function;
* by line: ``file:line function``.

Each row gives the thunk seconds, their share of all thunk seconds and how many thunks ran.
The header gives the traced call's wall and the process CPU seconds it used. Thunk
seconds are the thunks' wall durations summed: two thunks that run at once on the two
cores both count, and a kernel that XLA splits over threads counts its wall once, so the
total differs from both the wall and the CPU time; compare rows with each other, and runs
only on one machine. Loops (``while``) and calls are not charged themselves, only the thunks
inside them. Takes a few minutes (one compilation without cache).
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_chain import DATA, ROOT, _load  # noqa: E402  (imports no JAX at module level)

DEFAULT_SCENE = DATA / "hci4d" / "stratified" / "backgammon"
# Frames of the pipeline's plumbing (jit wrappers, the stage cache, the driver): the call
# path starts below them, at the stage functions of `mvedge_jax.pipeline._chain`.
_PLUMBING = ("_jit.py", "pipeline/_compile.py", "pipeline/_driver.py")
_NESTED = ("while", "call", "conditional")
_TABLES = ("FileNames", "FunctionNames", "FileLocations", "StackFrames")
_INSTRUCTION = re.compile(r"^\s*(?:ROOT )?%?([\w.\-]+) = .*?stack_frame_id=(\d+)")


def parse_dump(path: str) -> tuple[str, dict[str, list[tuple[str, str, int]]]]:
    """One optimised HLO text dump: its module name and, per instruction, its stack frames
    (innermost first) as ``(file relative to the repository, function, line)``."""
    tables: dict[str, dict[int, str]] = {t: {} for t in _TABLES}
    section, name, frame_of = None, None, {}
    with open(path) as f:
        for line in f:
            line = line.rstrip("\n")
            if name is None and line.startswith("HloModule "):
                name = line.split()[1].rstrip(",")
                continue
            if line in _TABLES:
                section = line
                continue
            if section is not None:
                if not line.strip():
                    section = None
                else:
                    key, value = line.split(" ", 1)
                    tables[section][int(key)] = value
                continue
            m = _INSTRUCTION.match(line)
            if m:
                frame_of[m.group(1)] = int(m.group(2))

    def field(text: str, key: str) -> int:
        return int(re.search(key + r"=(\d+)", text).group(1))

    def frame(fid: int) -> tuple[str, str, int]:
        loc = tables["FileLocations"][field(tables["StackFrames"][fid], "file_location_id")]
        file = tables["FileNames"][field(loc, "file_name_id")].strip('"')
        try:
            file = str(Path(file).resolve().relative_to(ROOT))
        except ValueError:
            pass
        return (
            file,
            tables["FunctionNames"][field(loc, "function_name_id")].strip('"'),
            field(loc, "line"),
        )

    def stack(fid: int) -> list[tuple[str, str, int]]:
        out, seen = [], set()
        # The dump's parent ids count from 1 past the frame ids; a root's parent is 0.
        while fid in tables["StackFrames"] and fid not in seen:
            seen.add(fid)
            out.append(frame(fid))
            fid = field(tables["StackFrames"][fid], "parent_frame_id") - 1
        return out

    return name or Path(path).name, {op: stack(fid) for op, fid in frame_of.items()}


def attribute(events: list[dict], programs: dict[str, list[dict]]) -> list[tuple[dict, list]]:
    """Each thunk event with the stack of its instruction. Several programs may share a
    module name (each pipeline stage is ``jit_flat``): the events of one name are cut into
    runs at pauses of more than 5 ms, and each run goes to the program of that name that
    holds most of its instruction names."""
    by_module = collections.defaultdict(list)
    for e in events:
        by_module[e["args"]["hlo_module"]].append(e)
    out = []
    for module, evs in by_module.items():
        candidates = programs.get(module, [])
        evs.sort(key=lambda e: e["ts"])
        runs, run, end = [], [], None
        for e in evs:
            if run and e["ts"] - end > 5000:
                runs.append(run)
                run = []
            run.append(e)
            end = max(end or 0.0, e["ts"] + e["dur"])
        runs.append(run)
        for run in runs:
            names = {e["args"]["hlo_op"] for e in run}
            ops = max(candidates, key=lambda p: len(names & p.keys()), default={})
            out.extend((e, ops.get(e["args"]["hlo_op"], [])) for e in run)
    return out


def charge(attributed, depth: int) -> dict[str, collections.Counter]:
    """Thunk seconds and counts per step, function and line."""
    seconds = {k: collections.Counter() for k in ("step", "function", "line")}
    counts = {k: collections.Counter() for k in seconds}
    for e, stack in attributed:
        if e["args"]["hlo_op"].split(".")[0] in _NESTED:
            continue
        ours = [
            s
            for s in stack
            if s[0].startswith("mvedge_jax/") and not any(s[0].endswith(p) for p in _PLUMBING)
        ]
        if ours:
            path = [s[1] for s in reversed(ours)][:depth]
            keys = {
                "step": " > ".join(path),
                "function": f"{ours[0][0]} {ours[0][1]}",
                "line": f"{ours[0][0]}:{ours[0][2]} {ours[0][1]}",
            }
        else:
            keys = dict.fromkeys(seconds, f"(no mvedge_jax frame: {e['args']['hlo_module']})")
        for k, key in keys.items():
            seconds[k][key] += e["dur"] / 1e6
            counts[k][key] += 1
    return {"seconds": seconds, "counts": counts}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("scene", nargs="?", default=str(DEFAULT_SCENE))
    ap.add_argument("--depth", type=int, default=3, help="frames of the call path per step")
    ap.add_argument("--top", type=int, default=30, help="rows per table")
    ap.add_argument("--json", type=Path, default=None, help="write the tables as JSON here")
    ap.add_argument(
        "--optimize",
        action="store_true",
        help="profile optimize_disparity (thesis Ch. 7) on the chain's result instead",
    )
    args = ap.parse_args()
    if args.scene != "synthetic" and not Path(args.scene).is_dir():
        sys.exit(f"error: light-field folder not found: {args.scene}")

    with tempfile.TemporaryDirectory(prefix="mvedge-profile-") as tmp:
        dump, trace = Path(tmp) / "hlo", Path(tmp) / "trace"
        # Before JAX starts: compile (no persistent cache) and dump the optimised HLO.
        os.environ["MVEDGE_JAX_CACHE"] = "off"
        os.environ["XLA_FLAGS"] = (
            os.environ.get("XLA_FLAGS", "") + f" --xla_dump_to={dump} --xla_dump_hlo_as_text"
        ).strip()
        import jax

        from mvedge_jax.pipeline import (
            PipelineConfig,
            device_info,
            estimate_disparity,
            optimize_disparity,
        )

        lf = _load(args.scene)
        config = PipelineConfig()
        if args.optimize:
            result = estimate_disparity(lf, config)

            def run():
                return optimize_disparity(lf, result, config)[0].disparity

            # Its Adam steps run for minutes: the first call compiles, the second is traced.
            calls = 1
        else:

            def run():
                return estimate_disparity(lf, config).disparity

            calls = 2
        what = "compiling and a warm run" if calls > 1 else "compiling"
        print(f"[profile_chain] {args.scene}: {what} ...", flush=True)
        for _ in range(calls):
            jax.block_until_ready(run())
        print("[profile_chain] traced run ...", flush=True)
        jax.profiler.start_trace(str(trace))
        cpu0, t0 = os.times(), time.perf_counter()
        jax.block_until_ready(run())
        wall, cpu1 = time.perf_counter() - t0, os.times()
        jax.profiler.stop_trace()
        cpu = (cpu1.user - cpu0.user) + (cpu1.system - cpu0.system)

        programs = collections.defaultdict(list)
        for path in glob.glob(str(dump / "*.cpu_after_optimizations.txt")):
            name, ops = parse_dump(path)
            programs[name].append(ops)
        (trace_file,) = glob.glob(str(trace / "**" / "*.trace.json.gz"), recursive=True)
        with gzip.open(trace_file) as f:
            events = [
                e
                for e in json.load(f)["traceEvents"]
                if e.get("ph") == "X" and "hlo_op" in e.get("args", {})
            ]
    result = charge(attribute(events, programs), args.depth)
    total = sum(result["seconds"]["line"].values())
    print(
        f"\n{args.scene}, {device_info()['device']}: traced call {wall:.2f} s wall, "
        f"{cpu:.2f} s process CPU, {total:.2f} thunk s in {len(events)} thunks"
    )
    for kind in ("step", "function", "line"):
        print(f"\n| {kind} | thunk s | share | thunks |\n|---|---|---|---|")
        for key, s in result["seconds"][kind].most_common(args.top):
            print(f"| {key} | {s:.3f} | {100 * s / total:.1f} % | {result['counts'][kind][key]} |")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "scene": args.scene,
                    "wall_s": wall,
                    "cpu_s": cpu,
                    "thunk_s": total,
                    **{
                        kind: dict(result["seconds"][kind].most_common())
                        for kind in ("step", "function", "line")
                    },
                },
                indent=1,
            )
        )


if __name__ == "__main__":
    main()
