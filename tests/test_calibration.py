"""W calibration on constructed selections whose answer is known, and exact binomial bands."""

import numpy as np
import pytest

from hcid.selection.calibration import calibrate, clopper_pearson, sequential_p_value, sequential_settled
from hcid.selection.over_w import SelectionPath

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
    from hcid.selection.calibration import error_rates

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


# --------------------------------------------------------------------------- per-run evidence (SPEC 11)


def test_a_runs_p_value_and_power_follow_spec_11():
    # Source: SPEC 11's formulas. 19 FB twins with W* 0.01, 0.02, ..., 0.19: a run at W* 0.185 has
    # one FB twin at or above (0.19): p = (1 + 1) / 20 = 0.1; at 0.2, none: p = 1/20 = 0.05.
    from hcid.selection.calibration import evidence_p_value, evidence_power

    fb = np.arange(1, 20) / 100.0
    assert evidence_p_value(0.185, fb) == pytest.approx(0.1)
    assert evidence_p_value(0.2, fb) == pytest.approx(0.05)
    assert evidence_p_value(0.0, fb) == 1.0
    # FF twins: 3 of 4 above every FB twin (p = 0.05 <= 0.05), one among them.
    assert evidence_power(np.array([0.3, 0.5, 1.0, 0.1]), fb, 0.05) == 0.75
    # At 0.01, below the count's 1/20, the power is the tail's (run_p_value, SPEC 13): the FF
    # twins far beyond the FB twins' evenly spread tail are found, the one among them is not.
    from hcid.selection.calibration import run_p_value

    assert run_p_value(1.0, fb)[1:] == (19, "gpd tail") and run_p_value(1.0, fb)[0] < 0.01
    assert evidence_power(np.array([0.3, 0.5, 1.0, 0.1]), fb, 0.01) == np.mean(
        [run_p_value(w, fb)[0] <= 0.01 for w in (0.3, 0.5, 1.0, 0.1)]
    )
    assert evidence_power(np.array([0.1]), fb, 0.01) == 0.0


def test_the_threshold_is_the_selection_paths_last_feedforward_w_clipped_to_the_grid():
    from hcid.selection.calibration import feedforward_threshold

    path = SelectionPath(
        np.array([0, 1, 2, 3]), np.array([0.0, 1e-3, 0.05, 0.3]), np.array([1e-3, 0.05, 0.3, np.inf])
    )
    # Rows 0 and 2 keep feedforward: the last such interval ends at 0.3.
    assert feedforward_threshold(path, np.array([2, 0, 1, 0]), 1e-4, 2.0) == 0.3
    assert feedforward_threshold(path, np.array([0, 0, 0, 1]), 1e-4, 2.0) == 2.0  # always: the grid's top
    assert feedforward_threshold(path, np.array([0, 0, 0, 0]), 1e-4, 2.0) == 1e-4  # never: its bottom


def test_the_binomial_summary_and_the_false_discovery_rate():
    # Source: P(X >= 2) for X ~ Binomial(4, 0.05) = 1 - 0.95^4 - 4 * 0.05 * 0.95^3 = 0.014019.
    from hcid.selection.calibration import benjamini_hochberg, binomial_summary

    k, n, p = binomial_summary(np.array([0.01, 0.5, 0.03, 0.9]), 0.05)
    assert (k, n) == (2, 4) and p == pytest.approx(1 - 0.95**4 - 4 * 0.05 * 0.95**3)
    assert binomial_summary(np.array([0.5, 0.9]), 0.05)[2] == 1.0
    # Benjamini-Hochberg: sorted p 0.001, 0.012, 0.02, 0.04, 0.9 against 0.01, 0.02, 0.03, 0.04, 0.05.
    found = benjamini_hochberg(np.array([0.9, 0.012, 0.04, 0.001, 0.02]), 0.05)
    assert found.tolist() == [False, True, True, True, True]


