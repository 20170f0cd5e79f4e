"""File formats: HCI 4D, old HCI, view grids, PFM. The only package that touches files."""

from ._hci import read_hci4d as read_hci4d
from ._pfm import read_pfm as read_pfm, write_pfm as write_pfm
