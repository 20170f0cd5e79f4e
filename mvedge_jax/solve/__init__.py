"""Weighted screened-Poisson solver: matrix-free operator, preconditioners, PCG with custom VJP."""

from ._operator import laplacian as laplacian
from ._operator import matvec as poisson_matvec  # noqa: F401  (public re-export)
from ._solve import SolverConfig as SolverConfig
from ._solve import SolveResult as SolveResult
from ._solve import solve_poisson as solve_poisson
from ._solve import solve_poisson_lineax as solve_poisson_lineax
from ._weights import guide_edge_weights as guide_edge_weights
