"""Writing the main job's outputs (the only place besides the readers that touches files)."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ._images import write_png
from ._pfm import write_pfm


def check_output_dir(
    out: str | os.PathLike, source: str | os.PathLike | None, *, force: bool
) -> Path:
    """Validate an output folder before any work is done.

    Raises:
        ValueError: if ``out`` is the input folder or inside it, or exists and ``force`` is False.
    """
    out_p = Path(out).resolve()
    if source is not None:
        src = Path(source).resolve()
        if out_p == src or src in out_p.parents:
            raise ValueError(
                f"output folder {out_p} is inside the input folder {src}; choose another"
            )
    if out_p.exists() and not force:
        raise ValueError(f"output folder {out_p} exists; pass --force to replace it")
    return out_p


class OutputWriter:
    """Stage outputs in a temporary sibling folder and move it into place on `commit`.

    Nothing appears at the destination unless every file was written (no half-written output
    on failure); an existing destination is replaced only at commit time.
    """

    def __init__(self, out: str | os.PathLike):
        self.out = Path(out).resolve()
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(prefix=f".{self.out.name}.", dir=self.out.parent))

    def path(self, name: str) -> Path:
        p = self.tmp / name
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def png(self, name: str, rgb: np.ndarray) -> None:
        write_png(self.path(name), rgb)

    def pfm(self, name: str, image: np.ndarray) -> None:
        write_pfm(self.path(name), image)

    def json(self, name: str, obj) -> None:
        self.path(name).write_text(json.dumps(obj, indent=2, sort_keys=True) + "\n")

    def npz(self, name: str, **arrays) -> None:
        np.savez_compressed(self.path(name), **arrays)

    def commit(self) -> Path:
        if self.out.exists():
            shutil.rmtree(self.out)
        os.replace(self.tmp, self.out)
        return self.out

    def abort(self) -> None:
        shutil.rmtree(self.tmp, ignore_errors=True)
