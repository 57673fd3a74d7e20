"""p-values below 1/(N+1) from a generalized Pareto tail (SPEC 13), against exact formulas, a
brute-force posterior, scipy's GPD, and simulated null runs whose truth is known."""

import numpy as np
import pytest
from scipy import stats

from hcid.selection.calibration import evidence_p_value
from hcid.selection.tail import (
    GPD_TAIL,
    MONTE_CARLO,
    SHAPE_MAX,
    ad_p_value,
    anderson_darling_gpd,
    fit_gpd,
    gpd_sf,
    predictive_sf,
    tail_p_value,
)

#: Null distributions of SPEC 13's calibration: light, exponential (a GPD above any threshold),
#: heavy (GPD shape 1/3), bounded (shape -1/5) and log-normal (shape 0, reached slowly).
NULLS = {
    "normal": lambda rng, size: rng.standard_normal(size),
    "exponential": lambda rng, size: rng.exponential(size=size),
    "t3": lambda rng, size: rng.standard_t(3, size=size),
    "beta(2,5)": lambda rng, size: rng.beta(2.0, 5.0, size=size),
    "lognormal": lambda rng, size: np.exp(rng.standard_normal(size)),
}
RUNS = 2000  # per null and N; SPEC 13 asks for at least 1,000
SEED = 12345


