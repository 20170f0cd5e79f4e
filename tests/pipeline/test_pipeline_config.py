"""Configs: one field idiom, strict validation, TOML round trip, hyperparameter paths."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from click.testing import CliRunner

from mvedge_jax import EdgeConfig, ReconstructConfig, SurfaceConfig
from mvedge_jax.cli import main
from mvedge_jax.pipeline import (
    PipelineConfig,
    config_from_toml,
    config_to_dict,
    config_to_toml,
    get_path,
    hyperparameter_paths,
    replace_paths,
    smooth_config,
    with_values,
)

DOC = Path(__file__).resolve().parents[2] / "docs" / "GRADIENTS.md"


@pytest.mark.parametrize(
    "cls,kwargs,match",
    [
        (EdgeConfig, {"presmooth_sigma": "0.85"}, r"EdgeConfig\.presmooth_sigma must be a real"),
        (EdgeConfig, {"presmooth_sigma": np.ones(3)}, r"presmooth_sigma .*shape \(3,\)"),
        (EdgeConfig, {"presmooth_sigma": True}, r"presmooth_sigma must be a real"),
        (EdgeConfig, {"nms": "false"}, r"EdgeConfig\.nms must be true or false"),
        (EdgeConfig, {"n_filters": 60.5}, r"EdgeConfig\.n_filters must be an integer"),
        (SurfaceConfig, {"blur_radius": True}, r"blur_radius must be an integer"),
        (ReconstructConfig, {"colour_space": 3}, r"colour_space must be a string"),
        (ReconstructConfig, {"solver": 1.0}, r"ReconstructConfig\.solver must be a SolverConfig"),
    ],
)
def test_wrong_types_raise_type_error_naming_the_field(cls, kwargs, match):
    with pytest.raises(TypeError, match=match):
        cls(**kwargs)


@pytest.mark.parametrize(
    "cls,kwargs,match",
    [
        (EdgeConfig, {"presmooth_sigma": 0.0}, r"presmooth_sigma must be > 0"),
        (EdgeConfig, {"presmooth_sigma": float("nan")}, r"presmooth_sigma must be finite"),
        (EdgeConfig, {"n_filters": 2}, r"n_filters must be >= 3"),
        (EdgeConfig, {"d_max_fallback": 1e6}, r"d_max_fallback must be .*<= 64"),
        (EdgeConfig, {"strategy": "fuzzy"}, r"strategy must be one of \('hard', 'soft'\)"),
        (ReconstructConfig, {"omega": -1.0}, r"omega must be >= 0"),
        (ReconstructConfig, {"sharpen_filter": "mode"}, r"sharpen_filter must be one of"),
        (SurfaceConfig, {"smooth_eps": 0.0}, r"smooth_eps must be > 0"),
    ],
)
def test_out_of_range_values_raise_value_error(cls, kwargs, match):
    with pytest.raises(ValueError, match=match):
        cls(**kwargs)


def test_hyperparameters_are_floating_in_any_precision(x64):
    c = EdgeConfig(presmooth_sigma=1, edge_shift=np.float64(1.5))
    for v in (c.presmooth_sigma, c.edge_shift):
        assert jnp.issubdtype(v.dtype, jnp.floating) and v.ndim == 0
    assert ReconstructConfig(omega=150).omega.dtype == jnp.float64
    # Weakly typed leaves: they follow the precision of the arrays they meet.
    leaf = PipelineConfig().edges.presmooth_sigma
    assert leaf.weak_type
    assert (jnp.ones(3, jnp.float64) * leaf).dtype == jnp.float64
    assert (jnp.ones(3, jnp.float32) * leaf).dtype == jnp.float32


def test_configs_built_inside_jit_and_vmap_are_not_checked():
    def f(s):
        return EdgeConfig(presmooth_sigma=s).presmooth_sigma * 2.0

    np.testing.assert_allclose(jax.vmap(jax.jit(f))(jnp.asarray([0.5, 1.0])), [1.0, 2.0])


def test_toml_round_trip_keeps_every_field():
    base = PipelineConfig()
    cfg = with_values(base, {"edges.presmooth_sigma": 0.7, "reconstruct.omega": 99.0})
    cfg = dataclasses.replace(cfg, edges=dataclasses.replace(cfg.edges, strategy="soft"))
    text = config_to_toml(cfg)
    back = config_from_toml(text)
    assert config_to_dict(back) == config_to_dict(cfg)
    assert config_to_dict(back) != config_to_dict(base)
    assert float(back.edges.presmooth_sigma) == pytest.approx(0.7)
    assert back.edges.strategy == "soft"
    # every default is written, including the nested solver and optimize tables
    for table in ("[edges]", "[surface]", "[reconstruct]", "[reconstruct.solver]", "[optimize]"):
        assert table in text


def test_cli_config_dump_reads_back(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["config", "--dump"])
    assert res.exit_code == 0, res.output
    assert config_to_dict(config_from_toml(res.output)) == config_to_dict(PipelineConfig())
    f = tmp_path / "cfg.toml"
    f.write_text("[reconstruct]\nomega = 42.0\n")
    res = runner.invoke(main, ["config", "--dump", "--config", str(f)])
    assert res.exit_code == 0, res.output
    assert float(config_from_toml(res.output).reconstruct.omega) == 42.0
    assert runner.invoke(main, ["config"]).exit_code != 0


def test_paths_get_replace_and_with_values():
    cfg = PipelineConfig()
    paths = hyperparameter_paths(differentiable=True)
    assert "edges.presmooth_sigma" in paths and "reconstruct.omega" in paths
    assert "edges.min_confidence" in hyperparameter_paths(differentiable=False)
    assert set(paths).isdisjoint(hyperparameter_paths(differentiable=False))
    replaced = replace_paths(cfg, {"surface.offset": jnp.asarray(2.0)})
    assert float(get_path(replaced, "surface.offset")) == 2.0
    assert float(get_path(cfg, "surface.offset")) == 1.0
    with pytest.raises(AttributeError):
        replace_paths(cfg, {"surface.nope": 1.0})
    with pytest.raises(ValueError, match="omega must be >= 0"):
        with_values(cfg, {"reconstruct.omega": -1.0})
    smooth = smooth_config(cfg)
    assert smooth.edges.strategy == "soft" and smooth.reconstruct.sharpen_filter == "mean"


def _doc_table() -> dict[str, str]:
    rows = {}
    for line in DOC.read_text().splitlines():
        m = re.match(r"\|\s*`([a-z_]+\.[a-z_0-9]+)`\s*\|\s*(\w+)", line)
        if m:
            rows[m.group(1)] = m.group(2)
    return rows


def test_gradient_table_in_docs_matches_the_field_declarations():
    table = _doc_table()
    expect = {p: "smooth" for p in hyperparameter_paths(differentiable=True)}
    expect.update({p: "threshold" for p in hyperparameter_paths(differentiable=False)})
    assert table == expect