def test_runs_share_a_forcing_set_when_their_forcing_functions_agree():
    # Source: SPEC 11: within 0.1% RMS over the window. Runs 1 and 3 share theirs, run 2 has the
    # sign flipped (the same set: its twins are the set's, exactly; test_a_flipped_record_...),
    # run 6 only ft's sign (a set of its own), run 4 differs from run 1 by 0.05% RMS (same set),
    # run 5 by 0.2% (a set of its own).
    from types import SimpleNamespace

    from hcid.pipeline.twins import forcing_sets

    t = np.arange(400) / 10.0
    ft, fd = np.sin(0.5 * t), np.cos(0.7 * t)
    bump = np.sin(3.0 * t)  # RMS 1/sqrt(2), as ft's
    records = {1: {"ft": ft, "fd": fd}, 2: {"ft": -ft, "fd": -fd}, 3: {"ft": ft.copy(), "fd": fd.copy()},
               4: {"ft": ft + 0.0005 * bump, "fd": fd}, 5: {"ft": ft + 0.002 * bump, "fd": fd},
               6: {"ft": -ft, "fd": fd}}  # fmt: skip
    config = SimpleNamespace(timing=SimpleNamespace(window=40.0, output_rate=10.0))
    assert forcing_sets([1, 2, 3, 4, 5, 6], records, config) == [[1, 2, 3, 4], [5], [6]]


@pytest.mark.parametrize("method", ["direct", "indirect"])
def test_a_flipped_record_is_identified_exactly_as_the_record(ci_config, method):
    # Why a forcing set and its sign flip share their twins (hcid.pipeline.twins.forcing_sets):
    # every signal negated (forcing, e, u: a linear loop's response to -f with the remnant
    # negated) gives bit for bit the same candidates' V, so the same selection path and W*
    # (IEEE arithmetic rounds symmetrically: -a * -b = a * b, -a + -b = -(a + b)).
    from hcid.methods import identify

    from .conftest import _record

    record = {k: v for k, v in _record(ci_config, "FB", 3).items() if k in ("ft", "fd", "e", "u")}
    flipped = {k: -v for k, v in record.items()}
    rate = ci_config.timing.output_rate
    one = identify(record, ci_config.identify, method, rate=rate)
    other = identify(flipped, ci_config.identify, method, rate=rate)
    for name in ("na", "nb1", "nb2", "nk1", "nk2", "v", "vaf_validation", "n_unstable"):
        a, b = getattr(one.fit, name), getattr(other.fit, name)
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name  # NaN: a row without candidates
    for a, b in zip(one.choices, other.choices, strict=True):  # stage 1's choice and its e_r
        assert (a.na, a.nb1, a.nb2, a.nk1, a.nk2, a.v) == (b.na, b.nb1, b.nb2, b.nk1, b.nk2, b.v)
        assert np.array_equal(a.signal, -b.signal)


def test_sequential_p_value_has_its_level_under_the_null():
    # Source: Besag and Clifford (1991): with the run and its FB twins exchangeable (here i.i.d.
    # uniform), P(p <= a) = a at every level the rule can give; at h = 5 and 99 twins the levels
    # 0.01 and 0.05 are both attainable (1/100 and 5/100). 20000 draws: binomial 99.9% bands.
    rng = np.random.default_rng(2016)
    n = 20000
    p = np.array([sequential_p_value(x, rng.random(99), 5)[0] for x in rng.random(n)])
    for level in (0.01, 0.05):
        band = 3.3 * np.sqrt(level * (1 - level) / n)
        assert abs(np.mean(p <= level + 1e-12) - level) < band
    # And it stops early where it can: a run in the middle of its twins needs about 10 draws.
    used = [sequential_p_value(0.5, rng.random(99), 5)[1] for _ in range(2000)]
    assert 9.0 < np.mean(used) < 11.0  # negative binomial: 5 / 0.5 draws on average


@pytest.mark.parametrize("null", ["lognormal", "exponential", "uniform"])
def test_a_runs_p_value_from_39_twins_and_their_tail_has_its_level_under_the_null(null):
    # Source: SPEC 13's calibration rule: under the null, P(p <= 0.01) and P(p <= 0.05) within their
    # binomial 99% bands, over 4000 runs, each with its own 39 FB twins (the default), the run's
    # p-value as hcid analyse makes it (sequential, then the generalized Pareto tail of all 39 where
    # fewer than 5 reach the run: hcid.pipeline.evidence.run_p_value). Monte Carlo over 39 cannot
    # give p <= 0.01 at all (1/40); the tail can, and must not too often.
    from scipy import stats

    from hcid.selection.calibration import run_p_value

    rng = np.random.default_rng(47)
    draw = {"lognormal": lambda k: np.exp(rng.normal(0, 1, k)), "uniform": lambda k: rng.random(k),
            "exponential": lambda k: rng.exponential(1, k)}[null]  # fmt: skip
    n = 4000
    p = np.array([run_p_value(float(draw(1)[0]), draw(39))[0] for _ in range(n)])
    for level in (0.01, 0.05):
        low, high = stats.binom.ppf([0.005, 0.995], n, level) / n
        assert low <= np.mean(p <= level) <= high, (null, level, np.mean(p <= level))


