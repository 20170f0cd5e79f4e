"""Where the test run's time goes: seconds per test file, and how many of them XLA compiles.

Runs pytest (with the arguments given, default: the README's test command) with this file as
a plugin: every test's wall time and every XLA compilation of at least 0.3 s (JAX's compile
log: ``jax_log_compiles``) are written per pytest-xdist worker to ``--out``, then summed per
test file. Prints one table row per file, longest first: tests, seconds, seconds of XLA
compilation, the number of those compilations and the longest one (program name, seconds).

Usage::

    python experiments/compile_times.py [--out DIR] [--top 30] [-- PYTEST ARGS ...]

Example: ``python experiments/compile_times.py -- tests/reconstruct -n 2 --dist loadfile``.
"""

from __future__ import annotations

import argparse
import collections
import logging
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_ENV_OUT = "MVEDGE_COMPILE_TIMES_DIR"
_COMPILED = re.compile(r"Finished XLA compilation of (.*?) in ([\d.]+) s")
_MIN_SECONDS = 0.3

# ---- the pytest plugin (imported by pytest as ``-p compile_times``) ----------------------

if _ENV_OUT in os.environ:
    import jax
    import pytest

    jax.config.update("jax_log_compiles", True)
    _worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    _log = open(Path(os.environ[_ENV_OUT]) / f"{_worker}.tsv", "a", buffering=1)  # noqa: SIM115
    _current = ["<collection>"]

    class _CompileHandler(logging.Handler):
        def emit(self, record):
            match = _COMPILED.search(record.getMessage())
            if match and float(match.group(2)) >= _MIN_SECONDS:
                _log.write(f"{_current[0]}\tcompile\t{match.group(1)}\t{match.group(2)}\n")

    _jax_logger = logging.getLogger("jax")
    _jax_logger.addHandler(_CompileHandler(logging.DEBUG))
    _jax_logger.setLevel(logging.DEBUG)
    _jax_logger.propagate = False  # the compile log is recorded here, not printed

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        _current[0] = item.nodeid
        start = time.perf_counter()
        yield
        _log.write(f"{item.nodeid}\ttest\t-\t{time.perf_counter() - start:.3f}\n")

    def pytest_unconfigure(config):
        _log.close()


# ---- the script ---------------------------------------------------------------------------


def _readme_pytest_args() -> list[str]:
    """The arguments of the README's test command (its first ``pytest`` line)."""
    for line in (ROOT / "README.md").read_text().splitlines():
        words = line.strip().split()
        for i, word in enumerate(words):
            if word.endswith("pytest"):
                return words[i + 1 :]
    raise SystemExit("no pytest command found in README.md")


def summarise(folder: Path) -> list[dict]:
    """Per test file: tests, test seconds, compile seconds and count, the longest compile."""
    files: dict[str, dict] = collections.defaultdict(
        lambda: {"tests": 0, "seconds": 0.0, "compile": 0.0, "n": 0, "longest": ("-", 0.0)}
    )
    for tsv in sorted(folder.glob("*.tsv")):
        for line in tsv.read_text().splitlines():
            nodeid, kind, name, seconds = line.split("\t")
            row = files[nodeid.split("::")[0]]
            seconds = float(seconds)
            if kind == "test":
                row["tests"] += 1
                row["seconds"] += seconds
            else:
                row["compile"] += seconds
                row["n"] += 1
                if seconds > row["longest"][1]:
                    row["longest"] = (name, seconds)
    rows = [{"file": f, **r} for f, r in files.items()]
    return sorted(rows, key=lambda r: -r["seconds"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="folder of the per-worker logs (default: temp)")
    parser.add_argument("--top", type=int, default=30, help="rows printed (default 30)")
    parser.add_argument("pytest_args", nargs="*", help="after --: pytest's arguments")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="compile_times_"))
    out.mkdir(parents=True, exist_ok=True)
    if any(out.glob("*.tsv")):
        raise SystemExit(f"{out} already holds logs; name an empty folder")
    pytest_args = args.pytest_args or _readme_pytest_args()
    env = dict(os.environ)
    env[_ENV_OUT] = str(out)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT / "experiments"), str(ROOT), env.get("PYTHONPATH", "")]
    )
    cmd = [sys.executable, "-m", "pytest", "-p", "compile_times", *pytest_args]
    print("running:", " ".join(cmd), flush=True)
    start = time.perf_counter()
    code = subprocess.call(cmd, cwd=ROOT, env=env)
    wall = time.perf_counter() - start
    rows = summarise(out)
    total = sum(r["seconds"] for r in rows)
    compiled = sum(r["compile"] for r in rows)
    print(
        f"\n{len(rows)} files, wall {wall:.0f} s, test time {total:.0f} s, of which XLA "
        f"compilations >= {_MIN_SECONDS} s: {compiled:.0f} s (pytest exit code {code}; "
        f"logs in {out})"
    )
    print(f"{'file':58s} {'tests':>5s} {'s':>7s} {'compile s':>9s} {'n':>4s}  longest compile")
    for r in rows[: args.top]:
        name, seconds = r["longest"]
        print(
            f"{r['file'][:58]:58s} {r['tests']:5d} {r['seconds']:7.1f} {r['compile']:9.1f} "
            f"{r['n']:4d}  {name[:40]} {seconds:.1f}"
        )
    sys.exit(code)


if __name__ == "__main__":
    main()
