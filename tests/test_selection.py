"""Model selection over W: exact breakpoints against brute force (SPEC section 4)."""

import numpy as np
import pytest

from hcid.selection import criteria, over_w

from . import naive


def _random_frontier(rng, n=60):
    d = rng.integers(1, 22, n)
    # log V decreasing in d on average, with scatter, like a real frontier
    v = np.exp(-0.3 * d + rng.normal(0, 0.4, n) - 9)
    v[rng.random(n) < 0.1] = np.inf  # unstable rows are never selected
    orders = rng.integers(0, 8, (n, 5))
    return d, v, orders


@pytest.mark.parametrize("seed", range(20))
def test_selection_equals_brute_force(seed):
    # Brute force: argmin over every row of log V + W d with the SPEC tie rule.
    rng = np.random.default_rng(seed)
    d, v, orders = _random_frontier(rng)
    w = np.geomspace(1e-4, 10, 400)
    got = over_w.select_at(d, v, orders, w)
    expected = [naive.select_brute_force(d, v, orders, x) for x in w]
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("seed", range(4))
def test_breakpoints_agree_with_fine_grid(seed):
    # Every change of the brute-force selection on a fine grid is bracketed by a
    # breakpoint, and every breakpoint by a change.
    rng = np.random.default_rng(100 + seed)
    d, v, orders = _random_frontier(rng)
    seg = over_w.breakpoints(d, v, orders)
    w = np.geomspace(1e-5, 50, 5000)
    brute = np.array([naive.select_brute_force(d, v, orders, x) for x in w])
    changes = np.flatnonzero(brute[1:] != brute[:-1])
    inner = seg.w_from[(seg.w_from > w[0]) & (seg.w_from < w[-1])]
    assert len(changes) == len(inner)
    for c, b in zip(changes, inner, strict=True):
        assert w[c] < b <= w[c + 1]


def test_ties_go_to_smaller_d_then_orders():
    # SPEC 4: equal MSC -> smaller d, then smaller (na, nb_ft, nb_e, nk_ft, nk_e).
    d = np.array([3, 4, 3])
    v = np.exp(np.array([-1.0, -1.0 - 0.5, -1.0]))  # row 1 ties row 0 at W = 0.5
    orders = np.array([[2, 0, 0, 0, 0], [1, 1, 0, 3, 0], [1, 0, 1, 0, 2]])
    assert naive.select_brute_force(d, v, orders, 0.5) == 2
    assert over_w.select_at(d, v, orders, np.array([0.5]))[0] == 2
    assert over_w.select_at(d, v, orders, np.array([0.49]))[0] == 1


def test_aic_bic_penalties():
    # SPEC 4: Nf = 960 gives W_AIC = 2.08e-3 and W_BIC = 7.15e-3.
    assert criteria.w_aic(960) == pytest.approx(2.083e-3, rel=1e-3)
    assert criteria.w_bic(960) == pytest.approx(7.153e-3, rel=1e-3)


def test_false_positive_threshold_is_last_positive_interval_end():
    # Two realizations: nb_ft > 0 selected below W = 0.02 and below W = 0.05.
    seg_a = over_w.SelectionPath(np.array([0, 1]), np.array([0.0, 0.02]), np.array([0.02, np.inf]))
    seg_b = over_w.SelectionPath(
        np.array([0, 1, 2]), np.array([0.0, 0.01, 0.05]), np.array([0.01, 0.05, np.inf])
    )
    nb = np.array([3, 2, 0])
    nb_a = np.array([3, 0])
    assert over_w.false_positive_threshold([seg_a, seg_b], [nb_a, nb]) == 0.05


def test_false_negative_threshold_is_first_mean_below_two():
    # Means of nb_ft: (4+3)/2 below 0.1, (1+3)/2 = 2 from 0.1, (1+0)/2 from 0.3.
    seg_a = over_w.SelectionPath(np.array([0, 1]), np.array([0.0, 0.1]), np.array([0.1, np.inf]))
    seg_b = over_w.SelectionPath(np.array([0, 1]), np.array([0.0, 0.3]), np.array([0.3, np.inf]))
    nb_a, nb_b = np.array([4, 1]), np.array([3, 0])
    assert over_w.false_negative_threshold([seg_a, seg_b], [nb_a, nb_b]) == 0.3


