"""W calibration from simulations of an HC hypothesis (paper section 6, first recommendation).

A feedback-only twin (FB) and a feedforward twin (FF) of the expected HC are
simulated and identified; the false-positive rate (FB realizations selecting
nb_ft > 0) and the false-negative rate (FF realizations selecting nb_ft < 2)
are then functions of W, known exactly from each realization's breakpoints.
The safe interval is where both rates are at most the target rate; the
recommended W is its geometric midpoint, the point farthest from both ends
on the log-W axis on which W acts.

Pure functions; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

import numpy as np
import pyarrow as pa
from scipy.special import _ufuncs

from hcid import tables
from hcid.selection.over_w import SelectionPath, false_positive_extent
from hcid.selection.tail import MONTE_CARLO, tail_p_value

__all__ = [
    "ERRORS",
    "Calibration",
    "RateCurve",
    "Selections",
    "TwinPaths",
    "WChoice",
    "WRule",
    "benjamini_hochberg",
    "binomial_summary",
    "calibrate",
    "choose_w",
    "clopper_pearson",
    "count_power",
    "error_rates",
    "evidence_p_value",
    "evidence_power",
    "feedforward_threshold",
    "rates_at",
    "run_p_value",
    "separates",
    "sequential_p_value",
    "sequential_settled",
]

#: The two errors of SPEC 4 and 9, by name: which selected nb_ft counts as wrong.
#: FB realizations (no feedforward) are judged for false positives, FF ones for false negatives.
ERRORS = {
    "false_positive": lambda nb: nb > 0,
    "false_negative": lambda nb: nb < 2,
}


class Selections(NamedTuple):
    """Realizations' selections over W: each one's selection path and the nb_ft of every row of
    its frontier (which the path's segments index)."""

    paths: list[SelectionPath]
    nb_ft: list[np.ndarray]


class TwinPaths(NamedTuple):
    """The FB and the FF twins' selections (:func:`calibrate`'s ``fb`` and ``ff``)."""

    fb: Selections
    ff: Selections


def clopper_pearson(k: np.ndarray, n: int, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Exact binomial confidence interval of a rate k/n (Clopper and Pearson 1934)."""
    k = np.asarray(k, dtype=np.float64)
    alpha = 1.0 - level
    # scipy.stats.beta.ppf's own ufunc (its _ppf), without importing scipy.stats (0.5 s of
    # every command); tests/test_calibration.py holds it to beta.ppf's bits.
    low = np.where(k > 0, _ufuncs._beta_ppf(alpha / 2, k, n - k + 1), 0.0)
    high = np.where(k < n, _ufuncs._beta_ppf(1 - alpha / 2, k + 1, n - k), 1.0)
    return low, high


def _counts(segments: list[SelectionPath], nb_ft: list[np.ndarray], w: np.ndarray, positive) -> np.ndarray:
    return np.sum([positive(nb[s.at(w)]) for s, nb in zip(segments, nb_ft, strict=True)], axis=0)


def rates_at(
    fb: Selections,
    ff: Selections,
    w: float,
) -> dict[str, float]:
    """The twins' false-positive and false-negative rates at one W, exactly (from their
    selection paths, not the nearest grid point), with exact 95% bands (SPEC 9).

    ``fb``, ``ff`` as for :func:`calibrate`. Keys ``fp_rate``, ``fp_low``, ``fp_high``,
    ``fn_rate``, ``fn_low``, ``fn_high``.
    """
    at = np.array([float(w)])
    n_fb, n_ff = len(fb[0]), len(ff[0])
    fp = _counts(*fb, at, lambda nb: nb > 0)
    fn = _counts(*ff, at, lambda nb: nb < 2)
    fp_low, fp_high = clopper_pearson(fp, n_fb)
    fn_low, fn_high = clopper_pearson(fn, n_ff)
    return {
        "fp_rate": float(fp[0] / n_fb),
        "fp_low": float(fp_low[0]),
        "fp_high": float(fp_high[0]),
        "fn_rate": float(fn[0] / n_ff),
        "fn_low": float(fn_low[0]),
        "fn_high": float(fn_high[0]),
    }


@dataclass(frozen=True)
class RateCurve:
    """The share of realizations making one error, at each W, with its exact 95% band (SPEC 9)."""

    method: str
    model: str
    error: str
    w: np.ndarray
    k: np.ndarray
    n: int
    rate: np.ndarray
    low: np.ndarray
    high: np.ndarray

    def to_arrow(self) -> pa.Table:
        m = self.w.size
        return pa.Table.from_pydict(
            {
                "method": [self.method] * m,
                "model": [self.model] * m,
                "error": [self.error] * m,
                "w": self.w,
                "k": self.k.astype(np.int64),
                "n": [self.n] * m,
                "rate": self.rate,
                "low": self.low,
                "high": self.high,
            },
            schema=tables.RATES.arrow,
        )


def error_rates(
    method: str, model: str, error: str, segments: list[SelectionPath], nb_ft: list[np.ndarray], w: np.ndarray
) -> RateCurve:
    """Rate of ``error`` (a key of :data:`ERRORS`) over realizations at each W, exactly, with
    Clopper-Pearson 95% bands.

    Examples
    --------
    >>> from hcid.selection.over_w import SelectionPath
    >>> seg = SelectionPath(np.array([0, 1]), np.array([0.0, 0.01]), np.array([0.01, np.inf]))
    >>> c = error_rates("direct", "FB", "false_positive", [seg, seg], [np.array([2, 0])] * 2, [0.005, 0.02])
    >>> c.rate.tolist(), np.round(c.high, 4).tolist()  # k = 0 of 2: 1 - 0.025^(1/2)
    ([1.0, 0.0], [1.0, 0.8419])
    """
    w = np.asarray(w, dtype=np.float64)
    n = len(segments)
    k = _counts(segments, nb_ft, w, ERRORS[error])
    low, high = clopper_pearson(k, n)
    return RateCurve(method, model, error, w, k, n, k / n, low, high)


@dataclass(frozen=True)
class Calibration:
    """False-positive and false-negative rates over W for one method, and the safe interval.

    ``safe_low <= W < safe_high`` keeps both rates at most ``target_rate``;
    ``safe_low >= safe_high`` means there is no safe W (``recommended`` is NaN).
    """

    method: str
    w: np.ndarray
    fp_rate: np.ndarray
    fp_low: np.ndarray
    fp_high: np.ndarray
    fn_rate: np.ndarray
    fn_low: np.ndarray
    fn_high: np.ndarray
    n_fb: int
    n_ff: int
    target_rate: float
    safe_low: float
    safe_high: float
    recommended: float

    @property
    def has_safe_interval(self) -> bool:
        return bool(self.safe_low < self.safe_high)

    def to_arrow(self) -> pa.Table:
        n = self.w.size
        return pa.Table.from_pydict(
            {
                "method": [self.method] * n,
                "w": self.w,
                "fp_rate": self.fp_rate,
                "fp_low": self.fp_low,
                "fp_high": self.fp_high,
                "fn_rate": self.fn_rate,
                "fn_low": self.fn_low,
                "fn_high": self.fn_high,
                "n_fb": [self.n_fb] * n,
                "n_ff": [self.n_ff] * n,
                "target_rate": np.full(n, self.target_rate),
                "safe_low": np.full(n, self.safe_low),
                "safe_high": np.full(n, self.safe_high),
                "recommended": np.full(n, self.recommended),
            },
            schema=tables.CALIBRATION.arrow,
        )


def calibrate(
    method: str,
    fb: Selections,
    ff: Selections,
    w: np.ndarray,
    target_rate: float = 0.0,
) -> Calibration:
    """Rates over the W grid and the exact safe interval from the breakpoints.

    Parameters
    ----------
    method : str
    fb, ff : (segments, nb_ft) per realization
        Selections over W of the feedback-only and feedforward twins, and the
        nb_ft of every frontier row (indexed by the segments).
    w : ndarray
        W grid for the rate curves.
    target_rate : float
        Largest acceptable rate; 0 asks for no false result in any realization,
        which makes ``safe_low`` equal to W_FP.
    """
    w = np.asarray(w, dtype=np.float64)
    n_fb, n_ff = len(fb[0]), len(ff[0])
    fp_k = _counts(*fb, w, lambda nb: nb > 0)
    fn_k = _counts(*ff, w, lambda nb: nb < 2)
    fp_low, fp_high = clopper_pearson(fp_k, n_fb)
    fn_low, fn_high = clopper_pearson(fn_k, n_ff)

    # Exact ends: the rates only change at breakpoints, so evaluate them there.
    fp_at = np.unique(np.concatenate([s.w_from for s in fb[0]]))
    fp_rate_at = _counts(*fb, fp_at, lambda nb: nb > 0) / n_fb
    too_many = np.flatnonzero(fp_rate_at > target_rate)
    safe_low = (
        0.0
        if too_many.size == 0
        else (float(fp_at[too_many[-1] + 1]) if too_many[-1] + 1 < fp_at.size else np.inf)
    )
    fn_at = np.unique(np.concatenate([s.w_from for s in ff[0]]))
    fn_rate_at = _counts(*ff, fn_at, lambda nb: nb < 2) / n_ff
    over = np.flatnonzero(fn_rate_at > target_rate)
    safe_high = float(fn_at[over[0]]) if over.size else np.inf

    if safe_low < safe_high and np.isfinite(safe_high) and safe_low > 0:
        recommended = float(np.sqrt(safe_low * safe_high))
    elif safe_low < safe_high and np.isfinite(safe_high):
        recommended = safe_high / 10.0  # no lower bound: a decade below the upper end
    elif safe_low < safe_high and safe_low > 0:
        recommended = safe_low * 10.0  # no upper bound: a decade above the lower end
    else:
        recommended = float("nan")
    return Calibration(
        method=method,
        w=w,
        fp_rate=fp_k / n_fb,
        fp_low=fp_low,
        fp_high=fp_high,
        fn_rate=fn_k / n_ff,
        fn_low=fn_low,
        fn_high=fn_high,
        n_fb=n_fb,
        n_ff=n_ff,
        target_rate=target_rate,
        safe_low=safe_low,
        safe_high=safe_high,
        recommended=recommended,
    )


# --------------------------------------------------------------------------- per-run evidence (SPEC 11)


class WRule(StrEnum):
    """How a group's W was chosen (:func:`choose_w`; ``analysis_groups.w_rule``)."""

    SAFE_INTERVAL = "safe interval"
    LEAST_ERROR = "least total error (no safe interval)"
    LEAST_ERROR_SPLIT = "least total error (no contiguous safe interval)"


class WChoice(NamedTuple):
    """A group's W, how it was chosen, and whether decisions there are uncertain."""

    w: float
    rule: WRule
    uncertain: bool


def separates(cal: Calibration) -> bool:
    """Whether a calibration has a safe interval (a W that tells its twins apart)."""
    return bool(cal.has_safe_interval and math.isfinite(cal.recommended))


def choose_w(cal: Calibration) -> WChoice:
    """The group's W and whether its decisions are uncertain.

    The recommended W of a safe interval; else the grid's least total error (FP + FN), the
    geometric middle of the range of grid points that tie for it (twins that nearly coincide
    tie almost everywhere: the smallest W would call everything feedforward). Uncertain when
    either twin's rate there exceeds the target rate (:attr:`WRule.LEAST_ERROR`; else the rates
    are within it, yet no interval is: :attr:`WRule.LEAST_ERROR_SPLIT`).
    """
    if separates(cal):
        return WChoice(float(cal.recommended), WRule.SAFE_INTERVAL, False)
    total = cal.fp_rate + cal.fn_rate
    tied = np.flatnonzero(total <= total.min() + 1e-12)
    i = int(tied[len(tied) // 2])
    uncertain = bool(max(cal.fp_rate[i], cal.fn_rate[i]) > cal.target_rate)
    return WChoice(float(cal.w[i]), WRule.LEAST_ERROR if uncertain else WRule.LEAST_ERROR_SPLIT, uncertain)


def feedforward_threshold(path: SelectionPath, nb_ft: np.ndarray, w_min: float, w_max: float) -> float:
    """A run's W*: the largest W of the grid's range ``[w_min, w_max]`` at which its selection
    keeps ``nb_ft > 0`` (SPEC 11), exact from its selection path (:func:`false_positive_extent`):
    ``w_min`` when it never does, ``w_max`` when it always does.

    Examples
    --------
    >>> seg = SelectionPath(np.array([0, 1, 2]), np.array([0.0, 0.01, 0.2]), np.array([0.01, 0.2, np.inf]))
    >>> feedforward_threshold(seg, np.array([3, 1, 0]), 1e-4, 2.0)
    0.2
    >>> never, always = np.array([0, 0, 0]), np.array([1, 1, 1])
    >>> feedforward_threshold(seg, never, 1e-4, 2.0), feedforward_threshold(seg, always, 1e-4, 2.0)
    (0.0001, 2.0)
    """
    return float(np.clip(false_positive_extent(path, nb_ft), w_min, w_max))


def evidence_p_value(w_star: float, fb_thresholds: np.ndarray) -> float:
    """How often a person without feedforward (the FB twins) shows at least as much:
    ``(1 + #{FB twins with W* >= w_star}) / (1 + N)`` (SPEC 11; a Monte Carlo p-value, never 0).

    Examples
    --------
    >>> evidence_p_value(0.3, np.array([0.001, 0.01, 0.3, 0.5]))  # two of four at or above
    0.6
    >>> evidence_p_value(1.0, np.zeros(19))
    0.05
    """
    fb = np.asarray(fb_thresholds, dtype=np.float64)
    return float((1 + np.count_nonzero(fb >= w_star)) / (1 + fb.size))


def evidence_power(ff_thresholds: np.ndarray, fb_thresholds: np.ndarray, alpha: float) -> float:
    """The share of FF twins that the run's own rule calls feedforward at level ``alpha``: their
    :func:`run_p_value` against the FB twins at most ``alpha`` (SPEC 11's power: FF twins above
    the FB twins' (1 - alpha) quantile, with the p-value's own rule, the tail beyond every twin).

    Examples
    --------
    >>> evidence_power(np.array([2.0, 2.0, 0.2, 0.001]), np.full(19, 0.1), 0.05)
    0.75
    """
    ff = np.asarray(ff_thresholds, dtype=np.float64)
    fb = np.asarray(fb_thresholds, dtype=np.float64)
    # Beyond every FB twin the p is at most the count's 1 / (N + 1): at a level at or above that,
    # such an FF twin is found without fitting the tail (the fit is most of the time here).
    beyond = alpha >= 1.0 / (fb.size + 1)
    # An FF twin without the statistic (NaN) is not found.
    found = [
        not math.isnan(w) and ((beyond and not np.any(fb >= w)) or run_p_value(w, fb)[0] <= alpha) for w in ff
    ]
    return float(np.mean(found))


def sequential_p_value(value: float, fb_in_order: np.ndarray, h: int) -> tuple[float, int]:
    """A run's p-value from FB twins drawn one after another until ``h`` of them show at least
    ``value`` (Besag and Clifford 1991): ``h / m`` at the ``m``-th draw that makes ``h``; else,
    every draw made (``n``) with ``k < h`` at or above, :func:`evidence_p_value`'s
    ``(1 + k) / (1 + n)``. Returns the p-value and the draws it used. Twins drawn after the
    run's own stop do not change it, so runs that share twins each keep their own stop.

    Examples
    --------
    >>> fb = np.array([0.5, 0.1, 0.4, 0.3, 0.2, 0.6])
    >>> sequential_p_value(0.25, fb, 2)  # the second at or above 0.25 is the 3rd draw
    (0.6666666666666666, 3)
    >>> sequential_p_value(0.55, fb, 2)  # one of six: (1 + 1) / (1 + 6)
    (0.2857142857142857, 6)
    """
    fb = np.asarray(fb_in_order, dtype=np.float64)
    seen = np.cumsum(fb >= value)
    if seen.size and seen[-1] >= h:
        m = int(np.searchsorted(seen, h)) + 1
        return h / m, m
    return evidence_p_value(value, fb), int(fb.size)


def run_p_value(value: float, fb_in_order: np.ndarray, h: int = 5) -> tuple[float, int, str]:
    """A run's p-value against its FB twins in the order drawn, the twins it used, and how it was
    made (NaN, 0 and ``""`` where the run has no value of the statistic: a NaN would otherwise lie
    beyond every twin): Besag and Clifford's sequential p where ``h`` twins reached the run's
    value (the draws stopped there: ``h / m``), else the Monte Carlo ``(1 + k) / (1 + N)`` over
    every twin drawn; and where the run is beyond every twin (k = 0), where Monte Carlo stops at
    ``1 / (N + 1)``, the generalized Pareto tail of SPEC 13 (:func:`hcid.selection.tail.tail_p_value`;
    on the log scale where every value is positive, as W* and the Fourier size are), at most that.
    Between ``1 / (N + 1)`` and ``10 / (N + 1)`` the tail is conservative (measured on real twins
    and in tests/test_calibration.py: docs/methodology.md), so the exact count stands there; and
    at levels below ``1 / (N + 1)`` the minimum is the tail's p alone, so its level is the tail's.

    Examples
    --------
    >>> fb = np.exp(np.linspace(-3.0, 0.0, 39))  # 39 FB twins' W*, the largest 1.0
    >>> run_p_value(0.5, fb)[1:]  # 5 reached by the 35th draw: the sequential p, 5/35
    (35, 'monte carlo')
    >>> run_p_value(0.95, fb)  # one at or above: (1 + 1) / (1 + 39)
    (0.05, 39, 'monte carlo')
    >>> p, n, how = run_p_value(2.0, fb)  # beyond every twin: the tail
    >>> n, how, p < 1 / 40
    (39, 'gpd tail', True)
    """
    if math.isnan(value):  # no statistic (a fit that gave none): no p, no evidence either way
        return math.nan, 0, ""
    fb = np.asarray(fb_in_order, dtype=np.float64)
    p, n = sequential_p_value(value, fb, h)
    if n < fb.size or np.count_nonzero(fb >= value) > 0 or fb.size < 2:
        return p, n, MONTE_CARLO
    drawn = fb[np.isfinite(fb)]  # a twin drawn for the other statistic only has none of this one
    if drawn.size < 2 or not math.isfinite(value):
        return p, n, MONTE_CARLO
    log = value > 0 and bool(np.all(drawn > 0))
    tail = tail_p_value(math.log(value) if log else value, np.log(drawn) if log else drawn)
    # At most the Monte Carlo 1 / (N + 1): below it the tail's own p, above it the exact count's.
    return min(tail.p, p), n, tail.method


#: The fewest FB twins whose tail may settle a run beyond every one of them (the calibration's 20
#: and one batch more: the tail fit's quarter is then at least 10 twins, SPEC 13).
TAIL_SETTLES_FROM = 40


def sequential_settled(
    value: float, fb_in_order: np.ndarray, h: int, n_max: int, tail_below: float | None = None
) -> bool:
    """Whether more FB twins could change the decision on ``value``: not once ``h`` are at or
    above it (Besag and Clifford's stop), nor once ``n_max`` are drawn; and, with ``tail_below``,
    not once at least :data:`TAIL_SETTLES_FROM` are drawn, none at or above it, and their
    generalized Pareto tail (:func:`run_p_value`) puts its p at most ``tail_below``. A run far
    beyond every twin then stops at 40 where it took every one of ``n_max``: under the null a stop
    at one look happens with probability about ``tail_below`` (the tail's level), so over the
    looks at 40, 60 and 80 twins it can add at most about three times that to the level of a
    decision at ``alpha`` (``tail_below = alpha / 10``: 0.3 alpha in the worst case; measured, too
    little to see in 8000 null runs: tests/test_calibration.py).

    Examples
    --------
    >>> sequential_settled(0.25, np.array([0.5, 0.1]), 2, 99)  # one of two at or above
    False
    >>> sequential_settled(0.25, np.array([0.5, 0.3]), 2, 99)
    True
    >>> fb = np.exp(np.linspace(-3.0, 0.0, 40))  # 40 FB twins' W*, the largest 1.0
    >>> sequential_settled(5.0, fb, 5, 99), sequential_settled(5.0, fb, 5, 99, tail_below=0.005)
    (False, True)
    """
    fb = np.asarray(fb_in_order, dtype=np.float64)
    hits = np.count_nonzero(fb >= value)
    if fb.size >= n_max or hits >= h:
        return True
    if tail_below is None or hits > 0 or fb.size < TAIL_SETTLES_FROM:
        return False
    p, _, how = run_p_value(value, fb, h)
    return how != MONTE_CARLO and p <= tail_below


def binomial_summary(p_values: np.ndarray, alpha: float) -> tuple[int, int, float]:
    """A group's summary test: ``k`` of its ``n`` runs with ``p <= alpha``, and the chance of at
    least ``k`` if no run had feedforward (each then at most alpha: Binomial(n, alpha)).

    Examples
    --------
    >>> binomial_summary(np.array([0.01, 0.5, 0.03, 0.9]), 0.05)[:2]
    (2, 4)
    """
    p = np.asarray(p_values, dtype=np.float64)
    k, n = int(np.count_nonzero(p <= alpha)), int(p.size)
    from scipy import stats

    return k, n, float(stats.binom.sf(k - 1, n, alpha)) if n else float("nan")


def count_power(powers: np.ndarray, alpha: float) -> float:
    """The power of :func:`binomial_summary`'s test: the chance that at least ``k`` of the ``n``
    runs reach p <= alpha, ``k`` the fewest it calls significant (``Binomial(n, alpha)``'s chance
    of at least ``k`` at most alpha), were each run found with its own power (a Poisson binomial).
    NaN where a run's power is.

    Examples
    --------
    >>> round(count_power(np.full(6, 0.5), 0.05), 6)  # k = 2: 1 - (1 + 6) / 2^6
    0.890625
    >>> count_power(np.array([0.8, 0.8]), 0.05)  # k = 2 (one of two is not significant): 0.8^2
    0.6400000000000001
    """
    powers = np.asarray(powers, dtype=np.float64)
    n = powers.size
    if n == 0 or not np.all(np.isfinite(powers)):
        return float("nan")
    from scipy import stats

    k = next(k for k in range(1, n + 1) if stats.binom.sf(k - 1, n, alpha) <= alpha)
    found = np.array([1.0])  # the chance of each number of runs found, by convolution
    for q in powers:
        found = np.convolve(found, [1.0 - q, q])
    return float(min(1.0, found[k:].sum()))


def benjamini_hochberg(p_values: np.ndarray, q: float) -> np.ndarray:
    """Which p-values are discoveries with the false discovery rate controlled at ``q`` over them
    (Benjamini and Hochberg 1995).

    Examples
    --------
    >>> benjamini_hochberg(np.array([0.01, 0.03, 0.02, 0.5]), 0.05).tolist()  # 0.03 <= 3/4 of 0.05
    [True, True, True, False]
    >>> benjamini_hochberg(np.array([0.01, 0.04, 0.03, 0.5]), 0.05).tolist()  # 0.03 > 2/4 of 0.05
    [True, False, False, False]
    """
    p = np.asarray(p_values, dtype=np.float64)
    order = np.argsort(p, kind="stable")
    passed = p[order] <= q * np.arange(1, p.size + 1) / p.size
    out = np.zeros(p.size, dtype=bool)
    if passed.any():
        out[order[: np.flatnonzero(passed)[-1] + 1]] = True
    return out
