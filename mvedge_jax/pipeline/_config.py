"""`PipelineConfig`: the configuration of the whole chain, one frozen config per stage, and
its TOML form."""

from __future__ import annotations

import equinox as eqx

from ..diff import ModelConfig, OptimizeConfig, RenderConfig
from ..edges import EdgeConfig
from ..reconstruct import ReconstructConfig
from ..surface import SurfaceConfig
from ._checks import ConfigError, ConfigTypeError, override_config

#: The default of ``PipelineConfig.optimize``: the thesis schedule and losses (Sec. 7.1.5) with
#: settings measured to suit a start from the Ch. 6 result (dense, accurate labels): a narrower
#: splat (σ_S = 0.8, σ_λ = 0.5 instead of 1.3, 0.71) and stronger image-edge stops
#: (``q_scale`` 30) encode the Ch. 6 map far more faithfully; a low density ρ = 0.1 keeps
#: visible neighbours from hiding each other; larger tile capacities avoid overflow with
#: dense points; one pass at a third of the authors' learning rates (Adam moves every label
#: by about the learning rate per step, and more passes did not help on HCI crops).
#: Measured at full resolution (centre view, Ch. 6 → optimised and sharpened, before the
#: merge of `optimize_disparity`'s ``select_initial``): backgammon MSE×100 1.31 → 1.33,
#: BadPix(0.07) 1.76 → 1.45, BadPix(0.01) 13.9 → 24.5; antinous 8.10 → 7.88, 16.4 → 12.7,
#: 74.6 → 62.3 (session 3). With the merge: backgammon 1.31, 1.29, 12.1; antinous 7.81,
#: 12.8, 68.5 (session 4). With the merge and the residual diffusion of
#: `optimize_disparity`'s ``diffuse_residual`` (the default since session 5): backgammon
#: 1.29, 1.24, 12.3; antinous 6.50, 12.8, 69.9. ``OptimizeConfig()`` (one pass) instead:
#: backgammon 3.64, 4.99 (session 2). Twice the label rate (0.01) instead: antinous 7.98,
#: 12.96, 62.1 before the merge (session 4; worse than 0.005). Session 6 (after the Ch. 6
#: disocclusion and matting changes), on an H100 (whose scatter order varies, so the Ch. 6
#: start varies by ±0.1 BadPix(0.07) from run to run): the session-5 rates (0.005, 0.03)
#: gave antinous BadPix(0.07) −23.0 to −24.5% in five runs; label rate 0.008 and position
#: rate 0.05 with ``select_min_change = 0`` (every pixel may take the optimised value)
#: −25.2 to −26.0% in three runs, and backgammon −26.8% (against −27.5%). Session 8 (2-core
#: CPU, these rates): with the departures splatted per point (`predict`'s ``prior``; the
#: start is now the Ch. 6 map exactly) and the SSIM term in the merge's cost
#: (``ReconstructConfig.select_ssim``), antinous 8.02, 12.06 (−26.1%), 64.4 and backgammon
#: 1.22, 1.19 (−31.6%), 16.5; the optimised map alone (before sharpening and merge) went
#: from 11.07, 18.31 to 7.94, 15.66 on antinous.
OPTIMIZE_DEFAULT = OptimizeConfig(
    model=ModelConfig(
        render=RenderConfig(
            sigma_label=0.8,
            sigma_weight=0.5,
            density=0.1,
            tile_levels=((128, 1.0), (200, 0.5)),
        ),
        q_scale=30.0,
    ),
    passes=1,
    learning_rate=(0.008, 0.05, 0.005, 0.005),
)


class PipelineConfig(eqx.Module):
    """Configuration of the whole pipeline: one frozen config per stage.

    Attributes:
        edges: multi-view edge detection (Ch. 4.1).
        surface: surface vectors and depth-edge confidence (Ch. 4.2–4.3).
        reconstruct: smooth 4D reconstruction (Ch. 6); its cross-hair/off-cross-hair part
            also propagates an optimised centre map (`optimize_disparity`).
        optimize: the optional Ch. 7 refinement (`optimize_disparity`, ``mvedge depth
            --optimize``); default `OPTIMIZE_DEFAULT` (``OptimizeConfig()`` is the thesis
            configuration).
    """

    edges: EdgeConfig = EdgeConfig()
    surface: SurfaceConfig = SurfaceConfig()
    reconstruct: ReconstructConfig = ReconstructConfig()
    optimize: OptimizeConfig = OPTIMIZE_DEFAULT


CONFIG_TABLES = ("edges", "surface", "reconstruct", "optimize")


def config_from_dict(data: dict, *, source: str | None = None) -> PipelineConfig:
    """Build a `PipelineConfig` from ``{"edges": {...}, "surface": {...}, "reconstruct": {...},
    "optimize": {...}}`` (keyword arguments of the stage configs; missing tables and keys keep
    the defaults).

    Nested configs are sub-tables, e.g. in TOML ``[optimize.loss]`` (``LossConfig``),
    ``[optimize.model]``, ``[optimize.model.render]`` or ``[reconstruct.epi_solver]``; arrays
    become tuples (``blocks``, ``learning_rate``, ``tile_levels``). Every value is checked
    against the type of the field's default (`override_config`): ``"false"`` is not a
    boolean, an array is not a number.

    Args:
        data: the tables.
        source: the file they came from, named in every error message.

    Raises:
        ValueError: on an unknown table name or a bad parameter value (`ConfigError`).
        TypeError: on an unknown parameter or a value of the wrong type (`ConfigTypeError`,
            also a `ValueError`).
    """
    where = f"{source}: " if source else ""
    if not isinstance(data, dict):
        raise ConfigTypeError(f"{where}the configuration must be a table of tables")
    unknown = set(data) - set(CONFIG_TABLES)
    if unknown:
        raise ConfigError(
            f"{where}unknown config tables {sorted(unknown)}; use {', '.join(CONFIG_TABLES)}"
        )
    base = PipelineConfig()
    return PipelineConfig(
        **{
            name: override_config(getattr(base, name), data.get(name, {}), name, source)
            for name in CONFIG_TABLES
        }
    )