@pytest.mark.parametrize("null", ["lognormal", "exponential"])
def test_stopping_a_run_beyond_every_twin_at_its_tail_keeps_the_level(null):
    # Source: SPEC 13's calibration rule, for the draws as hcid analyse makes them: 20 FB twins,
    # then batches of 20 up to 99, stopped once 5 reach the run, or once 40 or more are drawn with
    # none reaching it and their tail's p at most alpha / 10 = 0.005 (sequential_settled); the p
    # over the twins drawn. Over 4000 null runs P(p <= 0.01) and P(p <= 0.05) within their
    # binomial 99% bands; a run far beyond every twin stops at 40, not 99.
    from scipy import stats

    from hcid.selection.calibration import run_p_value

    rng = np.random.default_rng(4747)
    draw = {
        "lognormal": lambda k: np.exp(rng.normal(0, 1, k)),
        "exponential": lambda k: rng.exponential(1, k),
    }[null]

    def drawn_for(value):
        fb = draw(20)
        while not sequential_settled(value, fb, 5, 99, tail_below=0.005):
            fb = np.concatenate([fb, draw(min(20, 99 - fb.size))])
        return fb

    n = 4000
    p = np.array([run_p_value(x, drawn_for(x))[0] for x in draw(n)])
    for level in (0.01, 0.05):
        low, high = stats.binom.ppf([0.005, 0.995], n, level) / n
        assert low <= np.mean(p <= level) <= high, (null, level, np.mean(p <= level))
    far = float(np.max(draw(10000)))  # beyond 10000 draws: settled by the tail before 99
    assert drawn_for(far).size < 99
    assert drawn_for(100 * far).size == 40  # far beyond: at the first chance, 40


def test_sequential_settled_needs_h_at_or_above_or_the_most_drawn():
    assert not sequential_settled(0.9, np.linspace(0, 1, 20), 5, 99)  # 2 at or above 0.9
    assert sequential_settled(0.5, np.linspace(0, 1, 20), 5, 99)  # 10 at or above
    assert sequential_settled(0.99, np.linspace(0, 1, 99), 5, 99)  # the most drawn


def test_clopper_pearson_is_scipy_stats_beta_ppf_bit_for_bit():
    # Source: the interval's definition, scipy.stats.beta.ppf at alpha/2 and 1 - alpha/2
    # (Clopper and Pearson 1934); calibration calls beta.ppf's own ufunc to spare every
    # command the import of scipy.stats, so its 64 bits must be beta.ppf's.
    from scipy import stats

    from hcid.selection.calibration import clopper_pearson

    for n in (1, 5, 20, 99, 400):
        for level in (0.9, 0.95, 0.99):
            k = np.arange(n + 1, dtype=np.float64)
            alpha = 1.0 - level
            low = np.where(k > 0, stats.beta.ppf(alpha / 2, k, n - k + 1), 0.0)
            high = np.where(k < n, stats.beta.ppf(1 - alpha / 2, k + 1, n - k), 1.0)
            got_low, got_high = clopper_pearson(k, n, level)
            assert np.array_equal(got_low.view(np.int64), low.view(np.int64))
            assert np.array_equal(got_high.view(np.int64), high.view(np.int64))


def test_the_power_skips_the_tail_only_where_it_cannot_change_the_decision():
    # evidence_power's shortcut (an FF twin beyond every FB twin is found at a level >= 1/(N+1)
    # without fitting the tail) against its definition, the share of run_p_value <= alpha, on
    # random twins with NaN draws, levels on both sides of 1/(N+1).
    from hcid.selection.calibration import evidence_power, run_p_value

    rng = np.random.default_rng(49)
    for _ in range(200):
        n = int(rng.integers(5, 100))
        fb = np.exp(rng.normal(-3, 1, n))
        fb[rng.random(n) < 0.05] = np.nan
        ff = np.exp(rng.normal(rng.normal(-2, 1), 0.5, 20))
        for alpha in (0.005, 0.01, 0.05, 0.1):
            slow = float(np.mean([run_p_value(w, fb)[0] <= alpha for w in ff]))
            assert evidence_power(ff, fb, alpha) == slow


