"""Slow, obvious twin of :func:`hcid.arx.engine.fit_grid` for tests and benchmarks.

One candidate at a time: build its own regression matrix on the estimation
rows, solve with :func:`numpy.linalg.lstsq`, test stability with
:func:`numpy.roots`, simulate with :func:`scipy.signal.lfilter`. No shared
factorisations, no kernels: what it computes can be read off the code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

__all__ = ["ReferenceFit", "fit_reference", "regression_matrix"]


@dataclass(frozen=True, eq=False)
class ReferenceFit:
    """Per-candidate results of :func:`fit_reference`.

    Attributes
    ----------
    na, nb1, nb2, nk1, nk2 : numpy.ndarray of int64, shape (m,)
        The candidates, as given.
    v : numpy.ndarray of float64, shape (m,)
        Mean squared simulation error over the validation rows; ``inf`` if
        unstable.
    unstable : numpy.ndarray of bool, shape (m,)
        A root of A with ``|z| >= 1`` or a non-finite simulation.
    max_root : numpy.ndarray of float64, shape (m,)
        Largest root magnitude of A.
    condition : numpy.ndarray of float64, shape (m,)
        2-norm condition number of the candidate's regression matrix on the
        estimation rows (NaN unless requested).
    a, b1, b2 : tuple of numpy.ndarray
        ``[1, a1, ..., a_na]``, ``[b1_0, ...]``, ``[b2_0, ...]`` per candidate.
    """

    na: np.ndarray
    nb1: np.ndarray
    nb2: np.ndarray
    nk1: np.ndarray
    nk2: np.ndarray
    v: np.ndarray
    unstable: np.ndarray
    max_root: np.ndarray
    condition: np.ndarray
    a: tuple[np.ndarray, ...]
    b1: tuple[np.ndarray, ...]
    b2: tuple[np.ndarray, ...]


def regression_matrix(i1, i2, o, na: int, nb1: int, nb2: int, nk1: int, nk2: int, rows: slice):
    """Regression matrix and target of one candidate on ``rows``.

    Columns ``-o(k-1) .. -o(k-na), i1(k-nk1) .. i1(k-nk1-nb1+1),
    i2(k-nk2) .. i2(k-nk2-nb2+1)``; samples before the record are 0.

    Parameters
    ----------
    i1, i2, o : numpy.ndarray of float64, shape (n,)
    na, nb1, nb2, nk1, nk2 : int
    rows : slice

    Returns
    -------
    numpy.ndarray of float64, shape (n_rows, na + nb1 + nb2 + 1)
        The regression matrix with the target ``o(rows)`` as last column.
    """
    ks = np.arange(len(o))[rows]

    def lagged(x, lag):
        out = np.zeros(ks.size)
        inside = ks - lag >= 0
        out[inside] = x[ks[inside] - lag]
        return out

    columns = [-lagged(o, i) for i in range(1, na + 1)]
    columns += [lagged(i1, nk1 + j) for j in range(nb1)]
    columns += [lagged(i2, nk2 + j) for j in range(nb2)]
    columns.append(o[ks])
    return np.column_stack(columns)


def fit_reference(
    i1,
    i2,
    o,
    na,
    nb1,
    nb2,
    nk1,
    nk2,
    estimation_rows: slice,
    validation_rows: slice,
    *,
    condition: bool = False,
) -> ReferenceFit:
    """Fit, test and simulate each given candidate the obvious way.

    Parameters
    ----------
    i1, i2, o : array_like of float, shape (n,)
        Inputs and output.
    na, nb1, nb2, nk1, nk2 : array_like of int, shape (m,)
        The candidates (scalars broadcast).
    estimation_rows, validation_rows : slice
        Least-squares rows and V rows.
    condition : bool, default False
        Also compute each regression matrix's condition number (an SVD).

    Returns
    -------
    ReferenceFit
    """
    i1, i2, o = (np.asarray(x, dtype=np.float64) for x in (i1, i2, o))
    orders = np.broadcast_arrays(*(np.asarray(x, dtype=np.int64) for x in (na, nb1, nb2, nk1, nk2)))
    orders = [np.atleast_1d(x).copy() for x in orders]
    m = orders[0].size
    v = np.full(m, np.inf)
    unstable = np.zeros(m, dtype=bool)
    max_root = np.zeros(m)
    cond = np.full(m, np.nan)
    a_rows, b1_rows, b2_rows = [], [], []
    for c in range(m):
        ca, cb1, cb2, ck1, ck2 = (int(x[c]) for x in orders)
        matrix = regression_matrix(i1, i2, o, ca, cb1, cb2, ck1, ck2, estimation_rows)
        phi, y = matrix[:, :-1], matrix[:, -1]
        theta = np.linalg.lstsq(phi, y, rcond=None)[0]
        if condition:
            cond[c] = np.linalg.cond(phi)
        a = np.concatenate(([1.0], theta[:ca]))
        b1 = theta[ca : ca + cb1]
        b2 = theta[ca + cb1 :]
        a_rows.append(a)
        b1_rows.append(b1)
        b2_rows.append(b2)
        max_root[c] = np.max(np.abs(np.roots(a))) if ca > 0 else 0.0
        if max_root[c] >= 1.0:
            unstable[c] = True
            continue
        o_hat = np.zeros_like(o)
        if cb1:
            o_hat += lfilter(np.concatenate((np.zeros(ck1), b1)), a, i1)
        if cb2:
            o_hat += lfilter(np.concatenate((np.zeros(ck2), b2)), a, i2)
        if not np.all(np.isfinite(o_hat)):
            unstable[c] = True
            continue
        v[c] = np.mean((o_hat[validation_rows] - o[validation_rows]) ** 2)
    return ReferenceFit(
        *orders,
        v=v,
        unstable=unstable,
        max_root=max_root,
        condition=cond,
        a=tuple(a_rows),
        b1=tuple(b1_rows),
        b2=tuple(b2_rows),
    )


def select_brute_force(d: np.ndarray, v: np.ndarray, orders: np.ndarray, w: float) -> int:
    """Slow twin of :func:`select_at`: argmin of log V + W d with the tie rule, row by row."""
    best, best_key = -1, None
    for i in range(len(d)):
        if not np.isfinite(v[i]) or v[i] <= 0:
            continue
        key = (np.log(v[i]) + w * d[i], d[i], tuple(int(x) for x in orders[i]))
        if best_key is None or key < best_key:
            best, best_key = i, key
    return best
