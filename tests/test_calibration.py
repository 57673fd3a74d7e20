"""W calibration on constructed selections whose answer is known, and exact binomial bands."""

import numpy as np
import pytest

from hcid.calibration import calibrate, clopper_pearson
from hcid.selection import SelectionPath

INF = np.inf


def _segments(w_from, nb):
    """A realization selecting frontier rows 0, 1, ... on [w_from[i], w_from[i+1]), with those nb_ft."""
    w_from = np.asarray(w_from, dtype=float)
    return SelectionPath(np.arange(w_from.size), w_from, np.append(w_from[1:], INF)), np.asarray(nb)


def _twins():
    # FB: one realization is a false positive (nb_ft 1) up to W = 0.01, the other never.
    fb = [_segments([0.0, 0.01], [1, 0]), _segments([0.0], [0])]
    # FF: nb_ft 2 until W = 0.3 (then 0), and until W = 0.5 (then 1).
    ff = [_segments([0.0, 0.3], [2, 0]), _segments([0.0, 0.5], [2, 1])]
    split = lambda twins: ([s for s, _ in twins], [nb for _, nb in twins])  # noqa: E731
    return split(fb), split(ff)


def test_safe_interval_at_target_rate_zero():
    # Exact ends: no false positive from W = 0.01 on, no false negative below W = 0.3;
    # recommended W = sqrt(0.01 * 0.3), the geometric midpoint.
    fb, ff = _twins()
    cal = calibrate("direct", fb, ff, np.array([0.001, 0.02, 0.4, 1.0]), 0.0)
    assert (cal.safe_low, cal.safe_high) == (0.01, 0.3)
    assert cal.recommended == pytest.approx(np.sqrt(0.01 * 0.3), rel=1e-12)
    np.testing.assert_array_equal(cal.fp_rate, [0.5, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(cal.fn_rate, [0.0, 0.0, 0.5, 1.0])


def test_safe_interval_at_target_rate_half():
    # One of two FB realizations (rate 0.5) is accepted: no lower end; the FF rate exceeds 0.5
    # from W = 0.5 on; recommended a decade below the upper end.
    fb, ff = _twins()
    cal = calibrate("direct", fb, ff, np.array([0.1]), 0.5)
    assert (cal.safe_low, cal.safe_high, cal.recommended) == (0.0, 0.5, 0.05)


def test_no_safe_interval():
    fb = ([_segments([0.0, 0.6], [1, 0])[0]], [np.array([1, 0])])
    ff = ([_segments([0.0, 0.3], [2, 0])[0]], [np.array([2, 0])])
    cal = calibrate("direct", fb, ff, np.array([0.1]), 0.0)
    assert not cal.has_safe_interval and np.isnan(cal.recommended)


def test_clopper_pearson_exact_values():
    # k = 0 of n = 50: upper bound 1 - 0.025^(1/50) = 0.0711; k = n mirrors it.
    low, high = clopper_pearson(np.array([0, 50]), 50)
    assert low[0] == 0.0 and high[0] == pytest.approx(1 - 0.025 ** (1 / 50), rel=1e-9)
    assert high[1] == 1.0 and low[1] == pytest.approx(0.025 ** (1 / 50), rel=1e-9)


def test_clopper_pearson_against_the_exact_binomial_interval():
    # Source: scipy.stats.binomtest(k, n).proportion_ci(method="exact"), an independent
    # implementation of Clopper and Pearson (1934); e.g. 14 of 200 (7%): [0.0388, 0.1146].
    from scipy.stats import binomtest

    for k, n in ((0, 50), (1, 50), (3, 50), (14, 200), (100, 200), (200, 200)):
        low, high = clopper_pearson(np.array([k]), n)
        ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
        assert (low[0], high[0]) == pytest.approx((ci.low, ci.high), rel=1e-9, abs=1e-12)
    low, high = clopper_pearson(np.array([14]), 200)
    assert (low[0], high[0]) == pytest.approx((0.0388, 0.1146), abs=1e-4)


def test_error_rates_count_realizations_exactly_with_exact_bands():
    from hcid.calibration import error_rates

    fb, ff = _twins()
    w = np.array([0.005, 0.01, 0.4])
    fp = error_rates("direct", "FB", "false_positive", *fb, w)
    assert fp.k.tolist() == [1, 0, 0] and fp.n == 2  # [0, 0.01) half-open: none at 0.01
    fn = error_rates("direct", "FF", "false_negative", *ff, w)
    assert fn.rate.tolist() == [0.0, 0.0, 0.5]
    low, high = clopper_pearson(np.array([1]), 2)
    assert (fp.low[0], fp.high[0]) == (low[0], high[0])
    # 1 of 2: Beta(1, 2) and Beta(2, 1) quantiles, [1 - sqrt(0.975), sqrt(0.975)] = [0.0126, 0.9874]
    assert (low[0], high[0]) == pytest.approx((1 - 0.975**0.5, 0.975**0.5), rel=1e-9)
    table = fp.to_arrow()
    assert table.column_names == ["method", "model", "error", "w", "k", "n", "rate", "low", "high"]
