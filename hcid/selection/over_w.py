"""Model selection by ``MSC = log V + W d`` over W (SPEC section 4).

Only the best candidate per (na, nb_ft, nb_e) can be selected, so selection
works on a realization's frontier (:class:`hcid.selection.frontier.Frontier`). As a
function of W the selection is piecewise constant; it changes at the vertices of the lower convex hull of the
points (d, log V), and those breakpoints are computed exactly here.

Ties follow SPEC: equal MSC -> smaller d, then smaller
(na, nb_ft, nb_e, nk_ft, nk_e). At a breakpoint both neighbours have equal MSC,
so the smaller-d model is selected there: each selection holds on a half-open
interval ``[w_from, w_to)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from hcid.errors import IdentificationError

__all__ = [
    "Bootstrap",
    "SelectionPath",
    "breakpoints",
    "select_at",
    "false_negative_bootstrap",
    "false_negative_threshold",
    "false_positive_extent",
    "false_positive_threshold",
    "threshold_exceedance",
]


def _order_key(orders: np.ndarray) -> np.ndarray:
    """Row indices in lexicographic order of (na, nb_ft, nb_e, nk_ft, nk_e), the last tie rule."""
    return np.lexsort(orders.T[::-1])


@dataclass(frozen=True)
class SelectionPath:
    """The selection of one realization as a function of W.

    ``index[i]`` (a frontier row) is selected for ``w_from[i] <= W < w_to[i]``;
    ``w_from[0] = 0`` and ``w_to[-1] = inf``. Consecutive entries differ.
    """

    index: np.ndarray
    w_from: np.ndarray
    w_to: np.ndarray

    def at(self, w: np.ndarray) -> np.ndarray:
        """Frontier row selected at each W (W >= 0; a negative or NaN W is refused)."""
        w = np.asarray(w, dtype=np.float64)
        if not np.all(w >= 0):
            raise IdentificationError(f"w: must be >= 0, got {float(w[~(w >= 0)].flat[0])}")
        return self.index[np.searchsorted(self.w_from, w, side="right") - 1]

    def to_arrow(self) -> pa.Table:
        """One row per interval: the frontier row (``index``) selected for ``w_from <= W < w_to``."""
        return pa.table({"index": self.index, "w_from": self.w_from, "w_to": self.w_to})


def _ranked(d: np.ndarray, v: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """Indices of finite-V rows sorted by the full tie rule (d, log V, orders)."""
    finite = np.flatnonzero(np.isfinite(v) & (v > 0))
    rank_orders = np.empty(orders.shape[0], dtype=np.int64)
    rank_orders[_order_key(orders)] = np.arange(orders.shape[0])
    keys = (rank_orders[finite], np.log(v[finite]), d[finite])
    return finite[np.lexsort(keys)]


def breakpoints(d: np.ndarray, v: np.ndarray, orders: np.ndarray) -> SelectionPath:
    """Exact selection intervals in W from the lower convex hull of (d, log V).

    Parameters
    ----------
    d : ndarray of int, shape (m,)
        Parameter counts of the frontier rows.
    v : ndarray, shape (m,)
        V of the rows; inf (unstable) rows are never selected.
    orders : ndarray of int, shape (m, 5)
        (na, nb_ft, nb_e, nk_ft, nk_e) per row, for the tie rule.

    Returns
    -------
    SelectionPath
    """
    d = np.asarray(d, dtype=np.int64)
    v = np.asarray(v, dtype=np.float64)
    ranked = _ranked(d, v, np.asarray(orders))
    if ranked.size == 0:
        raise IdentificationError("every frontier row is unstable: nothing can be selected")
    # Best row per d: the first in (d, log V, orders) order.
    first_of_d = np.concatenate([[True], np.diff(d[ranked]) != 0])
    best = ranked[first_of_d]
    dd = d[best].astype(np.float64)
    lv = np.log(v[best])

    # W -> 0+: the smallest log V, ties to smaller d (best is sorted by d).
    current = int(np.argmin(lv))
    index, w_from = [best[current]], [0.0]
    while current > 0:
        # Moving to a smaller-d point p becomes worth it at W = (L_p - L_c) / (d_c - d_p).
        slopes = (lv[:current] - lv[current]) / (dd[current] - dd[:current])
        w_next = slopes.min()
        # Collinear points tie at w_next: the tie rule takes the smallest d.
        nxt = int(np.flatnonzero(slopes == w_next)[0])
        w_next = max(float(w_next), w_from[-1])
        if w_next == w_from[-1]:
            index[-1] = best[nxt]
        else:
            index.append(best[nxt])
            w_from.append(w_next)
        current = nxt
    w_from_arr = np.asarray(w_from)
    w_to = np.append(w_from_arr[1:], np.inf)
    return SelectionPath(index=np.asarray(index, dtype=np.int64), w_from=w_from_arr, w_to=w_to)


def select_at(d: np.ndarray, v: np.ndarray, orders: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Frontier row selected at each W, via :func:`breakpoints`."""
    return breakpoints(d, v, orders).at(w)


