"""Residual analysis: the white-residual band, known correlations, a slow twin."""

import numpy as np
import pytest
from scipy import stats

from hcid.analysis.residuals import RESIDUAL, analyse_residuals
from hcid.errors import DataError, IdentificationError


def _slow_correlation(eps, x, lag):
    """Textbook definition, one lag, plain loops over the de-meaned series."""
    e = eps - eps.mean()
    y = x - x.mean()
    total = 0.0
    for t in range(len(e)):
        if 0 <= t - lag < len(y):
            total += e[t] * y[t - lag]
    return total / np.sqrt(np.sum(e**2) * np.sum(y**2))


def test_matches_the_textbook_definition_on_the_rows():
    # Slow twin: direct sums over the rows only, for every lag.
    rng = np.random.default_rng(1)
    eps, x = rng.standard_normal(80) + 0.3, rng.standard_normal(80) - 1.0
    rows = slice(10, 70)
    r = analyse_residuals(eps, {"x": x}, rows, max_lag=7)
    auto, cross = r.correlation(RESIDUAL), r.correlation("x")
    np.testing.assert_array_equal(auto.lags, np.arange(1, 8))
    np.testing.assert_array_equal(cross.lags, np.arange(-7, 8))
    for lag, value in zip(auto.lags, auto.values, strict=True):
        assert value == pytest.approx(_slow_correlation(eps[rows], eps[rows], lag), abs=1e-12)
    for lag, value in zip(cross.lags, cross.values, strict=True):
        assert value == pytest.approx(_slow_correlation(eps[rows], x[rows], lag), abs=1e-12)
    assert r.n == 60


def test_band_is_the_normal_quantile_over_sqrt_n():
    # 99%: z = 2.5758 (two-sided normal quantile), so 2.576/sqrt(N) as in MATLAB's resid.
    r = analyse_residuals(np.random.default_rng(0).standard_normal(2500), {}, slice(0, 2500), 5)
    assert r.bound == pytest.approx(2.5758293035489 / 50.0, rel=1e-12)
    r95 = analyse_residuals(
        np.random.default_rng(0).standard_normal(2500), {}, slice(0, 2500), 5, confidence=0.95
    )
    assert r95.bound == pytest.approx(1.959963984540054 / 50.0, rel=1e-12)


def test_white_residual_has_about_one_percent_of_lags_outside():
    # White eps, independent white input: each of the 1000 + 2001 lags is outside
    # the 99% band with probability 0.01 (independent for lags << N = 100,000).
    # Allowed: the exact binomial 99.9% interval of the count (seeded, so fixed).
    n, m = 100_000, 1000
    rng = np.random.default_rng(2024)
    r = analyse_residuals(rng.standard_normal(n), {"x": rng.standard_normal(n)}, slice(0, n), m)
    for c, lags in ((r.correlation(RESIDUAL), m), (r.correlation("x"), 2 * m + 1)):
        low, high = stats.binom.ppf([0.0005, 0.9995], lags, 0.01)
        outside = np.count_nonzero(c.outside)
        assert low <= outside <= high, (c.signal, outside, low, high)
    total = 3 * m + 1
    low, high = stats.binom.ppf([0.0005, 0.9995], total, 0.01)
    assert low / total <= r.share_outside <= high / total


def test_ma1_residual_is_detected_at_lag_one():
    # eps = w(t) + 0.5 w(t-1): rho(1) = 0.5 / (1 + 0.5^2) = 0.4, rho(k > 1) = 0.
    # Standard error of a sample autocorrelation ~1/sqrt(N) = 0.0045.
    n = 50_000
    w = np.random.default_rng(3).standard_normal(n + 1)
    eps = w[1:] + 0.5 * w[:-1]
    auto = analyse_residuals(eps, {}, slice(0, n), 20).correlation(RESIDUAL)
    assert auto.values[0] == pytest.approx(0.4, abs=0.02)
    assert auto.outside[0]
    # Lag 2 has Bartlett variance (1 + 2 rho1^2)/N: 5 standard errors is 0.03.
    assert np.all(np.abs(auto.values[1:]) < 0.03)


def test_input_correlation_is_detected_at_its_lag():
    # eps = w + 0.5 x(t - 3), x and w white and unit: rho_eps,x(3) = 0.5 / sqrt(1.25)
    # = 0.447 at +3 (eps follows past x) and nothing at -3.
    n = 20_000
    rng = np.random.default_rng(4)
    x, w = rng.standard_normal(n), rng.standard_normal(n)
    eps = w + 0.5 * np.concatenate([np.zeros(3), x[:-3]])
    r = analyse_residuals(eps, {"x": x}, slice(0, n), 10, rate=25.0)
    cross = r.correlation("x")
    at = dict(zip(cross.lags.tolist(), cross.values, strict=True))
    assert at[3] == pytest.approx(0.5 / np.sqrt(1.25), abs=0.02)
    assert cross.outside[cross.lags == 3].item()
    assert abs(at[-3]) < 5 / np.sqrt(n)
    rows = r.rows()
    assert len(rows) == 10 + 21
    hit = [row for row in rows if row["signal"] == "x" and row["lag"] == 3][0]
    assert hit["outside"] and hit["kind"] == "cross" and hit["lag_s"] == pytest.approx(0.12)
    summary = {row["signal"]: row for row in r.summary_rows()}
    assert summary["x"]["outside"] >= 1 and summary["x"]["lags"] == 21


def test_bad_inputs_are_refused():
    eps = np.random.default_rng(0).standard_normal(100)
    with pytest.raises(IdentificationError, match=r"max_lag: must be an integer in \[1, 49\]"):
        analyse_residuals(eps, {}, slice(50, 100), 50)
    with pytest.raises(DataError, match="x: is constant on the rows"):
        analyse_residuals(eps, {"x": np.ones(100)}, slice(0, 100), 5)
    with pytest.raises(DataError, match="x: must be a 1-D array of the residual's length"):
        analyse_residuals(eps, {"x": np.ones(99)}, slice(0, 100), 5)
    with pytest.raises(IdentificationError, match="rows"):
        analyse_residuals(eps, {}, slice(0, 101), 5)
    with pytest.raises(DataError, match="eps: must be finite"):
        analyse_residuals(np.full(100, np.nan), {}, slice(0, 100), 5)
