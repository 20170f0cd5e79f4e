"""The main job end to end: `estimate_disparity` and `mvedge depth` / `mvedge demo`."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from mvedge_jax.cli import main
from mvedge_jax.io import load_light_field
from mvedge_jax.metrics import depth_metrics
from mvedge_jax.pipeline import PipelineConfig, config_from_dict, estimate_disparity
from mvedge_jax.reconstruct import centre_seeds
from mvedge_jax.synthetic import default_light_field

METRIC_KEYS = {
    "seconds_total",
    "compile_seconds",
    "seconds_per_stage",
    "view_consistency",
    "n_views",
}
GT_KEYS = {"mse_x100", "badpix_0.01", "badpix_0.03", "badpix_0.07", "q25_x100"}


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """`mvedge demo` once for the module (the embedded default input of the README)."""
    out = tmp_path_factory.mktemp("demo") / "out"
    res = CliRunner().invoke(main, ["demo", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out, res.output


def test_demo_writes_every_output(demo_run):
    out, output = demo_run
    lf = default_light_field()
    U, V = lf.grid
    metrics = json.loads((out / "metrics.json").read_text())
    assert METRIC_KEYS | GT_KEYS <= set(metrics)
    assert set(metrics["seconds_per_stage"]) == {"edges", "surface", "reconstruct"}
    assert metrics["n_views"] == U * V
    assert len(list((out / "disparity").glob("view_*.pfm"))) == U * V
    for png in (
        "centre_disparity",
        "mosaic",
        "edges_overlay",
        "epi_horizontal",
        "epi_vertical",
        "error_map",
        "badpix_0.07",
    ):
        assert (out / f"{png}.png").is_file(), png
    d = np.load(out / "disparity.npz")["disparity"]
    assert d.shape == (U, V) + lf.size and np.isfinite(d).all()
    assert "MSE" in output and "all 81 views" in output


def test_demo_accuracy_on_every_view(demo_run):
    """Every view of the synthetic scene, against its own exact GT (regression bounds)."""
    out, _ = demo_run
    lf = default_light_field()
    d = np.load(out / "disparity.npz")["disparity"]
    gt, gtm = np.asarray(lf.gt_disparity), np.asarray(lf.gt_mask)
    U, V = lf.grid
    per_view = [depth_metrics(d[r, c], gt[r, c], gtm[r, c]) for r in range(U) for c in range(V)]
    worst = max(m["mse_x100"] for m in per_view)
    # Measured 0.498 (mean of views 0.318, mean BadPix(0.07) 1.59) on the scene with colours
    # mixed in linear light; the target is every view <= 0.5 (docs/ACCURACY.md; the
    # bound leaves room for floating-point differences between CPUs).
    assert worst <= 0.51, worst
    assert np.mean([m["mse_x100"] for m in per_view]) < 0.35
    assert np.mean([m["badpix_0.07"] for m in per_view]) < 1.8
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["view_consistency"] < 0.02


def test_refuses_existing_output_without_force(demo_run):
    out, _ = demo_run
    res = CliRunner().invoke(main, ["demo", "--out", str(out)])
    assert res.exit_code != 0 and "--force" in res.output


def test_refuses_output_inside_input(data_dir, tmp_path):
    src = data_dir / "hci_old" / "stillLife_lf_3x3"
    res = CliRunner().invoke(main, ["depth", str(src), "--out", str(src / "out")])
    assert res.exit_code != 0 and "inside the input folder" in res.output
    assert not (src / "out").exists()


def test_bad_config_file_is_reported(tmp_path, data_dir):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[nonsense]\nx = 1\n")
    res = CliRunner().invoke(
        main,
        [
            "depth",
            str(data_dir / "hci_old" / "stillLife_lf_3x3"),
            "--out",
            str(tmp_path / "o"),
            "--config",
            str(cfg),
        ],
    )
    assert res.exit_code != 0 and "unknown config tables" in res.output
    assert not (tmp_path / "o").exists()


def test_config_from_dict_overrides_one_stage():
    cfg = config_from_dict({"surface": {"gradient_sigma": 1.5}})
    assert float(cfg.surface.gradient_sigma) == 1.5
    assert isinstance(cfg, PipelineConfig)
    with pytest.raises(TypeError):
        config_from_dict({"surface": {"no_such_parameter": 1}})


def test_nan_views_are_rejected():
    lf = default_light_field()
    with pytest.raises(ValueError, match="NaN"):  # refused by the LightField contract itself
        bad = type(lf)(views=lf.views.at[4, 4, 0, 0, 0].set(np.nan), view_mask=lf.view_mask)
        estimate_disparity(bad)


@pytest.mark.slow
def test_backgammon_accuracy(data_dir):
    """The targets of a real GT scene (thesis Ch. 6 pipeline, default config, centre view,
    full frame): MSE×100 ≤ 1.2 and BadPix(0.07) ≤ 1.5 %. Measured on the CPU: 0.866 and
    1.142 (docs/ACCURACY.md)."""
    lf = load_light_field(data_dir / "hci4d" / "stratified" / "backgammon")
    res = estimate_disparity(lf)
    rc, cc = lf.centre_index
    m = depth_metrics(np.asarray(res.disparity[rc, cc]), np.asarray(lf.centre_gt))
    assert res.disparity.shape == (9, 9, 512, 512)
    assert m["badpix_0.07"] <= 1.5, m
    assert m["mse_x100"] <= 1.2, m
    # every linear solve of the run is reported, and converged; no warning on this scene
    diag = res.diagnostics
    assert set(diag["solver"]) == {
        "surface",
        "reconstruct.centre",
        "reconstruct.epi",
        "reconstruct.fill",
    }
    assert all(s["status"] == "converged" for s in diag["solver"].values()), diag
    assert diag["warnings"] == [] and diag["saturated_fraction"] == 0.0


@pytest.mark.slow
def test_antinous_accuracy(data_dir):
    """The targets of the sparsely textured GT scene (default config, centre view, full
    frame): MSE×100 ≤ 5.0 and BadPix(0.07) ≤ 10 %; measured on the CPU: 3.093 and 8.939
    (docs/ACCURACY.md). The floor below the wall (rows 455–511 left and right of the
    statue's base) has no edge label; its disparity rises from −1.5 to 1.7 px per view step
    towards the bottom, and only the photo-consistent samples of `centre_seeds` tell the
    diffusion so: they must exist there (between 1000 and 20000 sampled pixels in the view)
    and be accurate on the floor (median error below 0.15, fewer than 15 % off by 0.3; the
    floor's MSE×100 below 50)."""
    lf = load_light_field(data_dir / "hci4d" / "additional" / "antinous")
    res = estimate_disparity(lf)
    rc, cc = lf.centre_index
    gt = np.asarray(lf.centre_gt)
    d = np.asarray(res.disparity[rc, cc])
    m = depth_metrics(d, gt)
    assert m["badpix_0.07"] <= 10.0, m
    assert m["mse_x100"] <= 5.0, m
    floor = np.zeros(gt.shape, bool)
    floor[455:, :110] = True
    floor[455:, 410:] = True
    assert 100 * np.mean((d - gt)[floor] ** 2) < 50.0
    weight, value = (np.asarray(a) for a in centre_seeds(lf.views, res.edges, res.surface))
    sampled = weight > 0
    assert 1000 < sampled.sum() < 20000, sampled.sum()
    err = np.abs(value - gt)[floor & sampled]
    assert np.median(err) < 0.15 and np.mean(err > 0.3) < 0.15, (np.median(err), err.mean())