def false_positive_threshold(segments: list[SelectionPath], nb_ft: list[np.ndarray]) -> float:
    """W_FP: the largest W at which any realization selects a model with nb_ft > 0.

    Each realization is a false positive on the union of its intervals with
    nb_ft > 0; the supremum is the right end of the last such interval. 0 when
    no realization is ever a false positive; inf when one stays a false positive
    for every W.
    """
    extents = [false_positive_extent(seg, nb) for seg, nb in zip(segments, nb_ft, strict=True)]
    return max(extents, default=0.0)


def false_positive_extent(segments: SelectionPath, nb_ft: np.ndarray) -> float:
    """L: the largest W at which one realization selects nb_ft > 0 (SPEC 9); 0 if never.

    The right end of its last interval with nb_ft > 0 (selections hold on
    ``[w_from, w_to)``, so L is a supremum); inf if it stays a false positive.
    W_FP of a study is the largest L.

    Examples
    --------
    >>> seg = SelectionPath(np.array([0, 1, 2]), np.array([0.0, 0.01, 0.2]), np.array([0.01, 0.2, np.inf]))
    >>> false_positive_extent(seg, np.array([3, 1, 0]))
    0.2
    """
    positive = np.asarray(nb_ft)[segments.index] > 0
    return float(segments.w_to[np.flatnonzero(positive)[-1]]) if positive.any() else 0.0


def threshold_exceedance(extents: np.ndarray, w: float, n: int) -> float:
    """P(W_FP >= w) for a study of ``n`` realizations: ``1 - (1 - q(w))^n`` (SPEC 9).

    ``q(w)`` is the share of the given realizations whose L (from
    :func:`false_positive_extent`) is at least ``w``: the plug-in estimate of
    the chance that one realization is still a false positive just below w.
    W_FP is the largest of n independent L, hence the power.

    Parameters
    ----------
    extents : ndarray, shape (m,)
        L of each realization of this run.
    w : float
        The threshold to compare with (e.g. the paper's W_FP).
    n : int
        Realizations of the study whose W_FP is meant (the paper's: 50).

    Examples
    --------
    >>> threshold_exceedance(np.array([0.0, 0.0, 0.02, 0.0]), 0.01, 2)  # q = 1/4
    0.4375
    """
    extents = np.asarray(extents, dtype=np.float64)
    q = float(np.mean(extents >= w))
    return float(1.0 - (1.0 - q) ** n)


def _nb_ft_at_breakpoints(
    segments: list[SelectionPath], nb_ft: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """(W, nb_ft per realization x W) at the union of the realizations' breakpoints."""
    at = np.unique(np.concatenate([s.w_from for s in segments]))
    values = np.array([nb[s.at(at)] for s, nb in zip(segments, nb_ft, strict=True)], dtype=np.float64)
    return at, values


def _first_below(at: np.ndarray, means: np.ndarray, level: float) -> np.ndarray:
    """Per row of ``means``, the first W of ``at`` with a mean below ``level`` (inf if none)."""
    below = means < level
    first = np.argmax(below, axis=-1)
    return np.where(below.any(axis=-1), at[first], np.inf)


def false_negative_threshold(
    segments: list[SelectionPath], nb_ft: list[np.ndarray], level: float = 2.0
) -> float:
    """W_FN: the smallest W at which the mean selected nb_ft drops below ``level``.

    The mean is piecewise constant with jumps at the union of the realizations'
    breakpoints, so it is evaluated exactly there. 0 when it starts below the
    level; inf when it never drops below it.
    """
    at, values = _nb_ft_at_breakpoints(segments, nb_ft)
    return float(_first_below(at, values.mean(axis=0), level))


@dataclass(frozen=True)
class Bootstrap:
    """A percentile bootstrap of a threshold over realizations.

    ``low``, ``high``: the ``confidence`` interval; ``share_at_or_above(w)``
    the share of resampled thresholds at or above w.
    """

    values: np.ndarray
    low: float
    high: float
    confidence: float

    def share_at_or_above(self, w: float) -> float:
        return float(np.mean(self.values >= w))


def false_negative_bootstrap(
    segments: list[SelectionPath],
    nb_ft: list[np.ndarray],
    level: float = 2.0,
    *,
    confidence: float = 0.95,
    resamples: int = 2000,
    seed: int = 0,
) -> Bootstrap:
    """Percentile bootstrap of W_FN over realizations (SPEC 9), seeded so reports are deterministic.

    Each resample draws as many realizations as there are, with replacement,
    and takes the W at which their mean selected nb_ft first drops below
    ``level``, exactly (at the breakpoints). The interval's ends are the
    ``(1 - confidence)/2`` and ``(1 + confidence)/2`` quantiles, taken as
    order statistics (no interpolation, so inf stays inf).
    """
    at, values = _nb_ft_at_breakpoints(segments, nb_ft)
    n = values.shape[0]
    rng = np.random.default_rng(seed)
    # One draw of resamples x n indices is the stream of resamples draws of n (numpy's Generator
    # draws them in order; tests/test_selection.py holds the weights to the one-by-one ones).
    draws_at = rng.integers(0, n, (resamples, n)) + n * np.arange(resamples)[:, None]
    weights = np.bincount(draws_at.ravel(), minlength=n * resamples).reshape(resamples, n)
    draws = _first_below(at, weights @ values / n, level)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(draws, [alpha, 1.0 - alpha], method="inverted_cdf")
    return Bootstrap(values=draws, low=float(low), high=float(high), confidence=confidence)
