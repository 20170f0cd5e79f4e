"""Weighted screened-Poisson solver: matrix-free operator, preconditioners, PCG with custom VJP."""

from ._operator import laplacian as laplacian
from ._operator import matvec as poisson_matvec  # noqa: F401  (public re-export)
from ._solve import CONVERGED as CONVERGED
from ._solve import MAX_STEPS as MAX_STEPS
from ._solve import NONFINITE as NONFINITE
from ._solve import STATUS_NAMES as STATUS_NAMES
from ._solve import SolverConfig as SolverConfig
from ._solve import SolveResult as SolveResult
from ._solve import describe_status as describe_status
from ._solve import solve_poisson as solve_poisson
from ._solve import solve_poisson_lineax as solve_poisson_lineax
from ._solve import solve_status as solve_status
from ._weights import guide_differences as guide_differences
from ._weights import guide_edge_weights as guide_edge_weights