# --------------------------------------------------------------------------- sampling (SPEC 9)


def _realization(w_from, nb):
    """One realization selecting rows 0, 1, ... on [w_from[i], w_from[i+1]), with those nb_ft."""
    w_from = np.asarray(w_from, dtype=float)
    return over_w.SelectionPath(np.arange(w_from.size), w_from, np.append(w_from[1:], np.inf)), np.asarray(nb)


def test_false_positive_extent_is_the_end_of_the_last_positive_interval():
    # Positive on [0, 0.01) and again on [0.02, 0.05): L = 0.05; never positive: L = 0; W_FP = max L.
    a = _realization([0.0, 0.01, 0.02, 0.05], [2, 0, 1, 0])
    b = _realization([0.0], [0])
    assert over_w.false_positive_extent(*a) == 0.05
    assert over_w.false_positive_extent(*b) == 0.0
    assert over_w.false_positive_threshold([a[0], b[0]], [a[1], b[1]]) == 0.05


def test_threshold_exceedance_is_one_minus_the_chance_that_no_realization_reaches_w():
    # 200 realizations, 2 with L >= 0.037: q = 0.01, so a study of 50 has W_FP >= 0.037 with
    # probability 1 - 0.99^50 = 0.39499 (exact formula); none with L >= 0.1: probability 0.
    extents = np.concatenate([np.full(198, 0.008), [0.04, 0.05]])
    assert over_w.threshold_exceedance(extents, 0.037, 50) == pytest.approx(1 - 0.99**50, rel=1e-12)
    assert over_w.threshold_exceedance(extents, 0.1, 50) == 0.0
    # at or above: L equal to w counts (W_FP is the supremum of the false-positive W)
    assert over_w.threshold_exceedance(extents, 0.05, 1) == pytest.approx(1 / 200)


def test_false_negative_bootstrap_is_degenerate_for_identical_realizations_and_seeded():
    # Every realization drops from nb_ft 2 to 0 at W = 0.3: every resample has W_FN = 0.3.
    same = [_realization([0.0, 0.3], [2, 0]) for _ in range(10)]
    boot = over_w.false_negative_bootstrap([s for s, _ in same], [nb for _, nb in same])
    assert (boot.low, boot.high) == (0.3, 0.3)
    assert boot.share_at_or_above(0.26) == 1.0 and boot.share_at_or_above(0.31) == 0.0
    # Half drop at 0.1, half at 0.5 (nb_ft 3 -> 0): the mean drops below 2 where the resample's
    # share of early droppers exceeds 1/3; the interval lies between the two and is reproducible.
    mixed = [_realization([0.0, 0.1], [3, 0]) for _ in range(20)] + [
        _realization([0.0, 0.5], [3, 0]) for _ in range(20)
    ]
    segs, nbs = [s for s, _ in mixed], [nb for _, nb in mixed]
    one = over_w.false_negative_bootstrap(segs, nbs, seed=3)
    two = over_w.false_negative_bootstrap(segs, nbs, seed=3)
    assert set(np.unique(one.values)) <= {0.1, 0.5}
    np.testing.assert_array_equal(one.values, two.values)
    assert over_w.false_negative_threshold(segs, nbs) == 0.1  # mean 1.5 from W = 0.1 on


@pytest.mark.parametrize("n", [1, 7, 40, 51])
def test_false_negative_bootstrap_draws_the_resamples_one_after_the_other(n):
    # Source: the bootstrap as first written (a bincount of n draws per resample, resample after
    # resample, from one seeded Generator); drawing all resamples at once must give the same
    # resamples, hence the same W_FN values, not merely the same distribution.
    rng = np.random.default_rng(11)
    mixed = [_realization([0.0, float(w)], [3, 0]) for w in rng.uniform(0.05, 0.6, n)]
    segs, nbs = [s for s, _ in mixed], [nb for _, nb in mixed]
    at, values = over_w._nb_ft_at_breakpoints(segs, nbs)
    draw = np.random.default_rng(4)
    weights = np.stack([np.bincount(draw.integers(0, n, n), minlength=n) for _ in range(300)])
    expected = over_w._first_below(at, weights @ values / n, 2.0)
    got = over_w.false_negative_bootstrap(segs, nbs, resamples=300, seed=4)
    np.testing.assert_array_equal(got.values, expected)
