"""Condition effects across people, with their uncertainty (SPEC 13; pure numerical core).

A quantity (a parameter, a response at a line, a loop figure) is observed once per run; runs belong
to subjects and to a level of the compared factor. Per level against the reference:

- ``mixed model (REML)``: statsmodels ``MixedLM``, fixed effects for the compared factor and any
  other factors, a random intercept per subject, REML. With known standard errors run ``r`` has the
  residual variance ``sigma2 (se_r**2 + tau2)``: ``tau2`` the trial-to-trial variance the se leave
  out, by DerSimonian and Laird's moment estimator (Cochran's Q summed over the cells of runs
  sharing a subject and every factor's level; 0 where Q is below its degrees of freedom); the free
  scale ``sigma2`` absorbs a common misstatement of the se. MixedLM has no weights: every row, its
  design and its random-effect column are multiplied by ``sqrt(w_r)``, ``w_r = 1 / (se_r**2 +
  tau2)``, lme4's weighted model (residual variance ``sigma2 / w_r``, random intercept on the
  data's scale). Weights ``1 / se_r**2`` alone would let a run with a tiny fit error outweigh the
  person's trial-to-trial spread. Where the compared factor varies within subjects, each subject's
  weighted share of each level is a further (between-subject) column (Mundlak 1978): the effect is
  the within-subject one, as with a fixed effect per subject, unbiased where which runs are left
  out depends on the subject (issue 49: end to end the subjects with the largest Kpe and TL lost
  their condition B runs, and the random intercept alone, comparing their A runs with the others' B
  runs, took TL's median effect from 0.021 to 0.016). Interval and p, for a factor varying within
  subjects: Bell and McCaffrey's CR2 cluster-robust covariance by subject with Student's t on its
  Satterthwaite degrees of freedom (Pustejovsky and Tipton 2018; ``n_subjects - 1`` on a balanced
  paired design, the paired t test of the subjects' mean differences). A random intercept assumes
  every subject has the same effect and the se tell each run's spread; where subjects' effects
  differ, or a fit's se understates its trial-to-trial spread, the model's own interval is too
  narrow (subjects' effects spread by half the effect: 79% coverage of TL's; end to end, levels
  7.5 to 8.8%) and the sandwich's is not (docs/methodology.md). Where the sandwich is degenerate
  (:data:`hcid.analysis.mixed_model.DEGENERATE`), and for a factor constant within subjects: the
  wider of the model's (t on the between-within dof, SAS ``DDFM=BETWITHIN``) and the sandwich's (t
  on ``n_subjects - 1``, or as the model's). The model's machinery: :mod:`hcid.analysis.mixed_model`.
- ``Wilcoxon signed-rank`` on the differences of the per-level means (weighted as above) of the
  subjects with both levels: ``scipy.stats.wilcoxon``'s p, the Hodges-Lehmann estimate and its
  exact interval (Hollander and Wolfe, Nonparametric Statistical Methods, 2nd ed., 3.3: confidence
  at least 95%, none below 6 subjects). With more than two levels also ``Kruskal-Wallis`` over the
  per-level means (as the field reports; it takes the levels' subjects as independent groups).
- ``circular (paired)`` for angles (deg): per subject and level the weighted circular mean, the
  wrapped paired differences ``d_i``, their circular mean ``m`` and ``m +- t(0.975, n - 1) sigma``,
  ``sigma**2 = sum(sin(d_i - m)**2) / (n (n - 1) Rbar**2)``: Fisher's circular standard error
  (Statistical Analysis of Circular Data, 1993, 4.4.4) with divisor n - 1 and Student's t for few
  subjects; p from the t statistic ``m / sigma``. (Rayleigh and V tests test uniformity, which the
  differences lack with or without an effect.) The other tests see an angle unwrapped to within
  180 deg of its circular mean over all runs (raw phases near +-180 deg do not average).

Undetermined values (NaN, or marked in ``undetermined``) are left out and counted.
:func:`study_effects` applies :func:`holm` per test across quantities; :func:`effects_frame` makes
a table.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import asdict, dataclass, fields, replace

import numpy as np
import pandas as pd
from scipy import stats
from statsmodels.regression.mixed_linear_model import MixedLM

from hcid.analysis.mixed_model import cluster_robust, fe_covariance, fit_reml, with_subject_means
from hcid.errors import DataError

__all__ = [
    "CIRCULAR", "KRUSKAL", "MIXED", "WILCOXON", "Effect", "circular_mean", "effects_frame", "holm",
    "quantity_effects", "study_effects", "wrap",
]  # fmt: skip

MIXED = "mixed model (REML)"
WILCOXON = "Wilcoxon signed-rank"
KRUSKAL = "Kruskal-Wallis"
CIRCULAR = "circular (paired)"
#: Two-sided level of every interval (95%).
ALPHA = 0.05
#: Undetermined shares of the compared levels' runs that differ by this much are named in the
#: effect's note (:meth:`_Data.uneven`): end to end, TL undetermined in 13% of condition A's runs and
#: 31% of B's cut its effect by a fifth (-0.022 against -0.028 over every run's value; truth -0.03).
UNEVEN = 0.05


@dataclass(frozen=True)
class Effect:
    """One effect of a compared factor on one quantity, by one test.

    Attributes
    ----------
    quantity, effect : str
        What was observed per run (``Kpe``, ...); ``"<factor>: <level> - <reference>"``, or
        ``"<factor>: any of <levels>"`` for an omnibus test.
    estimate, low, high : float
        The effect and its 95% interval in ``unit`` (NaN for an omnibus test or where not found).
    p, p_holm : float
        Two-sided p of no effect; after Holm's correction over the effects of the same test computed together.
    test : str
        :data:`MIXED`, :data:`WILCOXON`, :data:`KRUSKAL` or :data:`CIRCULAR`.
    subjects, runs, left_out : int
        The subjects and determined runs used; the undetermined runs at the compared levels, left out.
    unit, note : str
        The quantity's unit; empty, or why a figure is NaN or to be doubted (no convergence, ...).
    """

    quantity: str
    effect: str
    estimate: float
    low: float
    high: float
    p: float
    p_holm: float
    test: str
    subjects: int
    runs: int
    left_out: int
    unit: str
    note: str = ""


def holm(p_values: Sequence[float]) -> np.ndarray:
    """Holm's step-down adjusted p-values (NaN entries stay NaN and do not count).

    With the ``m`` p-values sorted, ``p_(1) <= ... <= p_(m)``, the adjusted value of ``p_(i)`` is
    ``max over j <= i of min(1, (m - j + 1) p_(j))`` (Holm, Scand. J. Statist. 6, 1979).

    Examples
    --------
    >>> holm([0.01, 0.04, 0.03, 0.005]).tolist()
    [0.03, 0.06, 0.06, 0.02]
    """
    p = np.asarray(p_values, dtype=np.float64)
    if p.ndim != 1:
        raise DataError(f"p_values: must be one-dimensional, got shape {p.shape}")
    out = np.full(p.shape, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    order = ok[np.argsort(p[ok], kind="stable")]
    m = order.size
    out[order] = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    return out


def wrap(degrees):
    """Angles in degrees wrapped to [-180, 180) (``wrap(190) = -170``)."""
    return (np.asarray(degrees, dtype=np.float64) + 180.0) % 360.0 - 180.0


def circular_mean(degrees: np.ndarray, weights: np.ndarray | None = None) -> float:
    """The (weighted) mean direction of angles in degrees, in [-180, 180]: the angle of the mean unit vector.

    Examples
    --------
    >>> circular_mean(np.array([170.0, -170.0]))  # the arithmetic mean would say 0
    180.0
    >>> round(circular_mean(np.array([350.0, 30.0, 90.0]), np.array([1.0, 1.0, 0.0])), 9)
    10.0
    """
    rad = np.radians(np.asarray(degrees, dtype=np.float64))
    w = np.ones_like(rad) if weights is None else np.asarray(weights, dtype=np.float64)
    return float(np.degrees(np.arctan2(np.sum(w * np.sin(rad)), np.sum(w * np.cos(rad)))))


def quantity_effects(
    quantity: str, value: Sequence[float], subject: Sequence, level: Sequence, *,
    se: Sequence[float] | None = None, undetermined: Sequence[bool] | None = None,
    factors: Mapping[str, Sequence] | None = None, factor: str = "level", reference: object = None,
    angle: bool = False, unit: str = "",
) -> list[Effect]:  # fmt: skip
    """The effects of the compared factor on one quantity, by every test of the module.

    Parameters
    ----------
    quantity : str
        Its name, copied into the effects.
    value, subject, level : sequence, shape (n_runs,)
        Per run: the value in ``unit`` (deg for an angle; NaN where undetermined), the subject, the
        level of the compared factor.
    se : sequence of float, shape (n_runs,), optional
        Each run's standard error, finite and positive for every determined value; None where unknown.
    undetermined : sequence of bool, shape (n_runs,), optional
        Runs whose finite value is undetermined (SPEC 11): left out and counted.
    factors : mapping of str to sequence, optional
        Other categorical fixed factors of the mixed model, one entry per run (the paired tests
        average over them).
    factor, reference
        The compared factor's name (for the labels) and its reference level (default: the first sorted).
    angle : bool
        An angle in degrees: the circular test is added, the others see the values unwrapped.
    unit : str
        The quantity's unit (``deg`` by default for an angle).

    Returns
    -------
    list of Effect
        Per non-reference level the mixed model's, the Wilcoxon test's and (angles) the circular
        effect; with more than two levels one Kruskal-Wallis effect. ``p_holm`` per test over these.

    Raises
    ------
    hcid.errors.DataError
        (a ValueError) naming the argument: lengths that differ, an infinite value, fewer than 2 subjects
        or levels, an unknown reference, a standard error not finite and positive.

    Examples
    --------
    >>> value = [1.0, 2.1, 1.4, 2.3, 0.9, 2.2, 1.6, 2.4]
    >>> subject, level = ["a", "a", "b", "b", "c", "c", "d", "d"], ["fo", "so"] * 4
    >>> mixed = quantity_effects("Kpe", value, subject, level, factor="plant")[0]
    >>> mixed.effect, mixed.test, round(mixed.estimate, 6)  # the mean paired difference
    ('plant: so - fo', 'mixed model (REML)', 1.025)
    """
    y, subj, lev, s, drop, others = _checked(value, subject, level, se, undetermined, factors)
    levels = sorted(set(lev.tolist()), key=str)
    if len(levels) < 2:
        raise DataError(f"level: need at least 2 levels, got {len(levels)} ({levels[0]!r})")
    if reference is None:
        reference = levels[0]
    elif reference not in levels:
        raise DataError(f"reference: must be one of the levels {levels}, got {reference!r}")
    keep = ~drop
    y, subj, lev, others = y[keep], subj[keep], lev[keep], {k: x[keep] for k, x in others.items()}
    s = None if s is None else s[keep]
    if angle and y.size:
        centre = circular_mean(y, None if s is None else 1 / s**2)
        y = centre + wrap(y - centre)
    w = _weights(y, s, [subj, lev, *others.values()])
    unit = unit or ("deg" if angle else "")
    data = _Data(quantity, unit, factor, reference, y, subj, lev, w, others, np.asarray(level)[drop])
    contrasts = [lv for lv in levels if lv != reference]
    means = _cell_means(data, circular=False)
    out = _mixed(data, contrasts) + [_wilcoxon(data, means, lv) for lv in contrasts]
    if len(levels) > 2:
        out.append(_kruskal(data, means, levels))
    if angle:
        circ = _cell_means(data, circular=True)
        out += [_circular(data, circ, lv) for lv in contrasts]
    return _with_holm(out)


def study_effects(
    table: pd.DataFrame, factor: str, *, factors: Sequence[str] = (), reference: object = None,
    angles: Collection[str] = (), units: Mapping[str, str] | None = None,
) -> list[Effect]:  # fmt: skip
    """The effects of ``factor`` on every quantity of a long table, Holm-corrected per test.

    Parameters
    ----------
    table : pandas.DataFrame
        One row per run and quantity: ``quantity``, ``subject``, ``value``, ``factor``, every name
        in ``factors``, optionally ``se`` (all NaN for a quantity: unknown) and ``undetermined``.
    factor, factors, reference
        As in :func:`quantity_effects`.
    angles, units
        The quantities that are angles in degrees; each quantity's unit.

    Returns
    -------
    list of Effect
        :func:`quantity_effects` of every quantity in order, ``p_holm`` by Holm's correction over
        all effects of the same test (every quantity and contrast).

    Examples
    --------
    >>> table = pd.DataFrame({"quantity": ["Kpe"] * 6 + ["TL"] * 6, "subject": list("aabbcc") * 2,
    ...                       "plant": ["fo", "so"] * 6, "value": [1, 2, 1.5, 2.6, 1.2, 2.1] * 2})
    >>> frame = effects_frame(study_effects(table, "plant"))
    >>> frame[frame.test == "Wilcoxon signed-rank"][["quantity", "p", "p_holm"]].values.tolist()
    [['Kpe', 0.25, 0.5], ['TL', 0.25, 0.5]]
    """
    if missing := [c for c in ("quantity", "subject", "value", factor, *factors) if c not in table.columns]:
        raise DataError(f"table: missing columns {missing}; it has {list(table.columns)}")
    out: list[Effect] = []
    for name, rows in table.groupby("quantity", sort=False):
        se = rows["se"].to_numpy(np.float64) if "se" in rows else None
        flags = rows["undetermined"].to_numpy(bool) if "undetermined" in rows else None
        out += quantity_effects(
            str(name), rows["value"].to_numpy(np.float64), rows["subject"].to_numpy(),
            rows[factor].to_numpy(), se=None if se is None or np.isnan(se).all() else se, undetermined=flags,
            factors={f: rows[f].to_numpy() for f in factors}, factor=factor, reference=reference,
            angle=name in angles, unit=(units or {}).get(str(name), ""),
        )  # fmt: skip
    return _with_holm(out)


def effects_frame(effects: Sequence[Effect]) -> pd.DataFrame:
    """The effects as a table, one row each, columns in :class:`Effect`'s order.

    Examples
    --------
    >>> list(effects_frame([]).columns)[:6]
    ['quantity', 'effect', 'estimate', 'low', 'high', 'p']
    """
    return pd.DataFrame([asdict(e) for e in effects], columns=[f.name for f in fields(Effect)])


@dataclass(frozen=True)
class _Data:
    """One quantity's determined runs (angles unwrapped), their weights, and the undetermined runs' levels."""

    quantity: str
    unit: str
    factor: str
    reference: object
    y: np.ndarray
    subject: np.ndarray
    level: np.ndarray
    w: np.ndarray
    others: dict[str, np.ndarray]
    dropped: np.ndarray

    def effect(self, level, test: str, figures, subjects: int, runs: int, levels: list, note="") -> Effect:
        """An effect of ``level`` (None: an omnibus test over ``levels``); ``figures`` the estimate, low,
        high and p (None: NaN)."""
        est, low, high, p = (math.nan if x is None else float(x) for x in figures)
        omnibus = f"any of {', '.join(map(str, levels))}"
        label = f"{level} - {self.reference}" if level is not None else omnibus
        left = int(np.isin(self.dropped, levels).sum())
        compared = [self.reference, level] if level is not None else levels
        uneven = self.uneven(compared) if math.isfinite(est) or math.isfinite(p) else ""
        note = "; ".join(x for x in (note, uneven) if x)
        figures = (est, low, high, p, math.nan, test, subjects, runs, left, self.unit, note)
        return Effect(self.quantity, f"{self.factor}: {label}", *figures)

    def uneven(self, levels: list) -> str:
        """Where the compared levels lose shares of their runs as undetermined that differ by
        :data:`UNEVEN` or more, each level's share, in words: the values left out are seldom like
        the rest (a parameter is undetermined near its bound), so the effect may be biased
        (measured end to end: docs/methodology.md, "Effects across people"); else ""."""
        shares = {}
        for lv in levels:
            dropped = int(np.sum(self.dropped == lv))
            total = dropped + int(np.sum(self.level == lv))
            shares[lv] = dropped / total if total else 0.0
        if max(shares.values()) - min(shares.values()) < UNEVEN:
            return ""
        said = ", ".join(f"{lv} {100 * share:.0f}%" for lv, share in shares.items())
        return f"left out unevenly ({said} of the runs undetermined): the effect may be biased"


def _checked(value, subject, level, se, undetermined, factors):
    y = np.asarray(value, dtype=np.float64)
    if y.ndim != 1 or y.size == 0:
        raise DataError(f"value: must be a non-empty one-dimensional sequence, got shape {y.shape}")
    if np.isinf(y).any():
        raise DataError(f"value: must be finite or NaN (undetermined), got inf at run {np.isinf(y).argmax()}")

    def same_length(name, x):
        x = np.asarray(x)
        if x.shape != y.shape:
            raise DataError(f"{name}: must have one entry per value ({y.size}), got shape {x.shape}")
        return x

    subj, lev = same_length("subject", subject), same_length("level", level)
    flagged = False if undetermined is None else same_length("undetermined", undetermined).astype(bool)
    drop = np.isnan(y) | flagged
    s = None if se is None else same_length("se", np.asarray(se, dtype=np.float64))
    if s is not None and (bad := ~drop & ~(np.isfinite(s) & (s > 0))).any():
        i = int(bad.argmax())
        raise DataError(f"se: must be finite and positive where a value is determined, got {s[i]} (run {i})")
    others = {name: same_length(f"factors[{name!r}]", x) for name, x in (factors or {}).items()}
    if (n_subjects := len(set(subj.tolist()))) < 2:
        raise DataError(f"subject: need at least 2 subjects, got {n_subjects}")
    return y, subj, lev, s, drop, others


def _weights(y, se, cells) -> np.ndarray:
    """Each run's inverse variance ``1 / (se**2 + tau2)``, normalized to mean 1 (ones without se); ``tau2``
    DerSimonian and Laird's estimator: Cochran's Q summed over the ``cells``, against its dof."""
    if se is None or not y.size:
        return np.ones(y.size)
    codes = pd.factorize(pd.Series(list(zip(*cells, strict=True))))[0]
    w = 1 / se**2
    sw, swy = np.bincount(codes, w), np.bincount(codes, w * y)
    q = np.sum(w * (y - (swy / sw)[codes]) ** 2)
    dof, c = codes.size - sw.size, np.sum(sw - np.bincount(codes, w**2) / sw)
    tau2 = max(0.0, (q - dof) / c) if dof > 0 and c > 0 else 0.0
    w = 1 / (se**2 + tau2)
    return w / w.mean()


def _mixed(d: _Data, contrasts: list) -> list[Effect]:
    levels, runs, n_subj = [d.reference, *contrasts], d.y.size, len(set(d.subject.tolist()))
    present = [lv for lv in contrasts if np.any(d.level == lv)]  # a level without determined runs: blank
    columns = [np.ones(runs)] + [(d.level == lv).astype(float) for lv in present]
    for x in d.others.values():
        columns += [(x == v).astype(float) for v in sorted(set(x.tolist()), key=str)[1:]]
    design = np.column_stack(columns)
    rank, found = np.linalg.matrix_rank(design) if runs else 0, {}

    def effects(note: str) -> list[Effect]:
        blank = [None] * 4
        return [found.get(lv) or d.effect(lv, MIXED, blank, n_subj, runs, levels, note) for lv in contrasts]

    if n_subj < 2 or not present or not np.any(d.level == d.reference):
        return effects("not fitted: fewer than 2 subjects or no determined runs at the level or reference")
    if rank < design.shape[1]:
        return effects("not fitted: the factors are confounded")
    groups = pd.factorize(d.subject)[0]
    design = with_subject_means(design, range(1, 1 + len(present)), groups, d.w)
    rank = np.linalg.matrix_rank(design)
    spread = pd.DataFrame(design).groupby(groups).nunique().max(axis=0).to_numpy()
    between = [j for j in range(design.shape[1]) if spread[j] == 1]  # columns constant within subjects
    rank_b = np.linalg.matrix_rank(design[:, between]) if between else 0
    root_w = np.sqrt(d.w)
    # On the data's own scale: statsmodels' boundary and convergence checks use absolute tolerances.
    unit = float(np.std(d.y)) or 1.0
    model = MixedLM(d.y / unit * root_w, design * root_w[:, None], groups=groups, exog_re=root_w[:, None])
    try:
        result, note = fit_reml(model)
    except (np.linalg.LinAlgError, ValueError) as error:
        return effects(f"model failed: {error}")
    if result is None:
        return effects(f"model did not converge: {note}")
    model_based = np.sqrt(np.diag(fe_covariance(model, result, groups))) * unit
    robust, robust_dof = cluster_robust(model, result, groups)
    robust = np.sqrt(np.clip(np.diag(robust), 0.0, None)) * unit
    for j, lv in enumerate(present, start=1):
        est = float(result.fe_params[j]) * unit
        # Within subjects: the cluster-robust interval on its Satterthwaite dof (t on 1 to 2 dof is
        # wide, as it should be). Where the sandwich is degenerate (dof NaN: one subject alone
        # carries the contrast) and between subjects: the wider of the model's (between-within
        # dof) and the sandwich's (subjects - 1, or as the model's).
        within = j not in between
        if within and robust_dof[j] >= 1 - 1e-9:
            candidates = [(float(robust[j]), max(1.0, float(robust_dof[j])))]
        else:
            candidates = [
                (float(model_based[j]), runs - n_subj - (rank - rank_b) if within else n_subj - rank_b),
                (float(robust[j]), n_subj - 1 if within else n_subj - rank_b),
            ]
        usable = [(se, dof) for se, dof in candidates if dof >= 1 and np.isfinite(se)]
        if not usable:
            why = (
                "no degrees of freedom left" if all(dof < 1 for _, dof in candidates) else "no standard error"
            )
            found[lv] = d.effect(lv, MIXED, [est, None, None, None], n_subj, runs, levels, why)
            continue
        se, dof = max(usable, key=lambda c: stats.t.ppf(1 - ALPHA / 2, c[1]) * c[0])
        half = stats.t.ppf(1 - ALPHA / 2, dof) * se
        p = 2 * stats.t.sf(abs(est) / se, dof) if se > 0 else float(est == 0)
        found[lv] = d.effect(lv, MIXED, [est, est - half, est + half, p], n_subj, runs, levels, note)
    return effects("not fitted: no determined runs at the level")


def _cell_means(d: _Data, circular: bool) -> dict[tuple, tuple[float, int]]:
    """Per (subject, level): the weighted (circular) mean of the runs, and their number."""
    out = {}
    for key in dict.fromkeys(zip(d.subject.tolist(), d.level.tolist(), strict=True)):
        at = (d.subject == key[0]) & (d.level == key[1])
        mean = circular_mean(d.y[at], d.w[at]) if circular else float(np.average(d.y[at], weights=d.w[at]))
        out[key] = (mean, int(at.sum()))
    return out


def _paired(means: dict, reference, level) -> tuple[np.ndarray, int]:
    """The subjects with both levels: their means' differences ``level - reference``, and their runs."""
    subjects = [s for (s, lv) in means if lv == level and (s, reference) in means]
    diff = np.array([means[s, level][0] - means[s, reference][0] for s in subjects])
    return diff, sum(means[s, level][1] + means[s, reference][1] for s in subjects)


