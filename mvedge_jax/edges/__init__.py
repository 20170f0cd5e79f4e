"""Multi-view edge detection on EPIs (thesis Ch. 4.1)."""

from ._edgeset import HORIZONTAL as HORIZONTAL, VERTICAL as VERTICAL, EdgeSet as EdgeSet
from ._edgeset import concatenate as concatenate
