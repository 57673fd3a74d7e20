"""Condition effects across people (hcid.analysis.effects, SPEC 13): exact formulas and a coverage check."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from statsmodels.regression.mixed_linear_model import MixedLM, MixedLMParams
from statsmodels.stats.multitest import multipletests

from hcid import tables
from hcid.analysis import effects, mixed_model
from hcid.analysis.effects import (
    CIRCULAR,
    KRUSKAL,
    MIXED,
    WILCOXON,
    circular_mean,
    effects_frame,
    holm,
    quantity_effects,
    study_effects,
)

from .conftest import ROOT


def by_test(found, test):
    return [e for e in found if e.test == test]


# --- Holm -------------------------------------------------------------------------------------


def test_holm_matches_the_hand_computed_step_down():
    # Sorted: 0.005 x 4 = 0.02, 0.01 x 3 = 0.03, 0.03 x 2 = 0.06, 0.04 x 1 = 0.04 -> 0.06 (monotone);
    # capped at 1; NaN stays NaN and does not count in m (Holm 1979).
    assert holm([0.01, 0.04, 0.03, 0.005]).tolist() == pytest.approx([0.03, 0.06, 0.06, 0.02], abs=1e-15)
    assert holm([0.5, np.nan, 0.4]).tolist()[::2] == [0.8, 0.8] and np.isnan(holm([0.5, np.nan, 0.4])[1])
    assert holm([]).size == 0


def test_holm_agrees_with_statsmodels_multipletests():
    p = np.random.default_rng(4).uniform(0, 0.2, 17)
    assert holm(p) == pytest.approx(multipletests(p, method="holm")[1], abs=1e-14)


# --- the mixed model --------------------------------------------------------------------------

SUBJECTS = np.repeat(np.arange(6), 6)
LEVELS = np.tile(np.repeat(["fo", "so"], 3), 6)


def test_balanced_noise_free_design_gives_the_exact_difference_of_means():
    # Subject offsets, a trial pattern and a known effect 0.7: in a balanced design the GLS estimate of a
    # within-subject contrast is the difference of the level means whatever the variances.
    offset = np.array([1.0, -0.5, 2.0, 0.3, -1.2, 0.8])[SUBJECTS]
    trial = np.tile([-0.2, 0.05, 0.15, 0.1, -0.1, 0.0], 6)
    y = 3.0 + offset + 0.7 * (LEVELS == "so") + trial
    exact = y[LEVELS == "so"].mean() - y[LEVELS == "fo"].mean()
    for se in (None, np.full(y.size, 0.3)):
        (mixed,) = by_test(quantity_effects("Kpe", y, SUBJECTS, LEVELS, se=se, factor="plant"), MIXED)
        assert mixed.estimate == pytest.approx(exact, abs=1e-10)
        assert mixed.effect == "plant: so - fo" and (mixed.subjects, mixed.runs, mixed.left_out) == (6, 36, 0)


def test_one_run_per_subject_and_level_is_the_paired_t_test():
    # The random-intercept model (REML, variance interior) of two levels with one run each is the paired
    # t test: estimate mean(d), interval mean(d) +- t(0.975, n - 1) sd(d) / sqrt(n), p of ttest_rel.
    rng = np.random.default_rng(7)
    n = 9
    a = 5 + rng.normal(0, 2, n)
    b = a + 0.8 + rng.normal(0, 0.5, n)
    found = quantity_effects("TL", np.r_[a, b], np.r_[np.arange(n), np.arange(n)], ["A"] * n + ["B"] * n)
    (mixed,) = by_test(found, MIXED)
    d = b - a
    half = stats.t.ppf(0.975, n - 1) * d.std(ddof=1) / math.sqrt(n)
    assert mixed.estimate == pytest.approx(d.mean(), rel=1e-9)
    assert (mixed.low, mixed.high) == pytest.approx((d.mean() - half, d.mean() + half), rel=1e-5)
    assert mixed.p == pytest.approx(stats.ttest_rel(b, a).pvalue, rel=1e-4)


def test_weights_follow_dersimonian_laird_by_hand():
    # Cells (subject, level): {0, 4} with se {1, 2} and {1, 1} with se {1, 1}. Weights 1/se^2: cell 1's
    # mean 0.8, Q = 1 * 0.64 + 0.25 * 10.24 = 3.2, df = 2, c = (1.25 - 1.0625 / 1.25) + (2 - 1) = 1.4,
    # tau2 = (3.2 - 2) / 1.4 = 6/7 (DerSimonian and Laird 1986, eq. 8); w = 1 / (se^2 + 6/7).
    y, se = np.array([0.0, 4.0, 1.0, 1.0]), np.array([1.0, 2.0, 1.0, 1.0])
    w = effects._weights(y, se, [np.array([0, 0, 1, 1]), np.array(["a"] * 4)])
    expected = 1 / (se**2 + 6 / 7)
    assert w == pytest.approx(expected / expected.mean(), rel=1e-12)
    # Q below its degrees of freedom: tau2 = 0, the weights are 1/se^2.
    w0 = effects._weights(np.array([0.0, 0.1, 1.0, 1.0]), se, [np.array([0, 0, 1, 1])])
    assert w0 == pytest.approx((1 / se**2) / np.mean(1 / se**2), rel=1e-12)


class _Stuck(MixedLM):
    """A MixedLM whose optimizer never converges and whose REML likelihood grows without bound."""

    def fit(self, *args, **kwargs):
        result = super().fit(*args, **kwargs)
        result.converged = kwargs.get("free") is not None
        return result


class _Unbounded(_Stuck):
    def loglike(self, params, profile_fe=True):
        if isinstance(params, MixedLMParams):  # as the bounded search asks
            return float(params.cov_re[0, 0])
        return super().loglike(params, profile_fe)


def test_a_model_that_does_not_converge_is_reported_not_returned(monkeypatch):
    y = (
        1.0
        + np.array([0.5, -0.3, 0.2, 0.9, -1.0, 0.1])[SUBJECTS]
        + np.tile([0.1, -0.2, 0.3, 0, 0.2, -0.1], 6)
    )
    good = by_test(quantity_effects("Kpe", y, SUBJECTS, LEVELS), MIXED)[0]
    monkeypatch.setattr(effects, "MixedLM", _Stuck)  # stops early: the bounded search finds the maximum
    searched = by_test(quantity_effects("Kpe", y, SUBJECTS, LEVELS), MIXED)[0]
    assert searched.note.startswith("REML maximum by a bounded search")
    assert (searched.estimate, searched.low, searched.high) == pytest.approx(
        (good.estimate, good.low, good.high), rel=1e-4
    )
    monkeypatch.setattr(effects, "MixedLM", _Unbounded)
    stuck = by_test(quantity_effects("Kpe", y, SUBJECTS, LEVELS), MIXED)[0]
    assert stuck.note.startswith("model did not converge") and math.isnan(stuck.p) and math.isnan(stuck.low)


# --- paired tests -----------------------------------------------------------------------------


def test_wilcoxon_uses_scipy_on_the_per_subject_means_of_subjects_with_both_levels():
    # Unbalanced: 1-3 runs per subject and level, one undetermined run, subject 8 only at level A.
    rng = np.random.default_rng(11)
    rows = [
        (s, lv, rng.normal(s + 0.4 * (lv == "B"), 0.3))
        for s in range(9)
        for lv in "AB"
        for _ in range(1 + s % 3)
    ]
    table = pd.DataFrame(rows, columns=["subject", "level", "value"])
    table = table[~((table.subject == 8) & (table.level == "B"))].reset_index(drop=True)
    table.loc[table.index[table.subject == 2][0], "value"] = np.nan  # one of subject 2's three runs at A
    found = quantity_effects("Kpt", table.value, table.subject, table.level)
    (wilcoxon,) = by_test(found, WILCOXON)
    means = table.dropna().groupby(["subject", "level"]).value.mean().unstack().dropna()
    d = (means.B - means.A).to_numpy()
    assert wilcoxon.p == pytest.approx(stats.wilcoxon(d).pvalue, rel=1e-12)
    walsh = np.sort([(d[i] + d[j]) / 2 for i in range(d.size) for j in range(i, d.size)])
    assert wilcoxon.estimate == pytest.approx(np.median(walsh), rel=1e-12)  # Hodges-Lehmann
    # n = 8: P(T <= 3) = 5/256 <= 0.025 < P(T <= 4) = 7/256 (subsets of 1..8 with sums 0..4: 1, 1, 1,
    # 2, 2), so the interval is the 4th and 33rd of the 36 Walsh averages (confidence 1 - 10/256).
    assert np.round(effects._signed_rank_cdf(8)[:5] * 256).tolist() == [1, 2, 3, 5, 7]
    assert (wilcoxon.low, wilcoxon.high) == (walsh[3], walsh[32])
    assert (wilcoxon.subjects, wilcoxon.left_out) == (8, 1)
    (mixed,) = by_test(found, MIXED)
    assert (mixed.subjects, mixed.runs, mixed.left_out) == (9, len(table) - 1, 1)


def test_more_than_two_levels_add_kruskal_wallis_over_the_per_subject_means():
    rng = np.random.default_rng(2)
    subject, level = np.repeat(np.arange(5), 6), np.tile(np.repeat(["c1", "c2", "c3"], 2), 5)
    y = rng.normal(0, 1, 5)[subject] + (level == "c3") * 1.5 + rng.normal(0, 0.2, subject.size)
    found = quantity_effects("Kpe", y, subject, level, factor="condition", reference="c2")
    assert [e.effect for e in by_test(found, MIXED)] == ["condition: c1 - c2", "condition: c3 - c2"]
    (kruskal,) = by_test(found, KRUSKAL)
    means = pd.DataFrame({"s": subject, "l": level, "y": y}).groupby(["l", "s"]).y.mean()
    assert kruskal.effect == "condition: any of c1, c2, c3"
    assert kruskal.p == pytest.approx(
        stats.kruskal(*(means[c].to_numpy() for c in ("c1", "c2", "c3"))).pvalue
    )


def test_a_level_without_determined_runs_leaves_the_other_contrasts_fitted():
    subject, level = np.repeat(np.arange(5), 6), np.tile(np.repeat(["a", "b", "c"], 2), 5)
    y = np.arange(5.0)[subject] + 0.5 * (level == "b") + np.tile([0.1, -0.1, 0.2, -0.3, 0.0, 0.0], 5)
    y[level == "c"] = np.nan
    b, c = by_test(quantity_effects("Kpe", y, subject, level), MIXED)
    # Balanced in a and b: the exact difference of the level means (0.5 - 0.05 from the trial pattern).
    assert b.estimate == pytest.approx(y[level == "b"].mean() - y[level == "a"].mean(), abs=1e-10)
    assert math.isfinite(b.p) and math.isnan(c.p) and "no determined runs" in c.note and c.left_out == 10
    confounded = by_test(quantity_effects("Kpe", y, subject, level, factors={"f": level == "b"}), MIXED)
    assert all("confounded" in e.note and math.isnan(e.estimate) for e in confounded)


# --- angles -----------------------------------------------------------------------------------


def test_circular_mean_across_180_degrees():
    assert circular_mean(np.array([170.0, -170.0])) == 180.0  # not 0, the arithmetic mean
    assert circular_mean(np.array([-175.0, 165.0])) == pytest.approx(175.0, abs=1e-12)


def test_phases_near_180_degrees_give_the_paired_circular_difference():
    # Per subject: reference near 175 deg, the other level 10 deg further (so across -180), symmetric
    # deviations: the circular mean of the differences is exactly 10 deg; the interval is Fisher's
    # (1993, 4.4.4) circular standard error with divisor n - 1 and t(0.975, n - 1).
    n = 6
    base = np.array([170.0, 178.0, 175.0, 172.0, 179.0, 176.0])
    d = 10.0 + np.array([-3.0, 3.0, -1.0, 1.0, -2.0, 2.0])
    value = ((np.r_[base, base + d] + 180) % 360) - 180  # as measured: wrapped
    subject, level = np.r_[np.arange(n), np.arange(n)], ["ref"] * n + ["other"] * n
    found = quantity_effects("He phase", value, subject, level, reference="ref", angle=True)
    (circ,) = by_test(found, CIRCULAR)
    rad = np.radians(d - 10)
    sigma = math.degrees(math.sqrt(np.sum(np.sin(rad) ** 2) / (n * (n - 1))) / np.mean(np.cos(rad)))
    half = stats.t.ppf(0.975, n - 1) * sigma
    assert circ.estimate == pytest.approx(10.0, abs=1e-12) and circ.unit == "deg"
    assert (circ.low, circ.high) == pytest.approx((10 - half, 10 + half), rel=1e-12)
    assert circ.p == pytest.approx(2 * stats.t.sf(10 / sigma, n - 1), rel=1e-10)
    # The linear tests see the phases unwrapped around their circular mean: the same 10 deg.
    assert by_test(found, MIXED)[0].estimate == pytest.approx(10.0, abs=1e-9)
    naive = by_test(quantity_effects("He phase", value, subject, level, reference="ref"), MIXED)[0]
    assert abs(naive.estimate - 10.0) > 100  # raw phases averaged across +-180 deg


# --- study level ------------------------------------------------------------------------------


def test_study_effects_applies_holm_per_test_across_quantities():
    rng = np.random.default_rng(3)
    frames = []
    for q, shift in (("Kpe", 0.5), ("TL", 0.0), ("Kpt", 0.2)):
        y = rng.normal(0, 1, 8)[np.repeat(np.arange(8), 4)] + shift * np.tile([0, 0, 1, 1], 8)
        subject, plant = np.repeat(np.arange(8), 4), np.tile(["fo", "fo", "so", "so"], 8)
        value = y + rng.normal(0, 0.2, 32)
        frames.append(
            pd.DataFrame({"quantity": q, "subject": subject, "plant": plant, "value": value, "se": 0.2})
        )
    frame = effects_frame(study_effects(pd.concat(frames), "plant", units={"Kpe": "1"}))
    expected = [
        "quantity",
        "effect",
        "estimate",
        "low",
        "high",
        "p",
        "p_holm",
        "test",
        "subjects",
        "runs",
        "left_out",
    ]
    assert list(frame.columns[:11]) == expected
    for test in (MIXED, WILCOXON):
        rows = frame[frame.test == test]
        assert rows.quantity.tolist() == ["Kpe", "TL", "Kpt"]
        assert rows.p_holm.to_numpy() == pytest.approx(holm(rows.p.to_numpy()), abs=1e-15)
    assert frame.groupby("quantity", sort=False).unit.first().tolist() == ["1", "", ""]


# --- refusals ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"subject": [1] * 36}, "subject: need at least 2 subjects"),
        ({"level": ["fo"] * 36}, "level: need at least 2 levels"),
        ({"se": np.r_[np.nan, np.ones(35)]}, "se: must be finite and positive"),
        ({"se": np.r_[0.0, np.ones(35)]}, "se: must be finite and positive"),
        ({"subject": SUBJECTS[:-1]}, "subject: must have one entry per value"),
        ({"reference": "fx"}, "reference: must be one of the levels"),
        ({"value": np.r_[np.inf, np.ones(35)]}, "value: must be finite or NaN"),
        ({"factors": {"sign": [1, -1]}}, r"factors\['sign'\]: must have one entry per value"),
    ],
)
def test_refusals_name_the_argument(kwargs, match):
    args = {"value": np.arange(36.0), "subject": SUBJECTS, "level": LEVELS} | kwargs
    with pytest.raises(ValueError, match=match):
        quantity_effects("Kpe", args.pop("value"), args.pop("subject"), args.pop("level"), **args)


def test_a_nan_se_where_the_value_is_undetermined_is_accepted():
    y, se = np.arange(36.0) % 7, np.full(36, 0.5)
    y[3] = se[3] = np.nan
    found = quantity_effects("Kpe", y, SUBJECTS, LEVELS, se=se, undetermined=np.arange(36) == 5)
    assert {e.left_out for e in found} == {2}
    with pytest.raises(ValueError, match="table: missing columns"):
        study_effects(pd.DataFrame({"quantity": ["Kpe"]}), "plant")


# --- coverage ---------------------------------------------------------------------------------


def test_weighted_mixed_model_and_paired_test_cover_at_95_percent():
    # 300 studies: 8 subjects x 2 conditions x 3 trials, subject offsets sd 0.4, measurement noise of a
    # known se uniform in [0.05, 0.4] varying run to run, 10% undetermined, true effect 0.3. The share of
    # intervals covering it must lie in the binomial(300, 0.95) 99% band (the Wilcoxon interval's
    # confidence is 1 - 10/256 = 96.1% at 8 subjects, inside the band as well).
    rng = np.random.default_rng(20260101)
    subject = np.repeat(np.arange(8), 6)
    level = np.tile(np.repeat(["A", "B"], 3), 8)
    studies, hits = 300, {MIXED: 0, WILCOXON: 0}
    for _ in range(studies):
        se = rng.uniform(0.05, 0.4, subject.size)
        y = 2.0 + rng.normal(0, 0.4, 8)[subject] + 0.3 * (level == "B") + rng.normal(0, 1, subject.size) * se
        y[rng.random(subject.size) < 0.1] = np.nan
        for e in quantity_effects("Kpe", y, subject, level, se=se):
            hits[e.test] += e.low <= 0.3 <= e.high
    band = stats.binom.ppf([0.005, 0.995], studies, 0.95) / studies
    for test, hit in hits.items():
        assert band[0] <= hit / studies <= band[1], (test, hit / studies, band)


def test_coverage_benchmark_smoke_run():
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "effects_coverage.py"), "--smoke", "--seed", "3"],
        check=True, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert "circular (paired)" in out.stdout and "CPU" in out.stdout


def test_superposition_is_compared_per_line_as_an_effect_of_the_trials():
    # Source: one value per person and level is the paired t test (test above): the mixed
    # model's estimate is the mean of the people's single-input minus two-input differences, its
    # interval mean +- t(0.975, n - 1) sd / sqrt(n); the phase by the paired circular difference.
    # Three people with both kinds, one with two-input trials only (left out: not paired).
    import pyarrow as pa

    from hcid.pipeline.effects import SUPERPOSITION, superposition_rows

    diff = {"a": 2.5, "b": 3.0, "c": 3.7}
    own = {"a": 0.0, "b": 6.2, "c": -4.8, "d": 1.0}  # the people differ: the variance is interior
    rows = []
    for person in ("a", "b", "c", "d"):
        for source in ("two-input trials", "single-input trials"):
            if person == "d" and source.startswith("single"):
                continue
            shift = diff.get(person, 0.0) if source.startswith("single") else 0.0
            base = {"h_ud_db": math.nan, "h_ud_deg": math.nan}
            rows.append({"person": person, "source": source, "omega": 1.5, "h_ur_db": own[person] + shift,
                         "h_ur_deg": -40.0 + 2 * shift, **base})  # fmt: skip
    rows.append({**rows[0], "person": "median"})  # the people's median row is no person
    rows.append({**rows[0], "source": "all trials"})  # nor is the estimate from every trial
    found = superposition_rows(pa.Table.from_pylist(rows))
    assert {r["source"] for r in found} == {SUPERPOSITION}
    assert {r["effect"] for r in found} == {"trials: single-input - two-input"}
    mixed = next(
        r for r in found if r["quantity"] == "|U/R| at 1.5 rad/s" and r["test"] == "mixed model (REML)"
    )
    d = np.array(list(diff.values()))
    half = stats.t.ppf(0.975, 2) * d.std(ddof=1) / math.sqrt(3)
    assert mixed["estimate"] == pytest.approx(d.mean(), rel=1e-9)
    # (REML's variance by an optimizer: with three people within 1e-4 of the closed form)
    assert (mixed["low"], mixed["high"]) == pytest.approx((d.mean() - half, d.mean() + half), rel=1e-4)
    assert (mixed["subjects"], mixed["unit"]) == (3, "dB")
    phase = [r for r in found if r["quantity"] == "U/R phase at 1.5 rad/s"]
    assert phase and all(r["unit"] == "deg" for r in phase)
    circular = next(r for r in phase if r["test"] == "circular (paired)")
    assert circular["estimate"] == pytest.approx(
        np.degrees(np.angle(np.mean(np.exp(1j * np.radians(2 * d)))))
    )
    # Fewer than two people with both kinds: nothing to compare.
    assert superposition_rows(pa.Table.from_pylist([r for r in rows if r["person"] in ("a", "d")])) == []


def test_where_subjects_effects_differ_the_interval_is_the_paired_t_test_of_their_means():
    # Slow reference: the paired t test on each subject's difference of level means. In a balanced
    # design (3 runs per subject and level, no se) the random-intercept model's estimate is their
    # mean, and Bell and McCaffrey's CR2 sandwich by subject with t on subjects - 1 is exactly the
    # paired t test (Satterthwaite's dof: subjects - 1); here the subjects' own effects spread (sd
    # 0.6) far beyond the runs' noise (0.05), where the model's own interval (which takes one
    # effect for all) would be far narrower.
    rng = np.random.default_rng(4)
    n, k = 7, 3
    subject = np.repeat(np.arange(n), 2 * k)
    level = np.tile(np.repeat(["A", "B"], k), n)
    own = 0.5 + rng.normal(0, 0.6, n)
    y = 2 + rng.normal(0, 1, n)[subject] + own[subject] * (level == "B") + rng.normal(0, 0.05, subject.size)
    (mixed,) = by_test(quantity_effects("Kpe", y, subject, level), MIXED)
    d = np.array(
        [
            y[(subject == g) & (level == "B")].mean() - y[(subject == g) & (level == "A")].mean()
            for g in range(n)
        ]
    )
    half = stats.t.ppf(0.975, n - 1) * d.std(ddof=1) / math.sqrt(n)
    assert mixed.estimate == pytest.approx(d.mean(), rel=1e-9)
    assert (mixed.low, mixed.high) == pytest.approx((d.mean() - half, d.mean() + half), rel=1e-6)
    assert mixed.p == pytest.approx(stats.ttest_1samp(d, 0.0).pvalue, rel=1e-6)


def test_runs_left_out_by_subject_leave_the_within_subject_effect():
    # Issue 49: the subjects with the largest values lose their runs at level B (undetermined), so
    # a random intercept alone would also compare the remaining B runs (low subjects) with every
    # subject's A runs and shrink the effect. With each subject's weighted share of B as a column
    # (Mundlak) the estimate is the within-subject one: least squares with a fixed effect per
    # subject and the runs' weights.
    rng = np.random.default_rng(49)
    n, k = 8, 3
    subject = np.repeat(np.arange(n), 2 * k)
    level = np.tile(np.repeat(["A", "B"], k), n)
    base = np.linspace(0.10, 0.18, n)[subject]
    se = rng.uniform(0.01, 0.04, subject.size)
    y = base + 0.03 * (level == "B") + rng.normal(0, 1, subject.size) * se
    lost = (level == "B") & ((base > 0.15) | (subject == 0) & (np.arange(subject.size) % 2 == 0))
    (mixed,) = by_test(quantity_effects("TL", y, subject, level, se=se, undetermined=lost), MIXED)
    keep = ~lost
    w = effects._weights(y[keep], se[keep], [subject[keep], level[keep]])
    x = np.column_stack([(level[keep] == "B").astype(float), np.eye(n)[subject[keep]]])
    root = np.sqrt(w)
    within = np.linalg.lstsq(x * root[:, None], y[keep] * root, rcond=None)[0][0]
    assert mixed.estimate == pytest.approx(within, rel=1e-8)
    assert mixed.left_out == int(lost.sum()) and mixed.subjects == n


def test_levels_that_lose_different_shares_of_runs_say_so():
    # Source: counted by hand. Six subjects with one run per level; level B loses 2 of its 6 runs
    # as undetermined (33%), A none: the note names both shares. With one lost in each (17% and
    # 17%) it says nothing of it.
    from hcid.analysis.effects import quantity_effects

    subject = [s for s in "abcdef" for _ in range(2)]
    level = ["A", "B"] * 6
    value = [1.0, 1.5, 1.1, 1.4, 0.9, 1.6, 1.2, 1.3, 1.0, 1.7, 1.1, 1.5]
    lost = [False, True, False, True] + [False] * 8
    effects = quantity_effects("Kpe", value, subject, level, undetermined=lost)
    said = "left out unevenly (A 0%, B 33% of the runs undetermined): the effect may be biased"
    assert all(said in e.note for e in effects), [e.note for e in effects]
    even = [True, False, False, True] + [False] * 8
    assert not any(
        "unevenly" in e.note for e in quantity_effects("Kpe", value, subject, level, undetermined=even)
    )


def test_flagged_values_are_compared_and_undetermined_ones_left_out():
    # Source: SPEC 11 and hcid.hcfit.determined: "not told from 0" and "outside its plausible
    # range" flag a determined value (kept in group summaries); a correlated pair, a bound, an
    # infinite se make it undetermined. End to end, taking the flag for undetermined left out the
    # tau_pt runs fitted near 0, more of them in the condition with the weaker feedforward: a false
    # effect (docs/methodology.md, "Effects across people").
    from hcid.pipeline.effects import long_table

    statuses = {
        "determined": False,
        "not told from 0 (se above |value|)": False,
        "outside its plausible range": False,
        "correlated with TI (r = +0.97)": True,
        "at a search bound": True,
        "not seen by the data (infinite se)": True,
        "in a failed fit (validation VAF below 0%)": True,
        "fixed at a literature value": True,
    }
    rows = []
    for k, status in enumerate(statuses):
        row = {
            "subject": f"s{k}",
            "plant": "fo",
            "crossover": 1.0,
            "phase_margin": 40.0,
            "remnant_share_data": 0.3,
        }
        for p in tables.HC_PARAMETER_NAMES:
            row.update({p: 0.05, f"{p}_se": 0.1, f"{p}_status": status})
        rows.append(row)
    table = long_table(rows, "plant", "subject")
    got = table[table.quantity == "tau_pt"].set_index("subject")["undetermined"]
    assert got.tolist() == list(statuses.values())
    nan_row = {**rows[0], "tau_pt": math.nan}
    assert long_table([nan_row], "plant", "subject").query("quantity == 'tau_pt'").undetermined.item()


def test_cluster_robust_dof_is_satterthwaites_and_subjects_minus_one_when_balanced():
    # Slow reference: the CR2 variance of coefficient j written as one quadratic form y' M y of the
    # whitened data, M = sum_g r_g r_g' with r_g = R[g, :]' A_g X_g B e_j (R the whitened residual
    # maker, A_g = (R_gg)^(-1/2), B the bread), and Satterthwaite's dof of it under the working
    # model (identity covariance): tr(M)^2 / tr(M^2) (Bell and McCaffrey 2002, eq. 9). Built with
    # full n x n matrices and a generic matrix square root, not the function's Gram matrix. A
    # balanced paired design gives subjects - 1 (the paired t test); an unbalanced one fewer.
    from scipy.linalg import sqrtm

    rng = np.random.default_rng(11)
    for runs_per_cell in ([3] * 12, [3, 1, 2, 3, 3, 1, 2, 3, 3, 3, 1, 3]):
        subject = np.repeat(np.arange(6), [runs_per_cell[2 * g] + runs_per_cell[2 * g + 1] for g in range(6)])
        level = np.concatenate(
            [["A"] * runs_per_cell[2 * g] + ["B"] * runs_per_cell[2 * g + 1] for g in range(6)]
        )
        y = rng.normal(0, 1, 6)[subject] + 0.4 * (level == "B") + rng.normal(0, 0.3, subject.size)
        x = np.column_stack([np.ones(y.size), (level == "B").astype(float)])
        x = mixed_model.with_subject_means(x, [1], subject, np.ones(y.size))
        model = effects.MixedLM(y, x, groups=subject, exog_re=np.ones((y.size, 1)))
        result, _ = mixed_model.fit_reml(model)
        cov, dof = mixed_model.cluster_robust(model, result, subject)
        psi = float(result.cov_re_unscaled[0, 0])
        v = np.eye(y.size) + psi * (subject[:, None] == subject[None, :])
        root_inv = np.linalg.inv(np.real(sqrtm(v)))
        xw, yw = root_inv @ x, root_inv @ y
        bread = np.linalg.inv(xw.T @ xw)
        r = np.eye(y.size) - xw @ bread @ xw.T
        m = np.zeros((y.size, y.size))
        for g in range(6):
            rows = np.flatnonzero(subject == g)
            a = np.linalg.pinv(np.real(sqrtm(r[np.ix_(rows, rows)])))
            vec = r[rows, :].T @ a @ xw[rows] @ bread[:, 1]
            m += np.outer(vec, vec)
        assert cov[1, 1] == pytest.approx(yw @ m @ yw, rel=1e-8)
        assert dof[1] == pytest.approx(np.trace(m) ** 2 / np.trace(m @ m), rel=1e-8)
        if len(set(runs_per_cell)) == 1:
            assert dof[1] == pytest.approx(5.0, rel=1e-9)
        else:
            assert dof[1] < 5.0


def test_a_contrast_one_subject_carries_keeps_an_interval():
    # Source: the CR2 sandwich is unbiased under the working model, so its variance's mean tr(G)
    # equals the bread's diagonal (Bell and McCaffrey 2002); where one subject alone has runs at
    # level B, the pseudo-inverse of that subject's I - H_gg removes everything it contributes, the
    # sandwich is exactly 0 and its Satterthwaite dof rounding noise (review: 25 of 60 such random
    # designs had noise dof >= 2, giving zero-width intervals at p 1e-33 to 0). Such a sandwich is
    # degenerate (NaN dof) and the interval is the wider rule's, here the model's: positive width.
    subject = np.repeat(list("abcdef"), 3)
    level = np.array(["A", "B", "B"] + ["A"] * 15)
    rng = np.random.default_rng(0)
    y = rng.normal(size=6)[np.repeat(np.arange(6), 3)] + 0.3 * (level == "B") + rng.normal(0, 0.2, 18)
    (mixed,) = by_test(quantity_effects("q", y, subject, level), MIXED)
    assert mixed.high - mixed.low > 0.1 and mixed.p > 1e-6, mixed
    # Two subjects with both levels (the CPHS recordings' Kpt: 3 and 2 runs): an interval too.
    subject = np.array(["a", "a", "a", "b", "b"])
    level = np.array(["A", "B", "B", "A", "B"])
    y = np.array([1.0, 0.6, 0.5, 1.2, 0.7])
    se = np.array([0.05, 0.04, 0.06, 0.05, 0.05])
    (mixed,) = by_test(quantity_effects("Kpt", y, subject, level, se=se), MIXED)
    assert mixed.high - mixed.low > 0.1 and mixed.p > 1e-3, mixed
