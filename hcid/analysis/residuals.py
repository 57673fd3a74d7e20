"""Residual analysis of an identified model (like MATLAB's ``resid``).

For a simulation residual ``eps = o - o_hat`` over given rows: the
autocorrelation of eps at lags 1..M and its cross-correlation with each input
at lags -M..M, with the band a white residual stays inside with the given
confidence (99%: ``2.576 / sqrt(N)``), and the share of lags outside it.

Conventions (the sample correlation of Box and Jenkins, as ``statsmodels``'
``acf``/``ccf``): both series are taken on the rows only, their means over the
rows removed, and

    r_eps(tau)   = sum_t eps(t) eps(t - tau) / sum_t eps(t)^2
    r_eps,x(tau) = sum_t eps(t) x(t - tau) / sqrt(sum_t eps(t)^2 sum_t x(t)^2)

with each sum over the rows where both factors lie (dividing by N, not by the
number of terms, which keeps the estimate's variance at or below 1/N). A
positive tau pairs eps with *past* x: dynamics the model missed. A negative tau
pairs eps with *future* x, which a closed loop produces by itself (the
residual feeds back into e), so lags below 0 of the error input are expected
to stand out and are no defect of the model.

Under the null hypothesis of a white eps (and eps independent of x), each
correlation is approximately normal with variance 1/N (Bartlett), whatever the
autocorrelation of x; the band is ``z / sqrt(N)`` with ``z`` the two-sided
normal quantile of the confidence.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal as sps
from scipy import stats

from hcid.arx.simulation import checked_rows
from hcid.errors import DataError, IdentificationError, checked_rate

__all__ = ["Correlation", "ResidualAnalysis", "analyse_residuals"]

#: Name of the residual's own series in the results (its autocorrelation).
RESIDUAL = "eps"


@dataclass(frozen=True)
class Correlation:
    """Normalised correlation of the residual with one series.

    Attributes
    ----------
    signal : str
        :data:`RESIDUAL` for the autocorrelation, else the input's name.
    lags : ndarray of int, shape (L,)
        Lags (samples): 1..M for the autocorrelation, -M..M for an input.
    values : ndarray, shape (L,)
        Correlation at each lag (-).
    outside : ndarray of bool, shape (L,)
        ``|values| > bound``.
    """

    signal: str
    lags: np.ndarray
    values: np.ndarray
    outside: np.ndarray

    @property
    def kind(self) -> str:
        return "auto" if self.signal == RESIDUAL else "cross"

    @property
    def share_outside(self) -> float:
        """Share of the lags outside the band (0..1)."""
        return float(np.mean(self.outside))


@dataclass(frozen=True)
class ResidualAnalysis:
    """Whiteness and independence test of one residual.

    Attributes
    ----------
    n : int
        Samples (rows) used.
    max_lag : int
        M (samples).
    rate : float
        Sample rate (Hz) of the lags, for :meth:`rows`'s ``lag_s``.
    confidence : float
        Of the band (e.g. 0.99).
    bound : float
        ``z / sqrt(n)``, the half-width of the band (-).
    correlations : tuple of Correlation
        The autocorrelation first, then one per input in the given order.
    """

    n: int
    max_lag: int
    rate: float
    confidence: float
    bound: float
    correlations: tuple[Correlation, ...]

    def correlation(self, signal: str) -> Correlation:
        """The correlation with ``signal`` (:data:`RESIDUAL` for the autocorrelation)."""
        for c in self.correlations:
            if c.signal == signal:
                return c
        raise KeyError(
            f"signal: no correlation with {signal!r}, have {[c.signal for c in self.correlations]}"
        )

    @property
    def share_outside(self) -> float:
        """Share of all lags (every series) outside the band (0..1)."""
        return float(np.mean(np.concatenate([c.outside for c in self.correlations])))

    def rows(self) -> list[dict[str, Any]]:
        """One dict per series and lag: signal, kind, lag, lag_s, correlation, bound, outside."""
        return [
            {
                "signal": c.signal,
                "kind": c.kind,
                "lag": int(lag),
                "lag_s": float(lag / self.rate),
                "correlation": float(value),
                "bound": self.bound,
                "outside": bool(out),
            }
            for c in self.correlations
            for lag, value, out in zip(c.lags, c.values, c.outside, strict=True)
        ]

    def summary_rows(self) -> list[dict[str, Any]]:
        """One dict per series: signal, kind, lags, outside, share_outside, bound, n, confidence."""
        return [
            {
                "signal": c.signal,
                "kind": c.kind,
                "lags": int(c.lags.size),
                "outside": int(np.count_nonzero(c.outside)),
                "share_outside": c.share_outside,
                "bound": self.bound,
                "n": self.n,
                "confidence": self.confidence,
            }
            for c in self.correlations
        ]


def _series(name: str, value: Any, n: int) -> np.ndarray:
    x = np.asarray(value, dtype=np.float64)
    if x.ndim != 1 or x.size != n:
        raise DataError(f"{name}: must be a 1-D array of the residual's length ({n}), got shape {x.shape}")
    return x


def _normalised(x: np.ndarray, name: str) -> np.ndarray:
    if not np.all(np.isfinite(x)):
        raise DataError(
            f"{name}: must be finite on the rows, got {np.count_nonzero(~np.isfinite(x))} NaN/inf"
        )
    x = x - np.mean(x)
    energy = math.sqrt(float(np.sum(x**2)))
    if energy == 0.0:
        raise DataError(f"{name}: is constant on the rows; its correlation is undefined")
    return x / energy


def _correlate(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """``sum_t a(t) b(t - tau)`` at each lag tau."""
    full = sps.correlate(a, b, mode="full", method="auto")
    return full[lags + b.size - 1]


def analyse_residuals(
    eps: np.ndarray,
    inputs: Mapping[str, np.ndarray],
    rows: slice,
    max_lag: int = 25,
    *,
    rate: float = 1.0,
    confidence: float = 0.99,
) -> ResidualAnalysis:
    """Autocorrelation of the residual and its cross-correlation with each input.

    Parameters
    ----------
    eps : ndarray, shape (N,)
        Residual ``o - o_hat`` (the simulation residual) over the record.
    inputs : mapping of str to ndarray, shape (N,)
        The model's inputs by name, e.g. ``{"ft": ft, "e": e}`` (not
        :data:`RESIDUAL`).
    rows : slice
        Rows to analyse, e.g. the validation rows ``slice(1088, 2048)``.
    max_lag : int
        M (samples), 1 <= M < number of rows.
    rate : float
        Sample rate (Hz), only to express lags in s in :meth:`ResidualAnalysis.rows`.
    confidence : float
        Of the white-residual band, in (0, 1).

    Returns
    -------
    ResidualAnalysis

    Raises
    ------
    hcid.errors.DataError
        If a series is not 1-D of the residual's length, not finite on the
        rows, or constant there.
    hcid.errors.IdentificationError
        If the rows, max_lag or confidence are out of range.

    Examples
    --------
    >>> import numpy as np
    >>> eps = np.random.default_rng(0).standard_normal(10_000)
    >>> r = analyse_residuals(eps, {}, slice(0, 10_000), max_lag=5)
    >>> round(r.bound, 4)  # 2.576 / sqrt(10000)
    0.0258
    """
    eps = np.asarray(eps, dtype=np.float64)
    if eps.ndim != 1:
        raise DataError(f"eps: must be a 1-D array, got shape {eps.shape}")
    start, stop = checked_rows("rows", rows, eps.size)
    n = stop - start
    if isinstance(max_lag, bool) or not isinstance(max_lag, int) or not 1 <= max_lag < n:
        raise IdentificationError(
            f"max_lag: must be an integer in [1, {n - 1}] (the rows hold {n}), got {max_lag!r}"
        )
    if not 0.0 < confidence < 1.0:
        raise IdentificationError(f"confidence: must be in (0, 1), got {confidence!r}")
    checked_rate(rate, IdentificationError)
    if RESIDUAL in inputs:
        raise IdentificationError(f"inputs: the name {RESIDUAL!r} is the residual's own")

    bound = float(stats.norm.ppf(0.5 + confidence / 2.0) / math.sqrt(n))
    e = _normalised(eps[start:stop], "eps")
    own = np.arange(1, max_lag + 1)
    values = _correlate(e, e, own)
    correlations = [Correlation(RESIDUAL, own, values, np.abs(values) > bound)]
    both = np.arange(-max_lag, max_lag + 1)
    for name, x in inputs.items():
        x = _normalised(_series(name, x, eps.size)[start:stop], name)
        values = _correlate(e, x, both)
        correlations.append(Correlation(name, both, values, np.abs(values) > bound))
    return ResidualAnalysis(
        n=n,
        max_lag=max_lag,
        rate=float(rate),
        confidence=float(confidence),
        bound=bound,
        correlations=tuple(correlations),
    )
