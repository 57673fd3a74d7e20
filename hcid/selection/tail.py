"""p-values below 1/(N+1) from few null draws: a generalized Pareto tail (SPEC 13).

A run's statistic ``x`` (its W*, or another statistic) is compared with ``N`` statistics of
simulated null runs (its FB twins). Where at least ``min_exceed`` of them reach ``x``, the Monte
Carlo p ``(1 + k) / (1 + N)`` of :func:`hcid.selection.calibration.evidence_p_value` stands.
Where fewer do, the null's ``m`` largest values are its tail (Knijnenburg, Wessels, Reinders and
Shmulevich, "Fewer permutations, more accurate P-values", Bioinformatics 25, 2009, i161-i168):
their excesses over the (m+1)-th largest value ``t`` are fitted by a generalized Pareto
distribution (GPD), the fit is checked by an Anderson-Darling test, and

    p = (m + 1) / (N + 1) * P(Y > x - t),

``(m + 1) / (N + 1)`` being the exact null probability that ``x`` passes ``t``, and ``Y`` the next
excess. ``P(Y > x - t)`` is the GPD's posterior predictive tail (:func:`predictive_sf`), not the
fitted GPD's own: with 10 to 25 excesses the fit's shape is uncertain, and a plug-in of one fit
makes small p-values too frequent (a negative shape even bounds the tail below ``x``, giving
p = 0; permApprox constrains that fit to reach ``x`` with a margin). The predictive averages the
tail over every shape and scale the excesses allow; its support reaches every ``x``, so p > 0.

Pure functions over arrays; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import gammaincc

__all__ = [
    "GPD_TAIL",
    "METHODS",
    "MONTE_CARLO",
    "P_FLOOR",
    "SHAPE_MAX",
    "TailP",
    "ad_p_value",
    "anderson_darling_gpd",
    "fit_gpd",
    "gpd_sf",
    "predictive_sf",
    "tail_p_value",
]

#: How a :class:`TailP` was made: the Monte Carlo count, or the fitted tail.
MONTE_CARLO = "monte carlo"
GPD_TAIL = "gpd tail"
METHODS = (MONTE_CARLO, GPD_TAIL)

#: The predictive's prior holds the shape below this: a null statistic with a finite mean.
SHAPE_MAX = 1.0
#: The smallest p returned: a tail probability that underflows is not evidence of p = 0.
P_FLOOR = float(np.finfo(np.float64).tiny)

#: Upper-tail critical values of A^2 for the GPD with both parameters estimated (Choulakian and
#: Stephens, Technometrics 43, 2001, Table 2, as Knijnenburg et al. 2009 use them), one row per
#: shape (here xi, the negative of their k), one column per level in _AD_LEVELS.
_AD_SHAPES = np.array([-0.9, -0.5, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
_AD_LEVELS = np.array([0.5, 0.25, 0.1, 0.05, 0.025, 0.01, 0.005, 0.001])
_AD_CRITICAL = np.array(
    [
        [0.339, 0.471, 0.641, 0.771, 0.905, 1.086, 1.226, 1.559],
        [0.356, 0.499, 0.685, 0.830, 0.978, 1.180, 1.336, 1.707],
        [0.376, 0.534, 0.741, 0.903, 1.069, 1.296, 1.471, 1.893],
        [0.386, 0.550, 0.766, 0.935, 1.110, 1.348, 1.532, 1.966],
        [0.397, 0.569, 0.796, 0.974, 1.158, 1.409, 1.603, 2.064],
        [0.410, 0.591, 0.831, 1.020, 1.215, 1.481, 1.687, 2.176],
        [0.426, 0.617, 0.873, 1.074, 1.283, 1.567, 1.788, 2.314],
        [0.445, 0.649, 0.924, 1.140, 1.365, 1.672, 1.909, 2.475],
        [0.468, 0.688, 0.985, 1.221, 1.465, 1.799, 2.058, 2.674],
        [0.496, 0.735, 1.061, 1.321, 1.590, 1.958, 2.243, 2.922],
    ]
)

#: Grids of u = log(1 + theta max(y)), theta = shape / scale; u -> -inf ends the tail at max(y).
_U_FIT = np.linspace(-15.0, 15.0, 301)
_U_PREDICTIVE = np.linspace(-40.0, 15.0, 221)
#: Most tails tried per value (from the largest down to ``min_tail``).
_TAILS_TRIED = 16


@dataclass(frozen=True)
class TailP:
    """A p-value and how it was made.

    Attributes
    ----------
    p : float
        The p-value, in (0, 1].
    method : str
        :data:`MONTE_CARLO` or :data:`GPD_TAIL`.
    n_null : int
        Null values it was compared with (N).
    n_tail : int
        Excesses in the fitted tail, ``m`` (0 for Monte Carlo).
    shape, scale : float
        The maximum-likelihood GPD of the excesses (scale in the statistic's unit), the fit the
        Anderson-Darling test accepted; NaN for Monte Carlo.
    threshold : float
        ``t``, the (m+1)-th largest null value; NaN for Monte Carlo.
    ad_p : float
        The fit's Anderson-Darling p-value (NaN for Monte Carlo).
    """

    p: float
    method: str
    n_null: int
    n_tail: int
    shape: float
    scale: float
    threshold: float
    ad_p: float


def gpd_sf(excess: np.ndarray, shape: float, scale: float) -> np.ndarray:
    """Survival function ``1 - F`` of the GPD: ``(1 + shape * y / scale) ** (-1 / shape)``,
    ``exp(-y / scale)`` at shape 0, and 0 beyond the endpoint ``scale / -shape`` of a negative shape.

    Examples
    --------
    >>> gpd_sf(np.array([0.0, 1.0, 3.0]), 0.5, 1.0).round(6).tolist()  # (1 + y / 2) ** -2
    [1.0, 0.444444, 0.16]
    >>> gpd_sf(np.array([1.0, 2.5]), -0.5, 1.0).tolist()  # (1 - y / 2) ** 2, endpoint 2
    [0.25, 0.0]
    """
    y = np.asarray(excess, dtype=np.float64) / scale
    if shape == 0.0:
        return np.exp(-y)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(shape * y > -1.0, np.exp(-np.log1p(shape * y) / shape), 0.0)


def _profile(c: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # Grimshaw (Technometrics 35, 1993): with theta = shape / scale fixed, the best shape is
    # mean(log(1 + theta y)), so the likelihood is searched over theta alone. z = y / max(y) and
    # c = theta max(y); returns the log-likelihood (up to -n log max(y)), shape, scale / max(y).
    with np.errstate(divide="ignore", invalid="ignore"):
        shape = np.log1p(np.multiply.outer(c, z)).mean(axis=-1)
        scale = np.where(c == 0.0, z.mean(), shape / np.where(c == 0.0, 1.0, c))
        loglik = -z.size * (np.log(scale) + shape + 1.0)
    return np.where(np.isfinite(loglik) & (shape >= -1.0), loglik, -np.inf), shape, scale


def fit_gpd(excesses: np.ndarray) -> tuple[float, float]:
    """Maximum-likelihood GPD of positive excesses, its shape at least -1 (where the likelihood is
    bounded): the profile likelihood over theta = shape / scale on a grid, refined four times.

    Parameters
    ----------
    excesses : ndarray, shape (n,)
        Positive values above a threshold.

    Returns
    -------
    shape, scale : float

    Examples
    --------
    >>> y = -np.log(1 - (np.arange(1, 200) / 200))  # exponential quantiles, scale 1
    >>> [round(v, 4) for v in fit_gpd(y)]  # scipy.stats.genpareto.fit(y, floc=0): -0.0425, 1.0292
    [-0.0425, 1.0292]
    """
    y = np.asarray(excesses, dtype=np.float64)
    top = float(y.max())
    z = y / top
    u = _U_FIT
    for _ in range(4):
        best = int(np.argmax(_profile(np.expm1(u), z)[0]))
        u = np.linspace(u[max(best - 1, 0)], u[min(best + 1, u.size - 1)], 33)
    best = int(np.argmax(_profile(np.expm1(u), z)[0]))
    _, shape, scale = _profile(np.expm1(u[best : best + 1]), z)
    return float(shape[0]), float(scale[0] * top)


def ad_p_value(a2: float, shape: float) -> float:
    """p-value of an Anderson-Darling A^2 for a GPD with both parameters estimated, from
    Choulakian and Stephens' (2001) table: interpolated linearly in the shape (held to the
    table's [-0.9, 0.5]) and log-linearly between levels; 0.5 stands for at least 0.5, 0.001 for
    at most 0.001 (the table's range).

    Examples
    --------
    >>> round(ad_p_value(0.974, 0.0), 12), round(ad_p_value(1.672, 0.3), 12)  # table: 5% at 0, 1% at 0.3
    (0.05, 0.01)
    >>> round(ad_p_value(0.974, 0.05), 4)  # halfway between shapes 0 and 0.1: 0.997 is the 5% point
    0.0545
    """
    s = min(max(shape, _AD_SHAPES[0]), _AD_SHAPES[-1])
    critical = np.array([np.interp(s, _AD_SHAPES, column) for column in _AD_CRITICAL.T])
    if not critical[0] < a2 < critical[-1]:
        return float(_AD_LEVELS[0] if a2 <= critical[0] else _AD_LEVELS[-1])
    return float(np.exp(np.interp(a2, critical, np.log(_AD_LEVELS))))


def anderson_darling_gpd(excesses: np.ndarray, shape: float, scale: float) -> tuple[float, float]:
    """Anderson-Darling statistic A^2 of excesses against a GPD fitted to them, and its
    :func:`ad_p_value` (0.001 where a value lies beyond the GPD's support).

    Examples
    --------
    >>> y = -np.log(1 - (np.arange(1, 100) / 100))  # exponential quantiles: a close fit
    >>> a2, p = anderson_darling_gpd(y, *fit_gpd(y))
    >>> round(a2, 4), p  # below the 0.5 point of every shape (0.339 and up)
    (0.0306, 0.5)
    >>> anderson_darling_gpd(np.r_[np.full(30, 0.01), np.ones(30)], 0.0, 0.5)[1]  # two clumps
    0.001
    """
    y = np.sort(np.asarray(excesses, dtype=np.float64))
    n = y.size
    with np.errstate(divide="ignore"):
        log_sf = np.log(gpd_sf(y, shape, scale))
        log_cdf = np.log(-np.expm1(log_sf))
    i = np.arange(1, n + 1)
    a2 = float(-n - np.sum((2 * i - 1) * (log_cdf + log_sf[::-1])) / n)
    return (a2, ad_p_value(a2, shape)) if np.isfinite(a2) else (math.inf, float(_AD_LEVELS[-1]))


def _log_1p(u: np.ndarray, c: np.ndarray, z: np.ndarray) -> np.ndarray:
    # log(1 + c z) for c = exp(u) - 1 near -1 too, as log((1 - z) + z exp(u)): a bounded tail
    # ending just past the largest excess has c closer to -1 than a float resolves.
    with np.errstate(divide="ignore", invalid="ignore"):
        near = np.log((1.0 - z)[None, :] + np.multiply.outer(np.exp(u), z))
        return np.where((c > -0.5)[:, None], np.log1p(np.multiply.outer(c, z)), near)


def _posterior(u: np.ndarray, z: np.ndarray, dz: float) -> tuple[np.ndarray, np.ndarray]:
    # Over u = log(1 + c), c = theta max(y): the log density of theta given the excesses, and
    # P(Y > d | theta, y). In (theta, xi) the prior is 1 / |theta| and the likelihood
    # |theta / xi|^n exp(-(1 / xi + 1) S), S = sum(log(1 + theta y)), xi of theta's sign: an
    # inverse-gamma kernel in xi. Integrated over xi, theta's density is
    # |theta / S|^(n - 1) exp(-S) Q(n - 1, S / SHAPE_MAX) (Q the regularized upper incomplete
    # gamma, from xi < SHAPE_MAX; 1 for theta < 0), and the tail is (S / (S + L))^(n - 1)
    # Q(n - 1, (S + L) / SHAPE_MAX) / Q(n - 1, S / SHAPE_MAX), L = log(1 + theta d), 0 where
    # theta d <= -1. r = S / c and L / c stay finite at c = 0.
    n = z.size
    c = np.expm1(u)
    at_zero = c == 0.0
    c_safe = np.where(at_zero, 1.0, c)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        s = _log_1p(u, c, z).sum(axis=1)
        r = np.where(at_zero, z.sum(), s / c_safe)
        log_d = _log_1p(u, c, np.array([dz]))[:, 0]
        inside = np.isfinite(log_d)
        r_d = np.where(at_zero, dz, log_d / c_safe)
        positive = c > 0.0
        q = np.where(positive, gammaincc(n - 1, s / SHAPE_MAX), 1.0)
        q_d = np.where(positive, gammaincc(n - 1, (s + log_d) / SHAPE_MAX), 1.0)
        log_density = u - (n - 1) * np.log(r) - s + np.log(q)  # u: the Jacobian d theta / du
        tail = np.where(inside, (r / (r + r_d)) ** (n - 1) * q_d / q, 0.0)
    ok = np.isfinite(log_density) & np.isfinite(tail)
    return np.where(ok, log_density, -np.inf), np.where(ok, tail, 0.0)


def predictive_sf(excesses: np.ndarray, excess: float) -> float:
    """Posterior predictive ``P(Y > excess)`` of the next excess of a GPD fitted to ``excesses``:
    the GPD tail averaged over its shape xi and scale sigma given the excesses, with the prior
    ``1 / sigma`` (scale-invariant: with xi known to be 0 the predictive, ``(1 + excess /
    sum(excesses)) ** -n``, is an exact p-value) and flat in xi below :data:`SHAPE_MAX`. The shape
    is integrated in closed form, the ratio ``theta = xi / sigma`` (whose ``-1 / theta`` ends a
    bounded tail) on a grid.

    Parameters
    ----------
    excesses : ndarray, shape (n,)
        Positive values above a threshold, n >= 3.
    excess : float
        A value above the same threshold (>= 0).

    Examples
    --------
    >>> y = -np.log(1 - (np.arange(1, 21) / 21))  # exponential quantiles, scale 1
    >>> predictive_sf(y, 0.0)
    1.0
    >>> round(predictive_sf(y, 5.0), 4), round(float(np.exp(-5.0)), 4)  # heavier than the truth
    (0.0142, 0.0067)
    """
    y = np.asarray(excesses, dtype=np.float64)
    top = float(y.max())
    z, dz = y / top, float(excess) / top
    log_density, tail = _posterior(_U_PREDICTIVE, z, dz)
    with np.errstate(divide="ignore"):
        log_joint = log_density + np.log(tail)
    # The two integrals again, each on a fine grid over where its integrand is within e^-40 of
    # its largest (the density narrows as n grows; the tail far beyond a bounded fit lives where
    # the density is small); on an even grid the trapezoid rule is a sum, taken in logs.
    return float(np.exp(_log_integral(log_joint, z, dz, True) - _log_integral(log_density, z, dz, False)))


def _log_integral(coarse: np.ndarray, z: np.ndarray, dz: float, with_tail: bool) -> float:
    keep = np.flatnonzero(coarse > coarse.max() - 40.0)
    if keep.size == 0:
        return -math.inf
    last = _U_PREDICTIVE.size - 1
    u = np.linspace(_U_PREDICTIVE[max(keep[0] - 1, 0)], _U_PREDICTIVE[min(keep[-1] + 1, last)], 401)
    log_density, tail = _posterior(u, z, dz)
    with np.errstate(divide="ignore"):
        values = log_density + (np.log(tail) if with_tail else 0.0)
    top = values.max()
    return float(top + np.log(np.sum(np.exp(values - top)) * (u[1] - u[0]))) if top > -np.inf else -math.inf


def _checked(value: object, null: object) -> tuple[float, np.ndarray]:
    x = np.asarray(value, dtype=np.float64)
    if x.ndim != 0 or not np.isfinite(x):
        raise ValueError(f"value: must be one finite number, got {value!r}")
    y = np.asarray(null, dtype=np.float64)
    if y.ndim != 1 or y.size == 0:
        raise ValueError(f"null: must be a 1-D array of at least one value, got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise ValueError(f"null: must be finite, got {np.count_nonzero(~np.isfinite(y))} non-finite values")
    return float(x), y


def _checked_options(min_exceed: object, min_tail: object, tail_share: object, ad_level: object) -> None:
    for name, v, least in (("min_exceed", min_exceed, 1), ("min_tail", min_tail, 3)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < least:
            raise ValueError(f"{name}: must be an integer >= {least}, got {v!r}")
    for name, v, top in (("tail_share", tail_share, 1.0), ("ad_level", ad_level, 0.999)):
        if isinstance(v, bool) or not isinstance(v, float | int) or not 0.0 < v <= top:
            raise ValueError(f"{name}: must be a number in (0, {top}], got {v!r}")


def tail_p_value(
    value: float,
    null: np.ndarray,
    *,
    min_exceed: int = 10,
    min_tail: int = 10,
    tail_share: float = 0.25,
    ad_level: float = 0.05,
) -> TailP:
    """The p-value of ``value`` against null draws, below ``1 / (N + 1)`` where the null's tail
    allows (SPEC 13).

    Where ``k >= min_exceed`` null values reach ``value``: the Monte Carlo ``(1 + k) / (1 + N)``.
    Else tails of the ``m`` largest null values, ``m`` from ``max(ceil(tail_share N), min_tail)``
    down to ``min_tail`` (at most 16 of them, and ``m > k``), threshold ``t`` the (m+1)-th largest:
    the first whose excesses' GPD (:func:`fit_gpd`) passes the Anderson-Darling test
    (:func:`anderson_darling_gpd`) at ``ad_level`` gives
    ``p = (m + 1) / (N + 1) * predictive_sf(excesses, value - t)``, at least :data:`P_FLOOR`.
    A tail whose m + 1 values are not all different is skipped: a statistic clipped at the top
    of its range ties there, and keeps the Monte Carlo p, as does every value no tail fits.

    Parameters
    ----------
    value : float
        The run's statistic; larger is more evidence against the null.
    null : ndarray, shape (N,)
        The null runs' statistics, finite.
    min_exceed : int
        Null values at or above ``value`` from which the Monte Carlo p stands.
    min_tail : int
        Fewest values in a fitted tail.
    tail_share : float
        Share of N in the first tail tried.
    ad_level : float
        A fit is accepted where its Anderson-Darling p-value exceeds this.

    Returns
    -------
    TailP

    Examples
    --------
    >>> null = -np.log(1 - (np.arange(1, 100) / 100))  # exponential quantiles, N = 99
    >>> tail_p_value(1.0, null).p  # 36 at or above: (1 + 36) / (1 + 99)
    0.37
    >>> r = tail_p_value(8.0, null)  # beyond all 99: the tail of 25 over the 26th largest
    >>> r.method, r.n_tail, round(r.threshold, 4), f"{r.p:.1e}"  # exp(-8) = 3.4e-4
    ('gpd tail', 25, 1.3471, '1.6e-03')
    >>> tail_p_value(1.0, np.r_[np.zeros(91), np.ones(8)]).method  # clipped at 1: ties
    'monte carlo'
    """
    x, y = _checked(value, null)
    _checked_options(min_exceed, min_tail, tail_share, ad_level)
    n = y.size
    k = int(np.count_nonzero(y >= x))
    monte_carlo = TailP((1 + k) / (1 + n), MONTE_CARLO, n, 0, math.nan, math.nan, math.nan, math.nan)
    first = min(max(math.ceil(tail_share * n), min_tail), n - 1)
    if k >= min_exceed or first < max(min_tail, k + 1):
        return monte_carlo
    desc = np.sort(y)[::-1]
    distinct = np.cumprod(np.diff(desc) < 0).astype(bool)  # distinct[m - 1]: the m + 1 largest differ
    tails = np.unique(np.linspace(first, max(min_tail, k + 1), _TAILS_TRIED).round().astype(int))[::-1]
    for m in map(int, tails):
        t = float(desc[m])
        excess = desc[:m] - t
        if not distinct[m - 1] or not excess[-1] > 1e-12 * max(abs(t), excess[0]):
            continue  # ties, or an excess lost to rounding
        shape, scale = fit_gpd(excess)
        ad_p = anderson_darling_gpd(excess, shape, scale)[1]
        if ad_p > ad_level:
            p = (m + 1) / (n + 1) * predictive_sf(excess, x - t)
            if np.isfinite(p):
                return TailP(max(p, P_FLOOR), GPD_TAIL, n, m, shape, scale, t, ad_p)
    return monte_carlo
