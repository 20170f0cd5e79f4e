"""`request_deterministic_gpu` and ``mvedge --deterministic``: XLA's deterministic GPU kernels,
requested before JAX starts its backend (each case in a fresh Python process)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLAG = "--xla_gpu_deterministic_ops=true"


def _run(
    code: str, xla_flags: str | None, *args: str, extra_env: dict | None = None
) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "MVEDGE_DETERMINISTIC")}
    env.update(extra_env or {})
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    env["PYTHONPATH"] = str(ROOT)
    cmd = [sys.executable, "-c", textwrap.dedent(code), *args]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)


def test_request_appends_the_flag_once_and_keeps_the_users_flags():
    out = _run(
        """
        import os
        import jax.numpy as jnp
        import mvedge_jax
        assert not mvedge_jax.deterministic_gpu_requested()
        mvedge_jax.request_deterministic_gpu()
        mvedge_jax.request_deterministic_gpu()
        from mvedge_jax.pipeline import device_info
        x = jnp.zeros(3).at[jnp.array([0, 0, 1])].add(1.0)  # the backend starts with the flag
        assert x.tolist() == [2.0, 1.0, 0.0], x
        mvedge_jax.request_deterministic_gpu()  # already requested: nothing to do, no error
        assert mvedge_jax.deterministic_gpu_requested()
        assert device_info()["deterministic"]
        print("FLAGS=" + os.environ["XLA_FLAGS"])
        """,
        "--xla_cpu_enable_fast_math=false",
    )
    assert out.returncode == 0, out.stderr[-3000:]
    flags = out.stdout.split("FLAGS=", 1)[1].split()
    assert flags == ["--xla_cpu_enable_fast_math=false", FLAG], flags


def test_request_after_the_backend_started_raises():
    out = _run(
        """
        import jax.numpy as jnp
        import mvedge_jax
        jnp.zeros(1).block_until_ready()
        try:
            mvedge_jax.request_deterministic_gpu()
        except RuntimeError as e:
            print("ERR=" + str(e))
        """,
        None,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "ERR=" in out.stdout and "before JAX starts its backend" in out.stdout, out.stdout


def test_cli_deterministic_refuses_a_contrary_flag(tmp_path):
    """``mvedge --deterministic`` with ``XLA_FLAGS`` asking for the opposite stops with one
    line naming the flag (nothing runs)."""
    out = _run(
        "from mvedge_jax.cli import main; main()",
        "--xla_gpu_deterministic_ops=false",
        "--deterministic",
        "info",
        str(tmp_path),
    )
    assert out.returncode == 1, (out.stdout, out.stderr[-2000:])
    assert "Error: XLA_FLAGS already sets --xla_gpu_deterministic_ops=false" in out.stderr
    assert "Traceback" not in out.stderr


def test_cli_deterministic_sets_the_flag_before_the_backend(tmp_path):
    """With ``MVEDGE_DETERMINISTIC=1`` the command's JAX backend starts with the flag."""
    code = """
        import os, sys
        import mvedge_jax.cli as cli
        seen = {}
        original = cli._check_platform
        def check():
            seen["flags"] = os.environ.get("XLA_FLAGS", "")
            original()
        cli._check_platform = check
        try:
            cli.main(["info", sys.argv[1]])
        except SystemExit:
            pass
        print("FLAGS=" + seen["flags"])
        """
    out = _run(code, None, str(tmp_path), extra_env={"MVEDGE_DETERMINISTIC": "1"})
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split("FLAGS=", 1)[1].split() == [FLAG], out.stdout