def _signed_rank_cdf(n: int) -> np.ndarray:
    """``P(T <= k)``, k = 0..n(n+1)/2, of the Wilcoxon signed-rank statistic of n untied differences."""
    pmf = np.ones(1)
    for i in range(1, n + 1):
        pmf = 0.5 * (np.concatenate([pmf, np.zeros(i)]) + np.concatenate([np.zeros(i), pmf]))
    return np.cumsum(pmf)


def _wilcoxon(d: _Data, means: dict, level) -> Effect:
    diff, runs = _paired(means, d.reference, level)
    n, levels = diff.size, [d.reference, level]
    if n < 2:
        return d.effect(level, WILCOXON, [None] * 4, n, runs, levels, "fewer than 2 paired subjects")
    i, j = np.triu_indices(n)
    walsh = np.sort((diff[i] + diff[j]) / 2)
    below = np.flatnonzero(_signed_rank_cdf(n) <= ALPHA / 2)  # P(T <= k - 1) for the k-th Walsh average
    k = int(below[-1]) + 1 if below.size else 0
    low, high = (walsh[k - 1], walsh[-k]) if k else (None, None)
    note = "" if k else "no 95% interval below 6 paired subjects"
    p = 1.0 if np.all(diff == 0) else stats.wilcoxon(diff).pvalue
    return d.effect(level, WILCOXON, [np.median(walsh), low, high, p], n, runs, levels, note)


