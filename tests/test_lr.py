"""The feedforward path's likelihood ratio at the forcing lines (hcid.hcfit.lr, issue 47 item 5).

Records are tests/test_hcfit_lines.py's, built in the frequency domain from the loop's own
equations, so that a noise-free record is fitted exactly by its true model (cost 0)."""

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from hcid import hcfit
from hcid.hcfit.fit import fit_lines
from hcid.hcfit.lines import LinesProblem, line_data
from hcid.hcfit.lr import feedforward_lr
from tests.test_hcfit_lines import PLANT, TRUTH, _record

FEEDBACK = {p: v for p, v in TRUTH.items() if p not in ("Kpt", "TI", "tau_pt")}
#: A start away from the truth, as a group's medians are from one run's values.
START = {**TRUTH, "Kpe": 2.0, "TL": 0.15, "tau_pe": 0.2, "Kpt": 0.6, "TI": 0.3, "tau_pt": 0.1}


def test_without_feedforward_and_remnant_at_the_lines_the_ratio_is_zero():
    # Source: the feedback-only truth makes every residual 0 (no remnant at the lines), so the
    # feedback-only fit's cost is 0 and no model can do better: C_FB - C_FF = 0, and the slope in
    # Kpt that stands for it (2 r0 . d) is 0 with the residuals r0 (to the fit's tolerance: a
    # millionth of a unit, where the next test's feedforward gives above 1e3).
    record, _ = _record(values=FEEDBACK, remnant=1e-3, at_lines=False)
    assert feedforward_lr(line_data(record), PLANT, "input", START) == pytest.approx(0.0, abs=1e-5)


def test_with_feedforward_the_ratio_is_the_feedback_only_models_least_cost():
    # Source: the true model with feedforward fits exactly (C_FF = 0), so the ratio is the least
    # cost of the feedback-only model, which fit_lines' global search (differential evolution and
    # random starts) finds independently of the local fits from the start.
    record, _ = _record(remnant=1e-3, at_lines=False)
    data = line_data(record)
    reduced = fit_lines(record, PLANT, False, hcfit.FitSettings(), "input", data=data)
    assert reduced.cost > 1e3  # the feedforward path is far from negligible here
    assert feedforward_lr(data, PLANT, "input", START) == pytest.approx(reduced.cost, rel=1e-4)


def test_the_ratio_grows_with_the_feedforward_gain_under_a_remnant():
    # Source: the same remnant realization (seed) on loops of growing Kpt: the feedforward path's
    # share of U at the target lines grows, and with it what the feedback-only model cannot fit.
    ratios = []
    for kpt in (0.0, 0.2, 1.0):
        values = {**TRUTH, "Kpt": kpt} if kpt else FEEDBACK
        record, _ = _record(values=values, remnant=0.05, at_lines=True, seed=9)
        ratios.append(feedforward_lr(line_data(record), PLANT, "input", START))
    assert ratios[0] < ratios[1] < ratios[2]
    assert ratios[0] < 0.1 * ratios[1]


@pytest.mark.parametrize("feedforward", [False, True])
def test_the_one_call_jacobian_is_scipys_finite_difference(feedforward):
    # Slow reference: scipy's own forward differences (approx_derivative '2-point' with bounds),
    # one residual evaluation per column; the fast path evaluates every column in one call.
    record, _ = _record(remnant=0.05, at_lines=True, seed=3)
    problem = LinesProblem(line_data(record), PLANT, feedforward, "input")
    settings = hcfit.FitSettings()
    lower = np.array([settings.bound(n).lower for n in problem.names])
    upper = np.array([settings.bound(n).upper for n in problem.names])
    rng = np.random.default_rng(1)
    for _ in range(5):
        x = np.array([START[n] for n in problem.names]) * rng.uniform(0.8, 1.2, len(problem.names))
        x[-1] = upper[-1] if feedforward else x[-1]  # tau_pt at its bound: the step turns back
        fast = problem.jacobian(x, lower, upper)
        slow = approx_derivative(problem.residuals, x, method="2-point", bounds=(lower, upper))
        assert fast == pytest.approx(slow, rel=1e-6, abs=1e-6 * np.abs(slow).max())


