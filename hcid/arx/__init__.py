"""MISO ARX identification over candidate grids (SPEC sections 3 and 4).

:mod:`hcid.arx.grid` defines the grids, :mod:`hcid.arx.engine` fits them,
the slow, obvious twin the tests compare with is ``tests/naive.py``.
"""

from hcid.arx.engine import GridFit, best, fit_grid
from hcid.arx.grid import Grid, candidates, max_lag, n_candidates, n_parameters
from hcid.arx.simulation import simulate

__all__ = [
    "Grid",
    "GridFit",
    "best",
    "candidates",
    "fit_grid",
    "max_lag",
    "n_candidates",
    "n_parameters",
    "simulate",
]