def _p_values(draws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tail p of each row's first value against the rest, and whether the tail made it."""
    results = [tail_p_value(row[0], row[1:]) for row in draws]
    return np.array([r.p for r in results]), np.array([r.method == GPD_TAIL for r in results])


# --------------------------------------------------------------------------- exact references


@pytest.mark.parametrize("n", [10, 20, 99])
def test_monte_carlo_p_where_ten_or_more_reach_the_value(n):
    # Source: SPEC 11 and 13, (1 + k) / (1 + N) for k >= 10, as evidence_p_value gives it.
    null = np.random.default_rng(n).standard_normal(n)
    for value in np.sort(null)[::-1][9:]:  # the 10th largest and below: k >= 10
        k = int(np.count_nonzero(null >= value))
        r = tail_p_value(value, null)
        assert (r.method, r.p, r.n_null, r.n_tail) == (MONTE_CARLO, (1 + k) / (1 + n), n, 0)
        assert r.p == evidence_p_value(value, null)
        assert np.isnan([r.shape, r.scale, r.threshold, r.ad_p]).all()


@pytest.mark.parametrize("shape", [-0.3, 0.0, 0.3])
def test_fit_recovers_the_parameters_of_a_large_gpd_sample(shape):
    # Source: the MLE's standard errors, (1 + xi) / sqrt(n) for the shape and about
    # sigma sqrt(2 (1 + xi) / n) relative for the scale (Smith 1984): at n = 20,000 about 0.009
    # and 1.2%; the tolerances are five of them.
    y = stats.genpareto.rvs(shape, scale=2.0, size=20_000, random_state=np.random.default_rng(7))
    fitted_shape, fitted_scale = fit_gpd(y)
    assert fitted_shape == pytest.approx(shape, abs=0.05)
    assert fitted_scale == pytest.approx(2.0, rel=0.06)


def test_fit_is_the_maximum_of_the_likelihood_as_scipy_finds_it():
    # Source: scipy.stats.genpareto.fit(y, floc=0), a generic optimiser of the same likelihood;
    # the grid search must reach at least its log-likelihood wherever scipy's shape is in the
    # region the fit searches (>= -1: below, the GPD likelihood is unbounded).
    rng = np.random.default_rng(3)
    compared = 0
    for _ in range(40):
        y = stats.genpareto.rvs(
            rng.uniform(-0.5, 0.8), scale=1.0, size=int(rng.integers(10, 40)), random_state=rng
        )
        shape_s, _, scale_s = stats.genpareto.fit(y, floc=0)
        if shape_s < -1:
            continue
        compared += 1
        shape, scale = fit_gpd(y)
        ours = stats.genpareto.logpdf(y, shape, 0, scale).sum()
        assert ours >= stats.genpareto.logpdf(y, shape_s, 0, scale_s).sum() - 1e-6
    assert compared >= 30


def test_gpd_sf_is_scipys():
    # Source: scipy.stats.genpareto.sf, shape c = xi.
    y = np.linspace(0.0, 6.0, 25)
    for shape in (-0.5, -0.1, 0.0, 0.2, 1.5):
        np.testing.assert_allclose(gpd_sf(y, shape, 1.5), stats.genpareto.sf(y, shape, 0, 1.5), rtol=1e-12)


def test_anderson_darling_statistic_is_scipys():
    # Source: scipy.stats.goodness_of_fit's Anderson-Darling statistic with known parameters.
    rng = np.random.default_rng(5)
    for shape in (-0.3, 0.0, 0.4):
        y = stats.genpareto.rvs(shape, scale=1.0, size=15, random_state=rng)
        ref = stats.goodness_of_fit(
            stats.genpareto,
            y,
            known_params={"c": shape, "loc": 0, "scale": 1.2},
            statistic="ad",
            n_mc_samples=1,
        ).statistic
        assert anderson_darling_gpd(y, shape, 1.2)[0] == pytest.approx(ref, rel=1e-10)


def test_ad_p_value_reads_choulakian_and_stephens_table():
    # Source: Choulakian and Stephens (2001), Table 2 (k = -xi): at xi = 0 the 25%, 5% and 1%
    # points are 0.569, 0.974, 1.409; at xi = -0.9 the 0.1% point is 1.559; at xi = 0.5 the 50%
    # point is 0.496. Shapes beyond the table use its last row.
    assert ad_p_value(0.569, 0.0) == pytest.approx(0.25, rel=1e-12)
    assert ad_p_value(0.974, 0.0) == pytest.approx(0.05, rel=1e-12)
    assert ad_p_value(1.409, 0.0) == pytest.approx(0.01, rel=1e-12)
    assert ad_p_value(1.558, -0.95) == pytest.approx(0.001, rel=0.01)
    assert ad_p_value(0.497, 2.0) == pytest.approx(0.5, rel=0.01)
    assert ad_p_value(0.1, 0.0) == 0.5 and ad_p_value(9.0, 0.0) == 0.001


def _brute_force_predictive(y: np.ndarray, d: float) -> float:
    """P(Y > d | y) on a dense grid over (shape, log scale): the GPD likelihood times the prior
    (flat in the shape below SHAPE_MAX, 1 / scale), integrated with no closed form."""
    shape = np.linspace(-6.0, SHAPE_MAX, 1200)[:, None, None]
    log_scale = np.log(y.mean()) + np.linspace(-6.0, 6.0, 900)[None, :, None]
    scale = np.exp(log_scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        arg = 1.0 + shape * y / scale
        safe = np.where(shape == 0.0, 1.0, shape)
        log_pdf = np.where(arg > 0, -log_scale - (1.0 / safe + 1.0) * np.log(arg), -np.inf)
        log_lik = np.where(shape == 0.0, -log_scale - y / scale, log_pdf).sum(axis=-1)
        arg_d = 1.0 + shape[..., 0] * d / scale[..., 0]
        tail = np.where(arg_d > 0, arg_d ** (-1.0 / safe[..., 0]), 0.0)
    weight = np.exp(log_lik - log_lik[np.isfinite(log_lik)].max())
    return float(np.sum(weight * tail) / np.sum(weight))


@pytest.mark.parametrize(("shape", "n", "d"), [(0.0, 10, 3.0), (-0.4, 15, 1.5), (0.3, 12, 8.0)])
def test_predictive_is_the_brute_force_posterior_average(shape, n, d):
    # Source: the definition of the posterior predictive, integrated on a 1200 x 900 grid (its
    # own error is about 0.5% here, so the tolerance is 1%); the module integrates the shape in
    # closed form and theta = shape / scale on an adaptive grid.
    y = stats.genpareto.rvs(shape, scale=1.0, size=n, random_state=np.random.default_rng(0))
    assert predictive_sf(y, d) == pytest.approx(_brute_force_predictive(y, d), rel=0.01)


def test_exponential_tail_just_beyond_every_null_value():
    # Source: an exponential null's exact tail exp(-x). x = log(200) (P = 0.005) beyond all
    # N = 100 null values: over the nulls for which it is, the median of p / 0.005 lies within a
    # factor 2 (the predictive widens it further out: it carries the fit's uncertainty).
    rng = np.random.default_rng(11)
    x = np.log(200.0)
    nulls = [null for null in rng.exponential(size=(250, 100)) if null.max() < x]
    ratios = np.array([tail_p_value(x, null).p for null in nulls]) / 0.005
    assert len(nulls) > 100
    assert 0.5 <= np.median(ratios) <= 2.0


def test_bounded_null_beyond_the_fitted_end_is_never_zero():
    # Source: a uniform null has GPD shape -1 (its tail ends at 1). Beyond every null value and
    # beyond the maximum-likelihood fit's end, p stays positive and below 1 / (N + 1), and it
    # falls as the value moves out: the predictive's support reaches every value.
    null = np.random.default_rng(2).uniform(size=99)
    r = tail_p_value(1.02, null)
    assert r.method == GPD_TAIL and r.shape < 0
    assert r.threshold + r.scale / -r.shape < 1.02  # the fitted tail ends below the value
    ps = [tail_p_value(v, null).p for v in (1.02, 1.1, 1.5, 3.0, 1e3)]
    assert all(0 < p < 1 / 100 for p in ps) and np.all(np.diff(ps) < 0)


# --------------------------------------------------------------------------- calibration (SPEC 13)


@pytest.mark.parametrize("n", [20, 50, 99])
@pytest.mark.parametrize("family", list(NULLS))
def test_p_values_are_uniform_under_the_null(family, n):
    # Source: SPEC 13. Each run's value and its N null values come from the same distribution,
    # so P(p <= a) = a: P(p <= 0.01) and P(p <= 0.05) must lie in their binomial 99% bands, and
    # a KS test of uniformity must not reject at 1%. The Monte Carlo p is discrete (steps of
    # 1 / (N + 1)) and a KS test rejects any discrete p given runs enough; spread over its step
    # (p - U / (N + 1)), an exact Monte Carlo p is exactly uniform (a randomized p-value), so the
    # KS test judges the tail's p-values and the hand-over between the two.
    rng = np.random.default_rng(SEED)
    p, tail = _p_values(NULLS[family](rng, (RUNS, n + 1)))
    spread = np.where(tail, p, p - rng.uniform(size=RUNS) / (n + 1))
    assert stats.kstest(spread, "uniform").pvalue > 0.01
    for level in (0.01, 0.05):
        low, high = stats.binom.ppf([0.005, 0.995], RUNS, level) / RUNS
        assert low <= np.mean(p <= level) <= high, (level, np.mean(p <= level))
    assert np.all((p > 0) & (p <= 1))


# --------------------------------------------------------------------------- power


def _shifted(n: int, shift: float, runs: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(SEED)
    return rng.standard_normal(runs) + shift, rng.standard_normal((runs, n))


def test_twenty_twins_reach_below_their_monte_carlo_floor():
    # Source: the Monte Carlo p of N = 20 is at least 1 / 21, so it never rejects at 0.01; the
    # tail's p does, for a run 2.5 null standard deviations up, far more often than the level.
    values, nulls = _shifted(20, 2.5)
    tail = np.array([tail_p_value(v, null).p for v, null in zip(values, nulls, strict=True)])
    monte_carlo = np.array([evidence_p_value(v, null) for v, null in zip(values, nulls, strict=True)])
    assert np.mean(monte_carlo <= 0.01) == 0.0
    assert np.mean(tail <= 0.01) >= 0.1


@pytest.mark.xfail(
    strict=True,
    reason="measured: at 0.01, a run 2.5 sd up is rejected in 0.27 of runs by the tail with N = 20 "
    "and 0.50 by the Monte Carlo p with N = 99; 20 twins cannot match 99 without giving up calibration",
)
def test_twenty_twins_with_the_tail_reject_as_often_as_ninety_nine_without():
    values, nulls20 = _shifted(20, 2.5)
    nulls99 = np.random.default_rng(SEED + 1).standard_normal((values.size, 99))
    tail = np.array([tail_p_value(v, null).p for v, null in zip(values, nulls20, strict=True)])
    monte_carlo = np.array([evidence_p_value(v, null) for v, null in zip(values, nulls99, strict=True)])
    assert np.mean(tail <= 0.01) >= np.mean(monte_carlo <= 0.01)


# --------------------------------------------------------------------------- fallbacks


def test_clipped_statistic_keeps_the_monte_carlo_p():
    # A statistic clipped at the top of its range: 8 null runs at the clip, the run there too.
    null = np.r_[np.random.default_rng(1).uniform(0.0, 0.9, size=91), np.full(8, 1.0)]
    r = tail_p_value(1.0, null)
    assert (r.method, r.p) == (MONTE_CARLO, 9 / 100)


@pytest.mark.parametrize(
    ("value", "null", "expected"),
    [
        (0.5, np.full(50, 0.3), 1 / 51),  # all equal
        (4.5, np.repeat(np.arange(5.0), 10), 1 / 51),  # five distinct values
        (2.0, np.arange(10.0) / 10, 1 / 11),  # N = 10: no tail of 10 below a threshold
        (9.0, np.arange(5.0), 1 / 6),  # N = 5
        (1e9 + 1.0, 1e9 + np.random.default_rng(0).standard_normal(99) * 1e-6, 1 / 100),  # spread lost
    ],
)
def test_degenerate_nulls_keep_the_monte_carlo_p(value, null, expected):
    r = tail_p_value(value, null)
    assert (r.method, r.p) == (MONTE_CARLO, expected)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"value": np.nan, "null": np.ones(20)}, "value"),
        ({"value": np.array([1.0, 2.0]), "null": np.ones(20)}, "value"),
        ({"value": 1.0, "null": np.r_[np.ones(19), np.nan]}, "null"),
        ({"value": 1.0, "null": np.r_[np.ones(19), np.inf]}, "null"),
        ({"value": 1.0, "null": np.ones((4, 5))}, "null"),
        ({"value": 1.0, "null": np.array([])}, "null"),
        ({"value": 1.0, "null": np.ones(20), "min_exceed": 0}, "min_exceed"),
        ({"value": 1.0, "null": np.ones(20), "min_tail": 2}, "min_tail"),
        ({"value": 1.0, "null": np.ones(20), "tail_share": 0.0}, "tail_share"),
        ({"value": 1.0, "null": np.ones(20), "ad_level": 1.5}, "ad_level"),
    ],
)
def test_bad_input_is_refused_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}: "):
        tail_p_value(**kwargs)


def test_p_is_never_nan_or_zero():
    rng = np.random.default_rng(4)
    cases = [
        (1e300, rng.standard_normal(99)),  # astronomically far
        (50.0, rng.standard_t(1, size=99)),  # Cauchy: shape 1, beyond the prior's
        (0.0, np.r_[-np.ones(95), np.zeros(4)]),
        (1.0, np.r_[rng.uniform(size=90), np.full(9, 1.0)]),
        (3.0, rng.beta(0.5, 0.5, size=40)),
    ]
    for value, null in cases:
        p = tail_p_value(value, null).p
        assert np.isfinite(p) and 0 < p <= 1