def _kruskal(d: _Data, means: dict, levels: list) -> Effect:
    groups = [np.array([m for (_, lv), (m, _) in means.items() if lv == level]) for level in levels]
    subjects, runs = len({s for (s, _) in means}), sum(r for (_, r) in means.values())
    try:
        p, note = stats.kruskal(*[g for g in groups if g.size]).pvalue, ""
    except ValueError as error:
        p, note = None, f"no test: {error}"
    return d.effect(None, KRUSKAL, [None, None, None, p], subjects, runs, levels, note)


def _circular(d: _Data, means: dict, level) -> Effect:
    diff, runs = _paired(means, d.reference, level)
    n, levels = diff.size, [d.reference, level]
    if n < 2:
        return d.effect(level, CIRCULAR, [None] * 4, n, runs, levels, "fewer than 2 paired subjects")
    diff = np.radians(wrap(diff))
    c, s = np.cos(diff).mean(), np.sin(diff).mean()
    m, r_bar = math.atan2(s, c), math.hypot(s, c)
    if r_bar < 1e-12:
        return d.effect(level, CIRCULAR, [None] * 4, n, runs, levels, "differences without a mean direction")
    sigma = math.degrees(math.sqrt(np.sum(np.sin(diff - m) ** 2) / (n * (n - 1))) / r_bar)
    est, half = math.degrees(m), stats.t.ppf(1 - ALPHA / 2, n - 1) * sigma
    p = 2 * stats.t.sf(abs(est) / sigma, n - 1) if sigma > 0 else float(est == 0)
    return d.effect(level, CIRCULAR, [est, est - half, est + half, p], n, runs, levels)


def _with_holm(effects: list[Effect]) -> list[Effect]:
    tests, p = np.array([e.test for e in effects]), np.array([e.p for e in effects], dtype=np.float64)
    adjusted = np.full(p.size, np.nan)
    for test in set(tests.tolist()):
        adjusted[tests == test] = holm(p[tests == test])
    return [replace(e, p_holm=float(q)) for e, q in zip(effects, adjusted, strict=True)]
