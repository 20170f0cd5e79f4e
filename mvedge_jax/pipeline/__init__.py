"""End-to-end entry points: light field → edges → surface vectors → disparity for every view.

The stages (thesis Ch. 4.1 → 4.2–4.3 → 6) are jittable pure functions of arrays
(`estimate_disparity_arrays`). The `estimate_disparity` driver compiles each stage, runs it,
and records the seconds per stage. `optimize_disparity` refines a result with the
differentiable edge model (thesis Ch. 7) and propagates the refined centre map to every view.
"""

from ._chain import STAGES as STAGES
from ._chain import ChainOutput as ChainOutput
from ._chain import edges_stage as edges_stage
from ._chain import estimate_disparity_arrays as estimate_disparity_arrays
from ._chain import reconstruct_stage as reconstruct_stage
from ._chain import surface_stage as surface_stage
from ._checks import check_memory_before_loading as check_memory_before_loading
from ._compile import STAGE_CACHE as STAGE_CACHE
from ._compile import StageCache as StageCache
from ._config import CONFIG_TABLES as CONFIG_TABLES
from ._config import OPTIMIZE_DEFAULT as OPTIMIZE_DEFAULT
from ._config import PipelineConfig as PipelineConfig
from ._config import config_from_dict as config_from_dict
from ._config import config_from_toml as config_from_toml
from ._config import config_to_dict as config_to_dict
from ._config import config_to_toml as config_to_toml
from ._config import get_path as get_path
from ._config import hyperparameter_paths as hyperparameter_paths
from ._config import path_spec as path_spec
from ._config import replace_paths as replace_paths
from ._config import smooth_config as smooth_config
from ._config import with_values as with_values
from ._driver import Result as Result
from ._driver import cross_hair_others as cross_hair_others
from ._driver import estimate_disparity as estimate_disparity
from ._driver import optimize_disparity as optimize_disparity
from ._driver import optimize_steps as optimize_steps
from ._outputs import FIGURES as FIGURES
from ._outputs import config_to_json as config_to_json
from ._outputs import device_info as device_info
from ._outputs import edge_epi_figure as edge_epi_figure
from ._outputs import epi_overlay as epi_overlay
from ._outputs import provenance as provenance
from ._outputs import quality_metrics as quality_metrics
from ._outputs import strict_json as strict_json
from ._outputs import write_outputs as write_outputs
from ._sweep import sweep as sweep
from ._tune import TuneScene as TuneScene
from ._tune import chain_loss as chain_loss
from ._tune import tune as tune
