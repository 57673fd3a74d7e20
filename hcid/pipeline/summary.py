"""What ``hcid analyse`` found, summed up once per group and method from its tables: the
answer line's evidence, the parameters its runs determine, the loop's medians; and what ``hcid
fit-hc`` found, per model, method, W and parameter over its records. The CLI prints these
summaries and the report draws them (:mod:`hcid.cli.answers`, :mod:`hcid.report.sections.study`,
:mod:`hcid.report.sections.hcfit`)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from hcid.pipeline.evidence import (
    MIN_POWER,
    STATISTICS,
    ParameterSummary,
    group_verdict,
    summarise_parameters,
)
from hcid.selection.calibration import WRule, binomial_summary

__all__ = [
    "GroupSummary", "ParameterFits", "StatisticVerdict", "rate_interval", "summarise_fits",
    "summarise_groups",
]  # fmt: skip


@dataclass(frozen=True)
class StatisticVerdict:
    """What one evidence statistic alone says of a group and method (:func:`group_verdict` over its
    own p-values and powers): ``verdict``, ``n_evidence`` of ``n_runs`` at p <= alpha, the
    ``binomial_p``, the runs' ``median_power`` and the count's ``group_power``
    (:func:`hcid.selection.calibration.count_power`); ``deciding`` for the statistic the group's
    verdict reads."""

    name: str
    verdict: str
    n_evidence: int
    n_runs: int
    binomial_p: float
    median_power: float
    group_power: float
    deciding: bool


@dataclass(frozen=True)
class GroupSummary:
    """One group and method of an analysis: its ``analysis_groups`` row, its runs' ``analysis``
    rows, the range of the runs' stated power, the parameters its runs determine (medians over
    them) and the loop's crossover (rad/s) and phase margin (deg), medians over its runs."""

    group: dict
    runs: list[dict]
    power: tuple[float, float]
    parameters: list[ParameterSummary]
    crossover: float
    phase_margin: float

    def by_subject(self) -> list[tuple[str, int, int, float]]:
        """Per subject (the runs' ``subject`` factor, where the data have it and the group holds
        more than one, not all with one run): ``(subject, runs at p <= alpha, runs, binomial p)``,
        so that a verdict carried by one person's runs is seen as such (the group's binomial counts
        runs, not people)."""
        return self._subjects

    @functools.cached_property
    def _subjects(self) -> list[tuple[str, int, int, float]]:
        subjects = sorted({str(r["subject"]) for r in self.runs if "subject" in r})
        if len(subjects) < 2:
            return []
        p = {s: np.array([r["p_value"] for r in self.runs if str(r["subject"]) == s]) for s in subjects}
        if all(x.size == 1 for x in p.values()):  # one run each: a binomial of one cannot reject
            return []
        return [(s, *binomial_summary(p[s], self.group["alpha"])) for s in subjects]

    @property
    def one_subject(self) -> str | None:
        """The subject all of a FEEDFORWARD verdict's runs at p <= alpha belong to, where there is
        one (and the group has several); else None."""
        with_evidence = [s for s, k, _, _ in self.by_subject() if k]
        one = self.group["verdict"] == "FEEDFORWARD" and len(with_evidence) == 1
        return with_evidence[0] if one else None

    @functools.cached_property
    def statistics(self) -> list[StatisticVerdict]:
        """Each evidence statistic's own verdict (:data:`hcid.pipeline.evidence.STATISTICS`) over
        the group's runs, as the group's verdict counts them (a run without its p-value among the
        n, never found; a statistic no run has is not listed), the deciding one marked: its
        verdict is the group's. The deciding statistic was chosen by its calibration
        twins' power before any run was read, and its p and power are over every FB twin drawn for
        it; the others' over the calibration's FB twins."""
        out = []
        for name, (p, power) in STATISTICS.items():
            rows = [{"p_value": math.nan if r[p] is None else r[p], "power": r[power]} for r in self.runs]
            if any(math.isfinite(r["p_value"]) for r in rows):
                v = group_verdict(rows, self.group["alpha"])
                out.append(StatisticVerdict(
                    name, v["verdict"], v["n_evidence"], len(rows), v["binomial_p"], v["median_power"],
                    v["group_power"], name == self.group["decided_by"],
                ))  # fmt: skip
        return out

    @property
    def disagreeing(self) -> list[StatisticVerdict]:
        """The statistics other than the deciding one whose twins show the power to tell (their
        count's power at least :data:`hcid.pipeline.evidence.MIN_POWER`) and whose verdict differs from
        the group's: where the runs' evidence depends on the statistic read. A statistic without
        that power that finds feedforward is listed in :attr:`statistics` but not named here:
        reading whichever of three statistics finds something would not hold the level alpha,
        which is why the one to read is chosen by its twins' power before the runs are read."""
        return [
            s for s in self.statistics
            if not s.deciding and s.group_power >= MIN_POWER and s.verdict != self.group["verdict"]
        ]  # fmt: skip

    @property
    def remnant_share(self) -> float:
        """The remnant's closed-loop share of var(u) from the data alone (``remnant_share_data``),
        the median over the group's runs."""
        return _median([r["remnant_share_data"] for r in self.runs])

    @property
    def without_paths(self) -> int:
        """Runs whose selection at the group's W keeps neither path (nb_ft = nb_e = 0): a W beyond
        what their data support, where "no feedforward" says nothing."""
        return sum(r["nb_ft"] == 0 and r["nb_e"] == 0 for r in self.runs)


