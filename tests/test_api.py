"""API conventions (in the style of dm_pix's api_test): the public names, keyword-only options,
docstring sections, and no private imports across packages."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import mvedge_jax

PACKAGE = Path(mvedge_jax.__file__).resolve().parent

#: The stable names of the top-level package.
PUBLIC = (
    "CentreConfig",
    "ChainOutput",
    "EdgeConfig",
    "EdgeRefineConfig",
    "EdgeSet",
    "EpiConfig",
    "FillConfig",
    "FilterConfig",
    "LabelConfig",
    "LightField",
    "ModelConfig",
    "OptimizeConfig",
    "OutlierConfig",
    "PipelineConfig",
    "ReconstructConfig",
    "SelectConfig",
    "SharpenConfig",
    "Result",
    "SurfaceConfig",
    "depth_metrics",
    "detect_edges",
    "enable_compilation_cache",
    "estimate_disparity",
    "estimate_disparity_arrays",
    "load_light_field",
    "optimize_disparity",
    "smooth_config",
    "sweep",
    "tune",
    "surface_vectors",
    "view_consistency",
)

#: Parameters that may be passed by position although they have a default: the stage's
#: configuration follows the data it configures, and an optional validity mask is data.
POSITIONAL_OPTIONS = {"config", "mask"}


def _public_functions():
    return [
        (n, getattr(mvedge_jax, n)) for n in PUBLIC if inspect.isfunction(getattr(mvedge_jax, n))
    ]


def test_public_names_and_version():
    for name in PUBLIC:
        assert hasattr(mvedge_jax, name), name
    assert isinstance(mvedge_jax.__version__, str) and mvedge_jax.__version__[0].isdigit()


@pytest.mark.parametrize(
    "name,fn", _public_functions(), ids=lambda v: v if isinstance(v, str) else ""
)
def test_options_are_keyword_only(name, fn):
    sig = inspect.signature(fn)
    positional_defaults = [
        p.name
        for p in sig.parameters.values()
        if p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
        and p.default is not inspect.Parameter.empty
        and p.name not in POSITIONAL_OPTIONS
    ]
    assert not positional_defaults, f"{name}: options {positional_defaults} must be keyword-only"


@pytest.mark.parametrize(
    "name,fn", _public_functions(), ids=lambda v: v if isinstance(v, str) else ""
)
def test_docstring_sections(name, fn):
    doc = inspect.getdoc(fn) or ""
    assert doc, f"{name} has no docstring"
    if inspect.signature(fn).parameters:
        assert "Args:" in doc, f"{name}: docstring lacks an Args section"
    assert "Returns:" in doc, f"{name}: docstring lacks a Returns section"


@pytest.mark.parametrize("name", [n for n in PUBLIC if inspect.isclass(getattr(mvedge_jax, n))])
def test_classes_document_attributes(name):
    doc = inspect.getdoc(getattr(mvedge_jax, name)) or ""
    assert "Attributes" in doc, f"{name}: docstring lacks an Attributes section"


def _private_cross_imports():
    """``(file, module)`` for every import of another package's private module."""
    found = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        own = rel.parts[0] if len(rel.parts) > 1 else None
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom) or node.module is None:
                continue
            parts = node.module.split(".")
            if node.level == 0:
                if parts[0] != "mvedge_jax":
                    continue
                parts = parts[1:]
            elif node.level == 1 and own is not None:
                parts = [own, *parts]
            if len(parts) >= 2 and parts[1].startswith("_") and parts[0] != own:
                found.append((str(rel), node.module))
    return found


def test_no_private_imports_across_packages():
    assert _private_cross_imports() == []
