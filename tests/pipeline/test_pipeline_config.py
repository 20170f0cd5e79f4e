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

from mvedge_jax import (
    CentreConfig,
    EdgeConfig,
    FilterConfig,
    LabelConfig,
    ReconstructConfig,
    SharpenConfig,
    SurfaceConfig,
)
from mvedge_jax.cli import main
from mvedge_jax.pipeline import (
    PipelineConfig,
    config_from_toml,
    config_to_dict,
    config_to_toml,
    get_path,
    hyperparameter_paths,
    path_spec,
    replace_paths,
    smooth_config,
    with_values,
)

DOC = Path(__file__).resolve().parents[2] / "docs" / "GRADIENTS.md"


@pytest.mark.parametrize(
    "cls,kwargs,match",
    [
        (
            FilterConfig,
            {"presmooth_sigma": "0.85"},
            r"FilterConfig\.presmooth_sigma must be a real",
        ),
        (FilterConfig, {"presmooth_sigma": np.ones(3)}, r"presmooth_sigma .*shape \(3,\)"),
        (FilterConfig, {"presmooth_sigma": True}, r"presmooth_sigma must be a real"),
        (LabelConfig, {"nms": "false"}, r"LabelConfig\.nms must be true or false"),
        (FilterConfig, {"n_filters": 60.5}, r"FilterConfig\.n_filters must be an integer"),
        (SurfaceConfig, {"blur_radius": True}, r"blur_radius must be an integer"),
        (ReconstructConfig, {"colour_space": 3}, r"colour_space must be a string"),
        (CentreConfig, {"solver": 1.0}, r"CentreConfig\.solver must be a SolverConfig"),
        (EdgeConfig, {"filter": LabelConfig()}, r"EdgeConfig\.filter must be a FilterConfig"),
        (ReconstructConfig, {"centre": 1.0}, r"ReconstructConfig\.centre must be a CentreConfig"),
    ],
)
def test_wrong_types_raise_type_error_naming_the_field(cls, kwargs, match):
    with pytest.raises(TypeError, match=match):
        cls(**kwargs)


@pytest.mark.parametrize(
    "cls,kwargs,match",
    [
        (FilterConfig, {"presmooth_sigma": 0.0}, r"presmooth_sigma must be > 0"),
        (FilterConfig, {"presmooth_sigma": float("nan")}, r"presmooth_sigma must be finite"),
        (FilterConfig, {"n_filters": 2}, r"n_filters must be >= 3"),
        (FilterConfig, {"d_max_fallback": 1e6}, r"d_max_fallback must be .*<= 64"),
        (LabelConfig, {"strategy": "fuzzy"}, r"strategy must be one of \('hard', 'soft'\)"),
        (CentreConfig, {"omega": -1.0}, r"omega must be >= 0"),
        (SharpenConfig, {"filter": "mode"}, r"SharpenConfig\.filter must be one of"),
        (SurfaceConfig, {"smooth_eps": 0.0}, r"smooth_eps must be > 0"),
    ],
)
def test_out_of_range_values_raise_value_error(cls, kwargs, match):
    with pytest.raises(ValueError, match=match):
        cls(**kwargs)


def test_hyperparameters_are_floating_in_any_precision(x64):
    c = FilterConfig(presmooth_sigma=1, edge_shift=np.float64(1.5))
    for v in (c.presmooth_sigma, c.edge_shift):
        assert jnp.issubdtype(v.dtype, jnp.floating) and v.ndim == 0
    assert CentreConfig(omega=150).omega.dtype == jnp.float64
    # Weakly typed leaves: they follow the precision of the arrays they meet.
    leaf = PipelineConfig().edges.filter.presmooth_sigma
    assert leaf.weak_type
    assert (jnp.ones(3, jnp.float64) * leaf).dtype == jnp.float64
    assert (jnp.ones(3, jnp.float32) * leaf).dtype == jnp.float32


