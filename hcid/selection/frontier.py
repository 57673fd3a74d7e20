"""One record's frontier by one method, in memory (:class:`Frontier`).

The frontier is what selection works on: the best candidate of every order
triple (:func:`hcid.arx.engine.fit_grid`). ``frontier.parquet`` stores the
frontiers of a study one below the other; :meth:`Frontier.from_table` takes one
record's rows of it (or of a worker's part) into named arrays, and
:meth:`Frontier.to_arrow` gives them back as those columns. Selection over W,
the nb_ft of each row and a row's coefficients are read from the arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from hcid.arx.gridfit import GridFit
from hcid.selection.over_w import SelectionPath, breakpoints, select_at
from hcid.tables import FRONTIER, FRONTIER_NAMES, ORDER_COLUMNS

__all__ = ["Frontier"]

_NUMBERS = (*ORDER_COLUMNS, "d", "v", "vaf_estimation", "vaf_validation", "n_unstable")
_COEFFICIENTS = ("a", "b_ft", "b_e")
#: The engine's names of :data:`_NUMBERS` (:class:`hcid.arx.gridfit.GridFit`: input 1 ft, input 2 e).
_ENGINE_NAMES = {table: engine for engine, table in FRONTIER_NAMES.items()}


@dataclass(frozen=True, eq=False)
class Frontier:
    """The frontier of one record by one method: one row per order triple.

    Attributes
    ----------
    method : str
        The identification method.
    na, nb_ft, nb_e, nk_ft, nk_e : numpy.ndarray of int64
        The row's orders and delays (SPEC 3; input 1 is ft, input 2 e).
    d : numpy.ndarray of int64
        Number of parameters.
    v : numpy.ndarray of float64
        Mean squared simulation error over the validation rows (``inf``: every
        candidate of the triple unstable).
    vaf_estimation, vaf_validation : numpy.ndarray of float64
        Variance accounted for (percent).
    n_unstable : numpy.ndarray of int64
        Unstable candidates of the triple.
    coefficients : dict
        Per name (``a``, ``b_ft``, ``b_e``) the rows' coefficients one after the
        other and their offsets from 0 (row ``i`` is ``values[offsets[i]:offsets[i + 1]]``):
        :meth:`row_coefficients` reads them.
    """

    method: str
    na: np.ndarray
    nb_ft: np.ndarray
    nb_e: np.ndarray
    nk_ft: np.ndarray
    nk_e: np.ndarray
    d: np.ndarray
    v: np.ndarray
    vaf_estimation: np.ndarray
    vaf_validation: np.ndarray
    n_unstable: np.ndarray
    coefficients: dict[str, tuple[np.ndarray, np.ndarray]]

    @classmethod
    def from_table(cls, table: pa.Table) -> Frontier:
        """One record's rows of ``frontier.parquet`` (its columns; model and seed may be absent)."""
        for key in ("model", "seed", "method"):
            values = table.column(key).unique().to_pylist() if key in table.column_names else [None]
            if len(values) != 1:
                raise ValueError(f"a frontier is one record's by one method, got {key} {values}")
        methods = table.column("method").unique().to_pylist()
        numbers = {c: table.column(c).to_numpy() for c in _NUMBERS}
        coefficients = {}
        for c in _COEFFICIENTS:
            lists = table.column(c).combine_chunks()
            offsets = lists.offsets.to_numpy().astype(np.int64)  # into the whole child array of a slice
            values = lists.values.to_numpy()[offsets[0] : offsets[-1]].copy()
            coefficients[c] = (values, offsets - offsets[0])
        return cls(method=methods[0], **numbers, coefficients=coefficients)

    @classmethod
    def from_grid_fit(cls, fit: GridFit, method: str) -> Frontier:
        """The frontier :func:`hcid.arx.engine.fit_grid` returned (input 1 is ft, input 2 e), as
        :meth:`from_table` reads it from ``frontier.parquet``."""
        numbers = {c: np.asarray(getattr(fit, _ENGINE_NAMES.get(c, c))) for c in _NUMBERS}
        coefficients = {}
        for c in _COEFFICIENTS:
            rows = getattr(fit, _ENGINE_NAMES.get(c, c))
            offsets = np.concatenate(([0], np.cumsum([r.size for r in rows]))).astype(np.int64)
            values = np.concatenate(rows).astype(np.float64) if rows else np.empty(0)
            coefficients[c] = (values, offsets)
        return cls(method=method, **numbers, coefficients=coefficients)

    @property
    def n_rows(self) -> int:
        """Number of rows (order triples)."""
        return int(self.d.size)

    @property
    def orders(self) -> np.ndarray:
        """(na, nb_ft, nb_e, nk_ft, nk_e) per row, shape (n_rows, 5): the last tie rule's key."""
        return np.column_stack([getattr(self, c) for c in ORDER_COLUMNS])

    def path(self) -> SelectionPath:
        """The exact selection over W (:func:`~hcid.selection.over_w.breakpoints`)."""
        return breakpoints(self.d, self.v, self.orders)

    def select(self, w) -> np.ndarray:
        """The row selected at each ``w`` (:func:`~hcid.selection.over_w.select_at`)."""
        return select_at(self.d, self.v, self.orders, np.asarray(w, dtype=float).reshape(-1))

    def row_coefficients(self, row: int) -> dict[str, np.ndarray]:
        """Row ``row``'s coefficients: ``a`` (``[1, a1, ..., a_na]``), ``b_ft`` and ``b_e`` (copies)."""
        out = {}
        for c, (values, offsets) in self.coefficients.items():
            out[c] = np.array(values[offsets[row] : offsets[row + 1]], dtype=np.float64)
        return out

    def to_arrow(self) -> pa.Table:
        """The frontier as ``frontier.parquet``'s columns without model and seed."""
        columns = {"method": pa.array([self.method] * self.n_rows, pa.string())}
        columns.update({c: getattr(self, c) for c in _NUMBERS})
        for c, (values, offsets) in self.coefficients.items():
            columns[c] = pa.ListArray.from_arrays(
                pa.array(offsets.astype(np.int32)), pa.array(values, pa.float64())
            )
        names = [f.name for f in FRONTIER.arrow if f.name in columns]
        return pa.table({n: columns[n] for n in names})
