"""The quickstart notebook executes top to bottom (at a small resolution), so it cannot rot."""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "quickstart.ipynb"


def test_quickstart_notebook_executes(data_dir, monkeypatch):
    monkeypatch.setenv("MVEDGE_DATA", str(data_dir))
    monkeypatch.setenv("MVEDGE_NOTEBOOK_SCALE", "0.25")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(
        nb,
        timeout=900,
        kernel_name="python3",
        resources={"metadata": {"path": str(NOTEBOOK.parent)}},
    ).execute()
    text = "".join(
        o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
    )
    assert "mse_x100" in text and "d/dω" in text
    assert "nan" not in text.split("d/dω")[1].lower()