def test_a_twins_start_is_as_far_from_its_truth_as_a_runs_from_its_own_fit():
    # Source: hcid.pipeline.line_statistics' rule: the deviations are the runs' determined fitted
    # feedback values minus the group model's (0 where a fit does not determine the parameter, and
    # for the feedforward path's, whose start is the group's for runs and twins alike), each
    # parameter's shrunk by sqrt(1 - mean(se^2) / mean(deviation^2)) over the runs that determine
    # it (0 where the fit error is the whole spread); twin k starts at the model minus deviation
    # (k - 1) mod n, the FB and the FF twin of a seed alike.
    from types import SimpleNamespace

    from hcid.pipeline.line_statistics import _offset, deviations

    model = {"Kpe": 2.0, "TL": 0.15, "Kpt": 0.8}
    names = ("Kpe", "TL", "Kpt")

    def fit(values, se, status):
        return SimpleNamespace(values=dict(zip(names, values, strict=True)), names=names, se=se,
                               status=dict(zip(names, status, strict=True)))  # fmt: skip

    ok = "determined"
    fits = [
        fit((2.5, 0.9, 0.7), (0.3, 0.1, 0.1), (ok, "correlated with Kpe", ok)),
        fit((1.75, 0.1, 0.8), (0.2, 0.05, 0.1), (ok, ok, ok)),
    ]
    # Kpe: deviations 0.5 and -0.25, mean square 0.15625, mean se^2 0.065: factor sqrt(0.584);
    # TL: one determined run, deviation -0.05 against se 0.05: the error is all its spread, 0.
    k = np.sqrt(1 - 0.065 / 0.15625)
    found = deviations(model, fits)
    assert found == [pytest.approx({"Kpe": 0.5 * k, "TL": 0.0, "Kpt": 0.0}),
                     pytest.approx({"Kpe": -0.25 * k, "TL": 0.0, "Kpt": 0.0})]  # fmt: skip
    # Every start a stable loop with an integrator (none is moved nearer the truth; next test).
    full = {**model, "tau_pe": 0.1, "w_nms": 10.1, "zeta_nms": 0.35}
    integrator = (np.array([1.0]), np.array([1.0, 0.0]))
    rest = {"TL": 0.15, "Kpt": 0.8, "tau_pe": 0.1, "w_nms": 10.1, "zeta_nms": 0.35}
    assert _offset(full, found, 1, *integrator) == pytest.approx({"Kpe": 2.0 - 0.5 * k, **rest})
    assert _offset(full, found, 2, *integrator) == pytest.approx({"Kpe": 2.0 + 0.25 * k, **rest})
    assert _offset(full, found, 3, *integrator) == _offset(full, found, 1, *integrator)  # the cycle
    assert _offset(full, [], 7, *integrator) == full  # no runs' deviations: the model itself


def test_a_twins_start_is_moved_towards_its_truth_until_its_loop_is_stable():
    # Source: line_statistics._offset's rule (a twin starts where a run could: a stable loop),
    # with the paper's plant 2.75 * 2 / (s (s + 2)) and p below, whose loop is stable for Kpe below
    # 1.7086 (bisection on loop_is_stable, whose own doctest checks Kpe 0.75 and 20 against it).
    # A deviation of -3 starts at Kpe 3.75, halved 2.25 (both unstable), halved again 1.5: stable.
    # Without the rule the start's cost is flat (1e6 a residual), the fit never moves, and the
    # likelihood ratio is 0 whatever the record (half of the CPHS fo twins, power 0.50).
    from hcid.hcfit.closed_loop import loop_is_stable
    from hcid.pipeline.line_statistics import _offset

    paper = (np.array([5.5]), np.array([1.0, 2.0, 0.0]))
    p = {"Kpe": 0.75, "TL": 0.4, "tau_pe": 0.24, "w_nms": 10.1, "zeta_nms": 0.35}
    assert loop_is_stable({**p, "Kpe": 1.70}, *paper) and not loop_is_stable({**p, "Kpe": 1.72}, *paper)
    assert _offset(p, [{"Kpe": -3.0}], 1, *paper) == pytest.approx({**p, "Kpe": 1.5})
    assert _offset(p, [{"Kpe": 0.5}], 1, *paper) == pytest.approx({**p, "Kpe": 0.25})  # stable: kept
    # Never stable within 8 halvings (-1e6 / 2^8 still starts at Kpe 3907): the truth itself.
    assert _offset(p, [{"Kpe": -1e6}], 1, *paper) == p
    # The fits start clipped into their bounds (lr._local_fit; TL's lower bound is 0): at Kpe 1.1
    # (the limit without lead is 1.2213, by bisection) TL -0.2 s is unstable and TL 0 stable, so a
    # start at TL -0.2 is the fits' start at 0, a stable one: kept, not halved (to TL 0.025).
    q = {**p, "Kpe": 1.1, "TL": 0.1}
    assert not loop_is_stable({**q, "TL": -0.2}, *paper) and loop_is_stable({**q, "TL": 0.0}, *paper)
    assert _offset(q, [{"TL": 0.3}], 1, *paper) == pytest.approx({**q, "TL": -0.2})


