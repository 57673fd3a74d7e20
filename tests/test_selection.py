"""Model selection over W: exact breakpoints against brute force (SPEC section 4)."""

import numpy as np
import pytest

from hcid import criteria, selection


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
    got = selection.select_at(d, v, orders, w)
    expected = [selection.select_brute_force(d, v, orders, x) for x in w]
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("seed", range(4))
def test_breakpoints_agree_with_fine_grid(seed):
    # Every change of the brute-force selection on a fine grid is bracketed by a
    # breakpoint, and every breakpoint by a change.
    rng = np.random.default_rng(100 + seed)
    d, v, orders = _random_frontier(rng)
    seg = selection.breakpoints(d, v, orders)
    w = np.geomspace(1e-5, 50, 5000)
    brute = np.array([selection.select_brute_force(d, v, orders, x) for x in w])
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
    assert selection.select_brute_force(d, v, orders, 0.5) == 2
    assert selection.select_at(d, v, orders, np.array([0.5]))[0] == 2
    assert selection.select_at(d, v, orders, np.array([0.49]))[0] == 1


def test_aic_bic_penalties():
    # SPEC 4: Nf = 960 gives W_AIC = 2.08e-3 and W_BIC = 7.15e-3.
    assert criteria.w_aic(960) == pytest.approx(2.083e-3, rel=1e-3)
    assert criteria.w_bic(960) == pytest.approx(7.153e-3, rel=1e-3)


def test_false_positive_threshold_is_last_positive_interval_end():
    # Two realizations: nb_ft > 0 selected below W = 0.02 and below W = 0.05.
    seg_a = selection.Segments(np.array([0, 1]), np.array([0.0, 0.02]), np.array([0.02, np.inf]))
    seg_b = selection.Segments(
        np.array([0, 1, 2]), np.array([0.0, 0.01, 0.05]), np.array([0.01, 0.05, np.inf])
    )
    nb = np.array([3, 2, 0])
    nb_a = np.array([3, 0])
    assert selection.false_positive_threshold([seg_a, seg_b], [nb_a, nb]) == 0.05


def test_false_negative_threshold_is_first_mean_below_two():
    # Means of nb_ft: (4+3)/2 below 0.1, (1+3)/2 = 2 from 0.1, (1+0)/2 from 0.3.
    seg_a = selection.Segments(np.array([0, 1]), np.array([0.0, 0.1]), np.array([0.1, np.inf]))
    seg_b = selection.Segments(np.array([0, 1]), np.array([0.0, 0.3]), np.array([0.3, np.inf]))
    nb_a, nb_b = np.array([4, 1]), np.array([3, 0])
    assert selection.false_negative_threshold([seg_a, seg_b], [nb_a, nb_b]) == 0.3
