"""The frontier of a grid fit (:class:`GridFit`), as :func:`hcid.arx.engine.fit_grid` returns it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from hcid.arx.grid import Grid

__all__ = ["GridFit"]


@dataclass(frozen=True, eq=False)
class GridFit:
    """Frontier of a grid fit: the best candidate of every order triple.

    Rows follow the lexicographic order of ``(na, nb1, nb2)`` over the grid
    (448 rows for the paper's direct grid). A row whose candidates are all
    unstable has ``v = inf``, ``nk1 = nk2 = -1``, NaN VAFs and empty
    coefficient arrays; so does one not searched to its end
    (:func:`~hcid.arx.engine.fit_grid`'s ``best_only``), with ``v = NaN``. A
    dropped input (``nb = 0``) of a fitted row has ``nk = 0``.

    Attributes
    ----------
    grid : Grid
        The grid that was fitted.
    na, nb1, nb2 : numpy.ndarray of int64, shape (n_rows,)
        Orders of the row.
    nk1, nk2 : numpy.ndarray of int64, shape (n_rows,)
        Delays (samples) of the row's best candidate: smallest V (the
        search's, see ``fused``), ties to the smaller nk1, then nk2.
    d : numpy.ndarray of int64, shape (n_rows,)
        Number of parameters, ``na + nb1 + nb2 + [nb1 > 0] + [nb2 > 0]``.
    v : numpy.ndarray of float64, shape (n_rows,)
        Mean squared simulation error over the validation rows, in the
        squared unit of ``o``; ``inf`` if every candidate is unstable, NaN if
        the triple was not searched to its end (``best_only``).
    vaf_estimation, vaf_validation : numpy.ndarray of float64, shape (n_rows,)
        Variance accounted for (percent) of the simulated output over the
        estimation / validation rows, ``(1 - sum (o - o_hat)^2 / sum o^2)
        * 100``.
    n_unstable : numpy.ndarray of int64, shape (n_rows,)
        Number of unstable candidates among the row's delay combinations.
    a : tuple of numpy.ndarray
        Per row, ``[1, a1, ..., a_na]`` (the leading 1 included).
    b1, b2 : tuple of numpy.ndarray
        Per row, ``[b_0, ..., b_{nb-1}]`` (empty for a dropped input).
    n_candidates : int
        Number of candidates fitted.
    n_unstable_total : int
        Number of unstable candidates of the whole grid.
    candidates : pyarrow.Table or None
        With ``keep_candidates=True``, one row per candidate in the order of
        :func:`hcid.arx.grid.candidates`: columns na, nb1, nb2, nk1, nk2
        (int64) and v (float64, ``inf`` if unstable): the search's V, fused
        (but in triples searched again unfused) unless ``fit_grid(fused=False)``,
        so a frontier candidate's V here may differ from its row's by rounding.
    """

    grid: Grid
    na: np.ndarray
    nb1: np.ndarray
    nb2: np.ndarray
    nk1: np.ndarray
    nk2: np.ndarray
    d: np.ndarray
    v: np.ndarray
    vaf_estimation: np.ndarray
    vaf_validation: np.ndarray
    n_unstable: np.ndarray
    a: tuple[np.ndarray, ...]
    b1: tuple[np.ndarray, ...]
    b2: tuple[np.ndarray, ...]
    n_candidates: int
    n_unstable_total: int
    candidates: pa.Table | None = None

    def to_arrow(self) -> pa.Table:
        """The frontier as an Arrow table.

        Returns
        -------
        pyarrow.Table
            One row per order triple: int64 columns na, nb1, nb2, nk1, nk2,
            d, n_unstable; float64 columns v, vaf_estimation,
            vaf_validation; ``list<double>`` columns a, b1, b2. The schema
            metadata holds ``n_candidates`` and ``n_unstable_total``.
        """
        columns = {
            "na": self.na,
            "nb1": self.nb1,
            "nb2": self.nb2,
            "nk1": self.nk1,
            "nk2": self.nk2,
            "d": self.d,
            "v": self.v,
            "vaf_estimation": self.vaf_estimation,
            "vaf_validation": self.vaf_validation,
            "n_unstable": self.n_unstable,
            "a": _list_array(self.a),
            "b1": _list_array(self.b1),
            "b2": _list_array(self.b2),
        }
        metadata = {
            "n_candidates": str(self.n_candidates),
            "n_unstable_total": str(self.n_unstable_total),
        }
        return pa.table(columns).replace_schema_metadata(metadata)


def _list_array(arrays: tuple[np.ndarray, ...]) -> pa.Array:
    lengths = np.array([x.size for x in arrays], dtype=np.int32)
    offsets = np.concatenate(([0], np.cumsum(lengths))).astype(np.int32)
    values = np.concatenate(arrays) if arrays else np.empty(0)
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(values, type=pa.float64()))
