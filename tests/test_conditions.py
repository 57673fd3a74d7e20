"""hcid.analysis.conditions: a whole experiment's trials by kind and combined per person (SPEC 12).

The reference is exact: noise-free trials built in the frequency domain from known paths He and
Ht and a known plant, whose closed-loop responses the combination must invert to the last bits.
"""

import math

import numpy as np
import pytest

from hcid.analysis import conditions
from hcid.analysis.conditions import Kind

N, RATE = 400, 10.0  # 40 s at 10 Hz: bin k is k / 40 Hz
EVEN, ODD = np.array([4, 10, 22, 34]), np.array([6, 14, 26, 38])  # two disjoint line sets


def _omega(bins):
    return 2 * np.pi * np.asarray(bins) * RATE / N


def yc_integrator(omega):
    return 1.0 / (1j * np.asarray(omega))


def he_true(omega):
    s = 1j * np.asarray(omega)
    return 2.0 * (0.3 * s + 1) * np.exp(-0.2 * s)


def ht_true(omega):
    s = 1j * np.asarray(omega)
    return 0.8 * s / (0.2 * s + 1) ** 2 * np.exp(0.1 * s)


def _trial(target_bins, dist_bins, disturbance_at="input", phase=0.0, sign=1.0):
    """A noise-free trial: the loop's exact response at each line, as time signals (irfft)."""
    spectra = {k: np.zeros(N // 2 + 1, complex) for k in ("ft", "fd", "u", "e")}
    for bins, name in ((target_bins, "ft"), (dist_bins, "fd")):
        for i, b in enumerate(bins):
            spectra[name][b] = sign * N / (b) * np.exp(1j * (phase + 0.7 * i))
    omega = _omega(np.arange(N // 2 + 1))
    omega[0] = 1.0  # DC holds nothing
    yc, he, ht = yc_integrator(omega), he_true(omega), ht_true(omega)
    ft, fd = spectra["ft"], spectra["fd"]
    if disturbance_at == "input":  # theta = Yc (u + fd), u = Ht ft + He e, e = ft - theta
        u = ((ht + he) * ft - he * yc * fd) / (1 + he * yc)
        theta = yc * (u + fd)
    else:  # theta = Yc u + fd
        u = ((ht + he) * ft - he * fd) / (1 + he * yc)
        theta = yc * u + fd
    spectra["u"], spectra["e"] = u, ft - theta
    return {k: np.fft.irfft(x, N) for k, x in spectra.items()}


def test_the_kind_of_a_trial_comes_from_its_data():
    # SPEC 12: an input is absent when its power at every line is below 1e-6 of the other's.
    two = conditions.trial_lines(_trial(EVEN, ODD), RATE, N)
    assert two.kind is Kind.TWO_INPUT and two.target.tolist() == EVEN.tolist()
    assert two.disturbance.tolist() == ODD.tolist() and two.problem is None
    dist = conditions.trial_lines(_trial([], np.sort(np.r_[EVEN, ODD])), RATE, N)
    assert dist.kind is Kind.DISTURBANCE_ONLY and dist.target.size == 0 and dist.disturbance.size == 8
    target = conditions.trial_lines(_trial(np.sort(np.r_[EVEN, ODD]), []), RATE, N)
    assert target.kind is Kind.TARGET_ONLY and target.disturbance.size == 0
    weak = _trial(EVEN, ODD)
    weak["fd"] = weak["fd"] * 1e-4  # power 1e-8 of the target's: absent
    assert conditions.trial_lines(weak, RATE, N).kind is Kind.TARGET_ONLY
    weak["fd"] = weak["fd"] * 100  # power 1e-4 of the target's: there
    assert conditions.trial_lines(weak, RATE, N).kind is Kind.TWO_INPUT
    none = {k: np.zeros(N) for k in ("ft", "fd", "e", "u")}
    assert conditions.trial_lines(none, RATE, N).kind is None


@pytest.mark.parametrize("disturbance_at", ["input", "output"])
def test_every_source_recovers_both_paths_exactly_from_noise_free_trials(disturbance_at):
    # A swapped-line pair (two-input), a disturbance-only and a target-only trial on all lines:
    # He = -H_UD / (Yc (1 + H_UD)) (input) or -H_UD / (1 + H_UD Yc) (output), Ht = H_UR (1 + He Yc)
    # - He (SPEC 12) must give He and Ht back to rounding at every line, from either source.
    every = np.sort(np.r_[EVEN, ODD])
    trials = [
        conditions.trial_lines(_trial(EVEN, ODD, disturbance_at), RATE, N),
        conditions.trial_lines(_trial(ODD, EVEN, disturbance_at, phase=1.0, sign=-1.0), RATE, N),
        conditions.trial_lines(_trial([], every, disturbance_at, phase=0.3), RATE, N),
        conditions.trial_lines(_trial(every, [], disturbance_at, phase=2.0), RATE, N),
    ]
    omega = _omega(every)
    for source in conditions.SOURCES:
        p = conditions.combine(conditions.of_kinds(trials, source), yc_integrator, disturbance_at, every)
        np.testing.assert_allclose(p.omega, omega)
        np.testing.assert_allclose(p.he, he_true(omega), rtol=1e-9)
        np.testing.assert_allclose(p.ht, ht_true(omega), rtol=1e-9)
        np.testing.assert_allclose(p.inversion, ht_true(omega) * yc_integrator(omega), rtol=1e-9)
        assert p.he_measured.all()


def test_he_is_interpolated_only_where_no_trial_measured_a_disturbance_line():
    p = conditions.combine([conditions.trial_lines(_trial(EVEN, ODD), RATE, N)], yc_integrator, "input")
    assert p.he_measured.tolist() == [b in ODD for b in np.sort(np.r_[EVEN, ODD])]
    measured = p.he_measured
    np.testing.assert_allclose(p.he[measured], he_true(p.omega[measured]), rtol=1e-9)
    # Ht where a target measured the line; at a disturbance line of this one trial it is unknown.
    assert np.all(np.isnan(p.ht[measured])) and np.all(np.isfinite(p.ht[~measured]))


def test_superposition_of_identical_estimates_has_ratio_one_and_no_test():
    every = np.sort(np.r_[EVEN, ODD])
    trials = [conditions.trial_lines(_trial(every, [], phase=f), RATE, N) for f in (0.0, 1.0)]
    trials += [conditions.trial_lines(_trial([], every, phase=f), RATE, N) for f in (0.0, 1.0)]
    p = conditions.combine(trials, yc_integrator, "input")
    found = conditions.superposition([p, p, p], [p, p, p])
    pooled = [c for c in found if math.isnan(c.omega)]
    assert {c.response for c in pooled} == {"U/R", "U/D"}
    for c in found:
        assert c.ratio == pytest.approx(1.0) and c.phase == pytest.approx(0.0, abs=1e-9)
        assert math.isnan(c.p_magnitude)  # every difference 0: Wilcoxon has nothing to rank


def test_superposition_p_is_scipys_wilcoxon_on_the_log_magnitude_ratios():
    from scipy import stats

    every = np.sort(np.r_[EVEN, ODD])
    base = conditions.combine(
        [conditions.trial_lines(_trial(every, [], phase=0.1), RATE, N)]
        + [conditions.trial_lines(_trial([], every, phase=0.2), RATE, N)],
        yc_integrator,
        "input",
    )
    rng = np.random.default_rng(3)
    scaled = [
        conditions.PersonLines(
            base.omega,
            base.h_ur * g,
            base.h_ud * g,
            base.he,
            base.ht,
            base.yc,
            base.he_measured,
            base.inversion_runs,
            base.n_target,
            base.n_disturbance,
        )
        for g in np.exp(rng.normal(0.1, 0.2, size=(4, every.size)))
    ]
    found = conditions.superposition(scaled, [base] * 4)
    pooled = next(c for c in found if c.response == "U/R" and math.isnan(c.omega))
    logs = np.concatenate([np.log(np.abs(s.h_ur / base.h_ur)) for s in scaled])
    assert pooled.pairs == logs.size
    assert pooled.p_magnitude == pytest.approx(stats.wilcoxon(logs).pvalue)
    assert pooled.ratio == pytest.approx(np.exp(np.median(logs)))


def test_a_noise_free_trial_is_predicted_exactly_with_feedforward_and_not_without():
    every = np.sort(np.r_[EVEN, ODD])
    model = conditions.combine(
        [
            conditions.trial_lines(_trial(every, [], phase=0.4), RATE, N),
            conditions.trial_lines(_trial([], every, phase=0.9), RATE, N),
        ],
        yc_integrator,
        "input",
        every,
    )
    found = conditions.prediction(conditions.trial_lines(_trial(EVEN, ODD), RATE, N), model, every)
    assert found.error_ff == pytest.approx(0.0, abs=1e-9) and found.lines_ff == pytest.approx(0.0, abs=1e-9)
    assert found.error_fb > 0.1 and found.lines_fb == pytest.approx(found.error_fb)  # u holds only lines


def test_a_weak_noise_where_an_input_is_absent_gives_the_same_kind_everywhere():
    # One rule (hcid.analysis.fourier.absent_inputs) for the trial's kind and the lines the plant
    # check and the lines estimator read: a target of 1e-7 noise (not exactly 0) is absent for all.
    from hcid.analysis.fourier import forcing_lines

    every = np.sort(np.r_[EVEN, ODD])
    rec = _trial([], every)
    rec["ft"] = rec["ft"] + 1e-7 * np.random.default_rng(1).standard_normal(N)
    assert conditions.trial_lines(rec, RATE, N).kind is Kind.DISTURBANCE_ONLY
    lines = forcing_lines(rec["ft"], rec["fd"], RATE, one_input=True)
    assert lines.problem is None and lines.target.size == 0 and lines.disturbance.tolist() == every.tolist()
    assert forcing_lines(rec["ft"], rec["fd"], RATE).problem is not None  # two inputs asked for
