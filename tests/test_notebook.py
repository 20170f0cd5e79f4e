"""The quickstart notebook executes top to bottom without warnings, and its committed outputs
are the ones of this run: the test writes the executed notebook back, so they never go stale.

The notebook's cells come from notebooks/make_quickstart.py; a notebook whose sources differ
from it fails here (edit the script, not the notebook)."""

import math
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "notebooks" / "quickstart.ipynb"
sys.path.insert(0, str(ROOT / "notebooks"))

import make_quickstart  # noqa: E402


@pytest.mark.slow
def test_quickstart_notebook_executes_and_is_written_back(data_dir, monkeypatch):
    monkeypatch.setenv("MVEDGE_DATA", str(data_dir))
    monkeypatch.delenv("MVEDGE_NOTEBOOK_SCALE", raising=False)  # the committed default
    monkeypatch.setenv("PYTHONWARNINGS", "default")  # warnings would show in the outputs
    # the kernel reuses the test suite's persistent compilation cache
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(ROOT / ".jax_cache"))
    committed = nbformat.read(NOTEBOOK, as_version=4)
    nb = make_quickstart.build()
    assert [c.source for c in committed.cells] == [c.source for c in nb.cells], (
        "notebooks/quickstart.ipynb differs from make_quickstart.py; run the script"
    )
    NotebookClient(
        nb,
        timeout=1200,
        kernel_name="python3",
        resources={"metadata": {"path": str(NOTEBOOK.parent)}},
    ).execute()
    nbformat.write(nb, NOTEBOOK)  # the committed outputs are this run's
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    stderr = "".join(o.get("text", "") for o in outputs if o.get("name") == "stderr")
    assert not stderr, f"the notebook printed to stderr (warnings?):\n{stderr}"
    text = "".join(o.get("text", "") for o in outputs)
    assert "mse_x100" in text and "d(MSE×100)/dω" in text and "vmap: ω = 50" in text
    grads = [line.split("d(MSE×100)/dω = ")[1] for line in text.splitlines() if "vmap" in line]
    assert len(grads) == 2 and all(math.isfinite(float(g)) and float(g) != 0 for g in grads), grads
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 2  # the disparity/error figure with colour bars, and the EPI