def test_a_run_or_twin_without_the_statistic_is_no_evidence():
    # Source: SPEC 11's p counts FB twins at or above the run's value; a NaN value has no rank
    # (every comparison with it is false), so before this guard it lay "beyond every twin" and got
    # 1/(N+1) = 1/21 < 0.05, evidence, and an FF twin with NaN counted as found. Now: no p, and
    # not found. A group whose FF twins all lack the statistic has no power: UNCERTAIN, not NO
    # FEEDFORWARD SHOWN (NaN >= 0.8 is false).
    import math

    from hcid.pipeline.evidence import group_verdict
    from hcid.selection.calibration import evidence_power, run_p_value

    fb = np.linspace(0.1, 1.0, 20)
    p, n, how = run_p_value(float("nan"), fb)
    assert math.isnan(p) and (n, how) == (0, "")
    assert run_p_value(2.0, fb)[0] < 1 / 21  # beyond every twin, a value: the tail, as before
    assert evidence_power(np.array([2.0, float("nan"), 5.0, 0.2]), fb, 0.05) == 0.5
    rows = [{"p_value": 0.5, "power": float("nan")}] * 3
    assert group_verdict(rows, 0.05)["verdict"] == "UNCERTAIN"


def test_the_counts_power_is_the_chance_its_binomial_test_is_significant():
    # Slow reference: every one of the 2^n outcomes (run i found with its power or not), each
    # judged by binomial_summary itself (its p at most alpha: significant), against count_power's
    # Poisson binomial above the fewest runs found that the test calls significant.
    import itertools

    from hcid.selection.calibration import binomial_summary, count_power

    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 6, 9):
        powers = rng.uniform(0.05, 1.0, n)
        for alpha in (0.05, 0.01):
            slow = 0.0
            for found in itertools.product((False, True), repeat=n):
                chance = np.prod([q if f else 1.0 - q for q, f in zip(powers, found, strict=True)])
                p_values = np.where(found, alpha / 2, 0.5)
                if binomial_summary(p_values, alpha)[2] <= alpha:
                    slow += chance
            assert count_power(powers, alpha) == pytest.approx(slow, abs=1e-12)
    assert np.isnan(count_power(np.array([0.9, np.nan]), 0.05))


def test_a_group_verdict_reads_the_power_of_its_count():
    # Source: group_verdict's rule. Twelve runs found with power 0.6 each, 2 of them at p <= 0.05
    # (binomial p 0.12): the count is significant from 3 runs on (Binomial(12, 0.05) gives 3 or
    # more with chance 0.020, 2 or more 0.118), which 12 runs of power 0.6 reach with chance
    # 1 - P(0, 1 or 2 of them) = 0.9972: NO FEEDFORWARD SHOWN (the runs' median power, 0.6, had
    # said UNCERTAIN). Two runs of power 0.8: one of two is not significant (0.0975), both are
    # found with chance 0.64 < 0.8: UNCERTAIN (the median, 0.8, had said NO FEEDFORWARD SHOWN).
    from hcid.pipeline.evidence import group_verdict

    twelve = [{"p_value": 0.01, "power": 0.6}] * 2 + [{"p_value": 0.5, "power": 0.6}] * 10
    v = group_verdict(twelve, 0.05)
    assert v["group_power"] == pytest.approx(1 - 0.4**12 - 12 * 0.6 * 0.4**11 - 66 * 0.36 * 0.4**10)
    assert (v["verdict"], v["median_power"]) == ("NO FEEDFORWARD SHOWN", 0.6)
    two = group_verdict([{"p_value": 0.5, "power": 0.8}] * 2, 0.05)
    assert two["group_power"] == pytest.approx(0.64) and two["verdict"] == "UNCERTAIN"


def test_a_run_without_a_p_is_one_of_the_count_and_never_found():
    # Source: group_verdict's rule: binomial_summary counts a run whose p is NaN among the n (not
    # at p <= alpha), so the count's power gives it 0, not its twins' power. Two runs of power 0.85
    # and one without a p: 2 of 3 are significant (1 of 3 is not: 0.143), reached with 0.85^2 =
    # 0.7225 < 0.8: UNCERTAIN (with the third run's 0.85 it would read 0.94).
    from hcid.pipeline.evidence import group_verdict

    rows = [{"p_value": 0.5, "power": 0.85}] * 2 + [{"p_value": float("nan"), "power": 0.85}]
    v = group_verdict(rows, 0.05)
    assert v["group_power"] == pytest.approx(0.85**2) and v["verdict"] == "UNCERTAIN"