def test_from_an_unstable_start_the_ratio_is_0_and_a_twins_start_is_moved_to_a_stable_one():
    # Source: the lines' cost is flat (1e6 a residual) where the loop is unstable, so neither fit
    # moves from there: the ratio of a record with a strong feedforward (above 1e3, as in the test
    # of the feedback-only model's least cost) is 0 or below. line_statistics._offset halves a
    # deviation that starts there until the start is stable, and the ratio is the record's again.
    from hcid.pipeline.line_statistics import _offset

    record, _ = _record(remnant=1e-3, at_lines=False)
    data = line_data(record)
    num, den = np.array(PLANT.num[0][0], float), np.array(PLANT.den[0][0], float)
    kpe = next(k for k in (4.0, 8.0, 16.0, 32.0) if not hcfit.loop_is_stable({**START, "Kpe": k}, num, den))
    assert feedforward_lr(data, PLANT, "input", {**START, "Kpe": kpe}) <= 0.0
    moved = _offset(START, [{"Kpe": START["Kpe"] - kpe}], 1, num, den)
    assert hcfit.loop_is_stable(moved, num, den) and moved["Kpe"] < kpe
    assert feedforward_lr(data, PLANT, "input", moved) > 1e3


def test_the_slope_in_kpt_at_the_nested_model_is_exact():
    # Source: the cost in Kpt at the nested model is an exact quadratic (the residuals are linear
    # in Kpt), so its slope at 0 is (4 C(h) - C(2h) - 3 C(0)) / (2 h) from three evaluations of
    # LinesProblem.costs, a path independent of the residuals nested_slope uses.
    from hcid.hcfit.lr import _local_fit, nested_slope

    signs = set()
    for seed in range(6):
        record, _ = _record(values=FEEDBACK, remnant=0.05, at_lines=True, seed=seed)
        fb = LinesProblem(line_data(record), PLANT, False, "input")
        ff = LinesProblem(line_data(record), PLANT, True, "input")
        _, x_fb = _local_fit(fb, np.array([START[n] for n in fb.names]), hcfit.FitSettings())
        nested = {**START, **dict(zip(fb.names, x_fb, strict=True)), "Kpt": 0.0}  # the feedback-only optimum
        x = np.array([nested[n] for n in ff.names])
        h = 1e-3
        thetas = np.column_stack(
            [np.array([{**nested, "Kpt": k}[n] for n in ff.names]) for k in (0.0, h, 2 * h)]
        )
        c0, c1, c2 = ff.costs(thetas)
        expected = (4 * c1 - c2 - 3 * c0) / (2 * h)
        assert nested_slope(ff, x) == pytest.approx(expected, rel=1e-6)
        signs.add(expected > 0)
    assert signs == {True, False}  # both signs met: the slope is not a constant


def test_where_the_full_fit_stays_at_the_nested_model_the_statistic_is_minus_the_slope(monkeypatch):
    # Source: the module's rule. A full fit that ends at the nested model (cost C_FB: Kpt stays on
    # its bound of 0, as 1.1% of the null study's runs did, 2026-11-28) gives -max(slope, 0) at
    # the nested model instead of a ratio of exactly 0; distinct records give distinct values.
    from hcid.hcfit import lr

    real = lr._local_fit
    nested_cost = {}

    def stuck(problem, start, settings):  # the full fit does no better than the nested model
        cost, x = real(problem, start, settings)
        return (nested_cost["C_FB"], x) if "Kpt" in problem.names else (cost, x)

    monkeypatch.setattr(lr, "_local_fit", stuck)
    seen = []
    for seed in range(6):
        record, _ = _record(values=FEEDBACK, remnant=0.05, at_lines=True, seed=seed)
        data = line_data(record)
        fb = LinesProblem(data, PLANT, False, "input")
        ff = LinesProblem(data, PLANT, True, "input")
        nested_cost["C_FB"], x_fb = real(fb, np.array([START[n] for n in fb.names]), hcfit.FitSettings())
        value = feedforward_lr(data, PLANT, "input", START)
        nested = {
            **dict(zip(fb.names, x_fb, strict=True)),
            "Kpt": 0.0,
            "TI": START["TI"],
            "tau_pt": START["tau_pt"],
        }
        slope = lr.nested_slope(ff, np.array([nested[n] for n in ff.names]))
        assert value == -max(slope, 0.0)
        seen.append(value)
    below = [v for v in seen if v < 0]  # (a slope below 0 would have moved a real fit off Kpt = 0)
    assert below and len(set(below)) == len(below)