def summarise_groups(groups: pa.Table, runs: pa.Table) -> list[GroupSummary]:
    """Every group and method of an analysis, in the groups table's order."""
    rows = runs.to_pylist()
    out = []
    for g in groups.to_pylist():
        mine = [r for r in rows if r["group"] == g["group"] and r["method"] == g["method"]]
        power = [r["power"] for r in mine]
        out.append(
            GroupSummary(
                g,
                mine,
                (min(power), max(power)) if power else (math.nan, math.nan),
                summarise_parameters(mine),
                _median([r["crossover"] for r in mine]),
                _median([r["phase_margin"] for r in mine]),
            )
        )
    return out


def _median(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def has_safe_interval(group: dict) -> bool:
    """Whether a group's W came from a safe interval of its twins (an ``analysis_groups`` row;
    tables before NaN marked a missing interval hold a backward pair there)."""
    return group["w_rule"] == WRule.SAFE_INTERVAL


def rate_interval(rate: float, low: float, high: float, *, long: bool = True) -> str:
    """An error rate with its exact 95% interval, in percent.

    >>> rate_interval(0.05, 0.001, 0.25)
    '5% (95% interval 0 to 25%)'
    >>> rate_interval(0.05, 0.001, 0.25, long=False)
    '5% [0, 25]'
    """
    if long:
        return f"{100 * rate:.0f}% (95% interval {100 * low:.0f} to {100 * high:.0f}%)"
    return f"{100 * rate:.0f}% [{100 * low:.0f}, {100 * high:.0f}]"


@dataclass(frozen=True)
class ParameterFits:
    """One (model, method, W, parameter) of ``hc_parameters``, over its records: ``records`` rows,
    ``fitted`` of them with an estimate (a record without a feedback path has none); the true
    value (NaN on measured data); over the estimates their ``mean``, ``median``, ``sd`` (ddof 1,
    NaN below two) and ``rmse`` against the truth; ``median_se`` over the rows with a standard
    error, an infinite one (a parameter the data do not see) included, and ``rms_se`` over the
    finite ones; ``covered`` of ``n_se`` rows with a finite standard error whose 95% interval holds
    the truth; ``at_bound`` rows on a search bound; and ``first``, the first record's row."""

    records: int
    fitted: int
    true: float
    mean: float
    median: float
    sd: float
    rmse: float
    median_se: float
    rms_se: float
    covered: int
    n_se: int
    at_bound: int
    first: dict

    @property
    def scored(self) -> bool:
        """Estimates to score against a true value (a simulated model's)."""
        return self.fitted > 0 and math.isfinite(self.true)

    @property
    def bias(self) -> float:
        return self.mean - self.true

    @property
    def se_ratio(self) -> float:
        """RMS se over the sd across records: 1 when the standard errors are right."""
        return self.rms_se / self.sd if self.sd > 0 else math.nan

    def percent(self, x: float) -> float:
        """``x`` in % of the true value's size (NaN where it is 0)."""
        return 100 * x / abs(self.true) if self.true != 0 else math.nan


def summarise_fits(params: pa.Table) -> dict[tuple, ParameterFits]:
    """Every (model, method, W, parameter) of an ``hc_parameters`` table, in the table's order."""
    groups: dict[tuple, list[dict]] = {}
    for row in params.to_pylist():
        groups.setdefault((row["model"], row["method"], row["w"], row["parameter"]), []).append(row)
    out = {}
    for key, rows in groups.items():
        x, se, low, high = (
            np.array([r[c] for r in rows], dtype=float) for c in ("estimate", "se", "ci_low", "ci_high")
        )
        true = rows[0]["true_value"]
        true = math.nan if true is None else float(true)
        est, has_se = x[np.isfinite(x)], np.isfinite(se)
        out[key] = ParameterFits(
            records=len(rows),
            fitted=int(est.size),
            true=true,
            mean=float(np.mean(est)) if est.size else math.nan,
            median=float(np.median(est)) if est.size else math.nan,
            sd=float(np.std(est, ddof=1)) if est.size > 1 else math.nan,
            rmse=float(np.sqrt(np.mean((est - true) ** 2))) if est.size else math.nan,
            median_se=float(np.nanmedian(se)) if not np.isnan(se).all() else math.nan,  # inf counts
            rms_se=float(np.sqrt(np.mean(se[has_se] ** 2))) if has_se.any() else math.nan,
            covered=int(np.count_nonzero(has_se & (low <= true) & (true <= high))),
            n_se=int(np.count_nonzero(has_se)),
            at_bound=sum(bool(r["at_bound"]) for r in rows),
            first=rows[0],
        )
    return out


def study_verdicts(groups: pa.Table, runs: pa.Table) -> list[str]:
    """Per method, over every group's runs: k of n at p <= alpha against the binomial (each run
    tested against its own group's twins), where the study has more than one group."""
    rows = runs.to_pylist()
    if len({r["group"] for r in rows}) < 2:
        return []
    alpha = float(groups.column("alpha")[0].as_py())
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == method]
        v = group_verdict(mine, alpha)
        out.append(
            f"ALL GROUPS, {method}: {v['verdict']}: {v['n_evidence']} of {len(mine)} runs show feedforward "
            f"at p <= {alpha:g} against their own group's twins (binomial p = {v['binomial_p']:.2g})"
        )
    return out