def test_configs_built_inside_jit_and_vmap_are_not_checked():
    def f(s):
        return EdgeConfig(filter=FilterConfig(presmooth_sigma=s)).filter.presmooth_sigma * 2.0

    np.testing.assert_allclose(jax.vmap(jax.jit(f))(jnp.asarray([0.5, 1.0])), [1.0, 2.0])


def test_toml_round_trip_keeps_every_field():
    base = PipelineConfig()
    cfg = with_values(base, {"edges.filter.presmooth_sigma": 0.7, "reconstruct.centre.omega": 99.0})
    label = dataclasses.replace(cfg.edges.label, strategy="soft")
    cfg = dataclasses.replace(cfg, edges=dataclasses.replace(cfg.edges, label=label))
    text = config_to_toml(cfg)
    back = config_from_toml(text)
    assert config_to_dict(back) == config_to_dict(cfg)
    assert config_to_dict(back) != config_to_dict(base)
    assert float(back.edges.filter.presmooth_sigma) == pytest.approx(0.7)
    assert back.edges.label.strategy == "soft"
    # every default is written, including the nested sub-config, solver and optimize tables
    tables = (
        "[edges.filter]",
        "[edges.label]",
        "[edges.outliers]",
        "[edges.refine]",
        "[surface]",
        "[reconstruct]",
        "[reconstruct.centre]",
        "[reconstruct.centre.solver]",
        "[reconstruct.sharpen]",
        "[reconstruct.select]",
        "[reconstruct.epi]",
        "[reconstruct.epi.solver]",
        "[reconstruct.fill]",
        "[reconstruct.fill.solver]",
        "[optimize]",
    )
    for table in tables:
        assert table in text, table


def test_toml_nested_tables_are_strict():
    cfg = config_from_toml("[reconstruct.epi]\nc = 0.3\n[edges.filter]\nn_filters = 31\n")
    assert float(cfg.reconstruct.epi.c) == pytest.approx(0.3)
    assert cfg.edges.filter.n_filters == 31
    assert float(cfg.reconstruct.fill.c) == 2.0  # same name, other sub-config: untouched
    # a flat (pre-nesting) key is an unknown key, named with its table
    with pytest.raises(TypeError, match=r"unknown key reconstruct\.omega; ReconstructConfig has"):
        config_from_toml("[reconstruct]\nomega = 1.0\n")
    with pytest.raises(TypeError, match=r"unknown key edges\.label\.presmooth_sigma"):
        config_from_toml("[edges.label]\npresmooth_sigma = 1.0\n")
    with pytest.raises(TypeError, match=r"edges\.filter expects a table"):
        config_from_toml("[edges]\nfilter = 3\n")


def test_cli_config_dump_reads_back(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["config", "--dump"])
    assert res.exit_code == 0, res.output
    assert config_to_dict(config_from_toml(res.output)) == config_to_dict(PipelineConfig())
    f = tmp_path / "cfg.toml"
    f.write_text("[reconstruct.centre]\nomega = 42.0\n")
    res = runner.invoke(main, ["config", "--dump", "--config", str(f)])
    assert res.exit_code == 0, res.output
    assert "[reconstruct.centre]" in res.output and "[edges.filter]" in res.output
    assert float(config_from_toml(res.output).reconstruct.centre.omega) == 42.0
    assert runner.invoke(main, ["config"]).exit_code != 0


def test_path_spec_gives_the_declared_bounds():
    cfg = PipelineConfig()
    ratio = path_spec(cfg, "reconstruct.seeds.ratio")
    assert (ratio.lower, ratio.upper, ratio.differentiable) == (0.0, 1.0, False)
    sigma_d = path_spec(cfg, "edges.refine.sigma_d")
    assert sigma_d.lower == 0.0 and sigma_d.lower_open and sigma_d.differentiable
    assert path_spec(cfg, "edges.refine.trilateral").kind == "bool"
    with pytest.raises(AttributeError, match="no field 'nope'"):
        path_spec(cfg, "edges.refine.nope")
    with pytest.raises(AttributeError):
        path_spec(cfg, "edges.nope.sigma_d")


def test_paths_get_replace_and_with_values():
    cfg = PipelineConfig()
    paths = hyperparameter_paths(differentiable=True)
    assert "edges.filter.presmooth_sigma" in paths and "reconstruct.centre.omega" in paths
    assert "edges.label.min_confidence" in hyperparameter_paths(differentiable=False)
    assert "reconstruct.epi.min_confidence" in hyperparameter_paths(differentiable=False)
    assert len(set(hyperparameter_paths())) == len(hyperparameter_paths()) == 86
    assert set(paths).isdisjoint(hyperparameter_paths(differentiable=False))
    replaced = replace_paths(cfg, {"surface.offset": jnp.asarray(2.0)})
    assert float(get_path(replaced, "surface.offset")) == 2.0
    assert float(get_path(cfg, "surface.offset")) == 1.0
    with pytest.raises(AttributeError):
        replace_paths(cfg, {"surface.nope": 1.0})
    replaced = replace_paths(cfg, {"reconstruct.epi.c": 0.3})
    assert float(get_path(replaced, "reconstruct.epi.c")) == pytest.approx(0.3)
    assert float(get_path(replaced, "reconstruct.fill.c")) == 2.0
    with pytest.raises(AttributeError):
        replace_paths(cfg, {"reconstruct.omega": 1.0})
    with pytest.raises(ValueError, match="omega must be >= 0"):
        with_values(cfg, {"reconstruct.centre.omega": -1.0})
    with pytest.raises(AttributeError):
        with_values(cfg, {"reconstruct.omega": 1.0})
    nested = with_values(
        cfg,
        {
            "reconstruct.centre.omega": 7.0,
            "reconstruct.centre.solver.max_iters": 9,
            "reconstruct.colour_space": "rgb",
            "edges.outliers.tau": 0.5,
        },
    )
    assert float(nested.reconstruct.centre.omega) == 7.0
    assert nested.reconstruct.centre.solver.max_iters == 9
    assert nested.reconstruct.colour_space == "rgb"
    assert float(nested.edges.outliers.tau) == 0.5
    assert float(nested.reconstruct.centre.a) == float(cfg.reconstruct.centre.a)
    smooth = smooth_config(cfg)
    assert smooth.edges.label.strategy == "soft" and smooth.reconstruct.sharpen.filter == "mean"
    assert not smooth.reconstruct.epi.visibility_fill
    assert PipelineConfig().reconstruct.epi.visibility_fill


def _doc_table() -> dict[str, str]:
    rows = {}
    for line in DOC.read_text().splitlines():
        m = re.match(r"\|\s*`([a-z_]+(?:\.[a-z_0-9]+)+)`\s*\|\s*(\w+)", line)
        if m:
            rows[m.group(1)] = m.group(2)
    return rows


def test_gradient_table_in_docs_matches_the_field_declarations():
    table = _doc_table()
    expect = {p: "smooth" for p in hyperparameter_paths(differentiable=True)}
    expect.update({p: "threshold" for p in hyperparameter_paths(differentiable=False)})
    assert table == expect


@pytest.mark.parametrize(
    "text, message",
    [
        ('[reconstruct.centre.solver]\nmax_iters = "5"\n', "reconstruct.centre.solver.max_iters"),
        ("[reconstruct.epi.solver]\nrtol = -1\n", r"\[reconstruct.epi.solver\] SolverConfig.rtol"),
        ('[reconstruct.fill.solver]\npreconditioner = "ilu"\n', "SolverConfig.preconditioner"),
    ],
)
def test_solver_tables_are_validated_like_every_config(text, message):
    with pytest.raises(ValueError, match=message):
        config_from_toml(text)
