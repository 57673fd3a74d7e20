"""What ``hcid analyse`` says of each run and group beside the calibrated W (SPEC 11): the data
check of every fitted model, each run's feedforward evidence against its own forcing set's twins,
the group's verdict, and the group's parameters from the runs that determine them."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import pyarrow as pa

from hcid import hcfit, tables
from hcid.config import Config, Loop
from hcid.errors import DataError
from hcid.hcfit.consistency import consistency, group_consistency
from hcid.hcfit.determined import is_flagged, is_undetermined, reason
from hcid.hcfit.lines import record_lines
from hcid.loop.hcmodel import plant
from hcid.pipeline.execution import Execution
from hcid.pipeline.line_statistics import LINE_STATISTICS, twin_statistics_of
from hcid.selection.calibration import (
    binomial_summary,
    count_power,
    evidence_power,
    feedforward_threshold,
    run_p_value,
    sequential_settled,
)

if TYPE_CHECKING:  # the type only: the report reads this module without the twins' machinery
    from hcid.pipeline.twins import FbDraws, TwinSets

__all__ = [
    "EXCEEDANCES",
    "MAX_FB_TWINS",
    "MIN_POWER",
    "STATISTICS",
    "TIE_ORDER",
    "Checks",
    "Evidence",
    "ParameterSummary",
    "consistency_columns",
    "decide",
    "determines",
    "group_name",
    "group_verdict",
    "most_powerful",
    "summarise_parameters",
]

#: Below this power the twins cannot tell a run's feedforward from none (SPEC 11).
MIN_POWER = 0.8
#: FB twins are drawn until this many show at least a run's statistic (Besag and Clifford 1991;
#: then p = EXCEEDANCES / draws) or the most are drawn. 5 at the most draws' 99 decides every run
#: at alpha = 0.05 as a p-value of all 99 would: one stopped early has p >= 5/98 > 0.05.
EXCEEDANCES = 5
#: The most FB twins per forcing set by default: the count's p down to 1/100, and below it, for a
#: run beyond every twin, their generalized Pareto tail (run_p_value). 39 keep the level and, on
#: 43 sets of real twins, the power at 0.05 of 99 on average, but on the CPHS `fo` recordings
#: 2 of the direct method's 3 runs at p <= 0.05 lose it (docs/methodology.md, "p-values from few
#: twins"): judged on the real recordings, the default stays 99.
MAX_FB_TWINS = 99
#: The statistics of a run's evidence, by name in the tables: (p-value, power) columns.
STATISTICS = {
    "W*": ("p_w_star", "power_w_star"),
    **{name: (f"p_{stem}", f"power_{stem}") for name, (_, stem) in LINE_STATISTICS.items()},
}
#: On a tie of their calibration twins' power, the first of these decides: W*, the paper's
#: statistic, then the likelihood ratio before the Fourier size, whose power is the least on every
#: study measured (docs/measured-studies.md): with 20 FB twins a power of 1.00 is often a tie, and
#: the Fourier size's can be a lucky one (0.35 over 99 twins).
TIE_ORDER = ("W*", "likelihood ratio", "Fourier coefficients")


def most_powerful(powers: Mapping[str, float]) -> str:
    """The statistic of the highest power (name -> power); on a tie the first of :data:`TIE_ORDER`.

    Examples
    --------
    >>> most_powerful({"W*": 0.15, "Fourier coefficients": 1.0, "likelihood ratio": 1.0})
    'likelihood ratio'
    >>> most_powerful({"W*": 1.0, "Fourier coefficients": 1.0, "likelihood ratio": 1.0})
    'W*'
    """
    return max(powers, key=lambda name: (powers[name], -TIE_ORDER.index(name)))


def group_name(by: Sequence[str], key: tuple[str, ...]) -> str:
    """A group's name in the tables: ``condition=pursuit``, or ``all runs`` without ``--by``."""
    return ", ".join(f"{f}={v}" for f, v in zip(by, key, strict=True)) or "all runs"


# --------------------------------------------------------------------------- the data check


class Checks:
    """Every run at its forcing lines, read once, for the consistency of any model with it (SPEC
    11); ``problem(members)`` says why some run (or the group) has no test. ``loops``: each run's
    loop where the runs' plants differ (:mod:`hcid.pipeline.plants`; a group's runs share one),
    else the config's."""

    def __init__(self, config: Config, records: dict, loops: Mapping[int, Loop] | None = None):
        loops = dict.fromkeys(records, config.loop) if loops is None else loops
        self.yc_of = {run: plant(loops[run]) for run in records}
        self.rate = config.timing.output_rate
        self.records = records
        self.lines, self.problems = {}, {}
        for run, record in records.items():
            try:
                self.lines[run] = record_lines(record, self.rate)
            except DataError as exc:
                self.problems[run] = f"no test: {exc}"

    def problem(self, members) -> str:
        """Why some run of ``members`` has no test (the first such run's reason), else ""."""
        return next((self.problems[s] for s in members if s in self.problems), "")

    def run(self, run: int, fit):
        """The run's own fit against its data; the lines estimator's free parameters, fitted to
        these lines, are taken off the degrees of freedom."""
        if run not in self.lines:
            return None
        fitted = len(fit.names) - len(fit.fixed) if fit.target == "lines" else 0
        yc = self.yc_of[run]
        return consistency(fit.values, yc, self.lines[run], self.records[run], self.rate, fitted)

    def group(self, members: list[int], values: dict) -> tuple[object, str]:
        """The group's model against its runs together, and why there is no test where there is
        none (a run's problem, or the group's own)."""
        if not all(s in self.lines for s in members):
            return None, self.problem(members)
        try:
            lines, records = [self.lines[s] for s in members], [self.records[s] for s in members]
            return group_consistency(values, self.yc_of[members[0]], lines, records, self.rate), ""
        except DataError as exc:
            return None, f"no test: {exc}"


def consistency_columns(check, problem: str) -> dict:
    """The tables' consistency columns of a check (:class:`hcid.hcfit.consistency.Consistency`),
    or of none, with the reason as its verdict."""
    if check is None:
        nan = math.nan
        return {
            "fc_chi2": nan,
            "fc_dof": 0,
            "fc_p": nan,
            "fc_verdict": problem,
            "fc_spread": "",
            "he_error_db": nan,
            "he_error_deg": nan,
            "ht_error_db": nan,
            "ht_error_deg": nan,
        }
    return {
        "fc_chi2": check.chi2,
        "fc_dof": check.dof,
        "fc_p": check.p,
        "fc_verdict": check.verdict,
        "fc_spread": check.spread,
        "he_error_db": check.he_db,
        "he_error_deg": check.he_deg,
        "ht_error_db": check.ht_db,
        "ht_error_deg": check.ht_deg,
    }


# --------------------------------------------------------------------------- each run's evidence


class _Draw(NamedTuple):
    """One draw of more FB twins of a group's forcing set: how many, their W* per identified
    method, and their folder."""

    count: int
    w_star: dict[str, np.ndarray]
    folder: str


@dataclass(frozen=True, eq=False)
class Evidence:
    """Each run's statistics against its own forcing set's twins (SPEC 11): its W* and its line
    statistics (:data:`LINE_STATISTICS`), each with its sequential p-value (:data:`EXCEEDANCES`,
    at most ``max_fb`` FB twins) and its twins' power.

    A frozen value: :meth:`with_calibration_lines` and :meth:`with_draws` return a new one with
    more of the twins' statistics (step 4 builds it so, round by round); steps 5 and 6 only read
    it. The twins' line statistics are computed once per twin folder whatever the number of runs
    they judge, from the group's model in the group's plant's loop (``starts``: group name ->
    (the group's config, its model values, its runs' deviations from them: each twin's start is
    as far from its truth as a run's from its own optimum,
    :func:`hcid.pipeline.line_statistics.twin_statistics`), as the runs' own); FB twins drawn
    beyond the calibration's are kept per group and forcing set, shared by the group's own and
    study twins (whose FB twin is the same loop). ``tail_below``: a run beyond every FB twin is
    settled once their tail puts its p this low
    (:func:`hcid.selection.calibration.sequential_settled`); None draws on to ``max_fb``."""

    config: Config
    run_dir: Path
    alpha: float
    max_fb: int
    starts: Mapping[str, tuple[Config, dict, list]]
    execution: Execution
    tail_below: float | None = None
    #: (group, twin folder) -> model -> statistic -> values (a group's start makes them).
    folder_lines: Mapping[tuple[str, str], dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)
    #: (group, forcing set) -> its draws of more FB twins, in order.
    more: Mapping[tuple[str, int], tuple[_Draw, ...]] = field(default_factory=dict)

    @functools.cached_property
    def lo(self) -> float:
        return float(min(self.config.selection.w_grid))

    @functools.cached_property
    def hi(self) -> float:
        return float(max(self.config.selection.w_grid))

    def w_star(self, path, nb_ft) -> float:
        return feedforward_threshold(path, nb_ft, self.lo, self.hi)

    def thresholds(self, twin, method: str) -> dict[str, np.ndarray]:
        """The FB and FF twins' W* of one twin folder under one method."""
        return {
            name: np.array([self.w_star(p, n) for p, n in zip(twins.paths, twins.nb_ft, strict=True)])
            for name, twins in zip(("FB", "FF"), twin.paths[method], strict=True)
        }

    def _folder_lines(self, group: str, folder: str) -> dict[str, dict[str, np.ndarray]]:
        return self.folder_lines[(group, folder)]

    def _with_folders(self, folders: Sequence[tuple[str, str, dict | None]]) -> dict:
        """:attr:`folder_lines` with those of every ``(group, twin folder, its records or None)``
        not yet computed, in one pool (:func:`hcid.pipeline.line_statistics.twin_statistics_of`):
        from the records held where this command simulated them, else read from the folder."""
        missing = {}
        for group, folder, held in folders:
            if (group, folder) not in self.folder_lines and (group, folder) not in missing:
                missing[(group, folder)] = held
        items = []
        for (group, folder), held in missing.items():
            config, start, offsets = self.starts[group]
            items.append((self.run_dir / folder, config, start, offsets, held))
        found = twin_statistics_of(items, self.execution) if items else []
        return {**self.folder_lines, **dict(zip(missing, found, strict=True))}

    def with_calibration_lines(self, twins: Sequence[tuple[str, TwinSets]]) -> Evidence:
        """With the line statistics of every forcing set's calibration twins of ``(group, TwinSets)``."""
        folders = [
            (g, folder, held)
            for g, used in twins
            for t in used.sets
            for folder, held in ((t.folder, t.records), (t.fb_folder, t.fb_records))
            if folder
        ]
        return dataclasses.replace(self, folder_lines=self._with_folders(folders))

    def lines(self, group: str, twin) -> dict[str, dict[str, np.ndarray]] | None:
        """The calibration twins' line statistics: statistic -> ``FB`` / ``FF`` -> values; None
        where the forcing has no lines."""
        own = self._folder_lines(group, twin.folder)
        fb = self._folder_lines(group, twin.fb_folder) if twin.fb_folder else own
        if "FF" not in own or "FB" not in fb:
            return None
        return {name: {"FB": fb["FB"][name], "FF": own["FF"][name]} for name in LINE_STATISTICS}

    def with_draws(self, drawn: Sequence[tuple[str, int, FbDraws, bool]]) -> Evidence:
        """With one round of more FB twins, each ``(group, forcing set, its draws, whether a line
        statistic decides there)``, in order: their W* computed once, here, and where asked their
        line statistics, every set's in one pool, from the simulations just made (which are not
        kept)."""
        more = dict(self.more)
        for group, forcing_set, draws, _ in drawn:
            w = {
                m: np.array([self.w_star(p, n) for p, n in zip(fb.paths, fb.nb_ft, strict=True)])
                for m, fb in draws.paths.items()
            }
            more[(group, forcing_set)] = (
                *more.get((group, forcing_set), ()),
                _Draw(draws.count, w, draws.folder),
            )
        lines = self._with_folders([(g, d.folder, d.records) for g, _, d, lines in drawn if lines])
        return dataclasses.replace(self, folder_lines=lines, more=more)

    def drawn(self, group: str, forcing_set: int, twin) -> int:
        """FB twins simulated so far for a group's forcing set (the next draw's first seed - 1)."""
        more = self.more.get((group, forcing_set), ())
        return len(next(iter(twin.paths.values())).fb.paths) + sum(d.count for d in more)

    def fb_thresholds(self, group: str, forcing_set: int, twin, method: str) -> np.ndarray:
        """Every FB twin's W* under ``method`` in the order drawn: the calibration's, then the
        draws that identified ``method`` (up to the first that did not: it was settled there)."""
        out = [self.thresholds(twin, method)["FB"]]
        for draw in self.more.get((group, forcing_set), ()):
            if method not in draw.w_star:
                break
            out.append(draw.w_star[method])
        return np.concatenate(out)

    def fb_lines(
        self, group: str, forcing_set: int, twin, drawn: bool = True
    ) -> dict[str, np.ndarray] | None:
        """Every FB twin's line statistics in the order drawn (statistic -> values); the
        calibration's only unless ``drawn`` (the draws' statistics, computed by :meth:`with_draws`
        where a line statistic decides: only then are they asked for)."""
        base = self.lines(group, twin)
        if base is None:
            return None
        draws = self.more.get((group, forcing_set), ()) if drawn else ()
        more = [self._folder_lines(group, d.folder) for d in draws]
        return {
            name: np.concatenate([base[name]["FB"], *(m["FB"][name] for m in more if "FB" in m)])
            for name in LINE_STATISTICS
        }

    def used(self, group: str, forcing_set: int, twin, method: str, deciding: str):
        """The FB twins' W* and line statistics in the order drawn, as the run's p-values use
        them: the deciding statistic's every draw, the others' the calibration's only (:meth:`run`)."""
        base = len(self.thresholds(twin, method)["FB"])
        w = self.fb_thresholds(group, forcing_set, twin, method)
        lines = self.fb_lines(group, forcing_set, twin, drawn=deciding in LINE_STATISTICS)
        if deciding != "W*":
            w = w[:base]
        if lines is not None:
            lines = {name: v if name == deciding else v[:base] for name, v in lines.items()}
        return w, lines

    def statistic(self, group: str, used: TwinSets, method: str) -> str:
        """Which statistic decides for a group and method (a name of :data:`STATISTICS`): the one
        whose calibration twins give the highest median power over the group's runs (each run its
        forcing set's); on a tie the first of :data:`TIE_ORDER` (W* where the forcing has no
        lines). From the twins alone, before any run's value is read and before more FB twins are
        drawn (only its p-values are drawn for)."""
        powers: dict[str, list[float]] = {name: [] for name in STATISTICS}
        for twin, runs in zip(used.sets, used.runs, strict=True):
            w, lines = self.thresholds(twin, method), self.lines(group, twin)
            powers["W*"] += [evidence_power(w["FF"], w["FB"], self.alpha)] * len(runs)
            for name in LINE_STATISTICS:
                power = (
                    evidence_power(lines[name]["FF"], lines[name]["FB"], self.alpha) if lines else math.nan
                )
                powers[name] += [power] * len(runs)
        median = {name: float(np.median(v)) for name, v in powers.items() if np.isfinite(v).all()}
        return most_powerful(median)

    def unsettled(self, group: str, forcing_set: int, twin_of: dict, deciding: dict, runs: list):
        """What more FB twins of a group's forcing set are drawn for: the methods (``twin_of``:
        method -> twins) that W* decides (``deciding``: method -> statistic) and under which some
        run (``runs``: (W* by method, line statistics)) has a p-value more twins could change;
        and whether a line statistic decides somewhere and has such a run."""
        methods_open = []
        for m, twin in twin_of.items():
            if deciding[m] != "W*":
                continue
            fb = self.fb_thresholds(group, forcing_set, twin, m)  # once for all the set's runs
            if any(
                not sequential_settled(w[m], fb, EXCEEDANCES, self.max_fb, self.tail_below) for w, _ in runs
            ):
                methods_open.append(m)
        line_deciding = [name for name in LINE_STATISTICS if name in deciding.values()]
        fb = self.fb_lines(group, forcing_set, next(iter(twin_of.values()))) if line_deciding else None
        lines_open = fb is not None and any(
            values is not None
            and not sequential_settled(values[name], fb[name], EXCEEDANCES, self.max_fb, self.tail_below)
            for name in line_deciding
            for _, values in runs
        )
        return methods_open, lines_open

    def run(
        self,
        group: str,
        w_star: float,
        used: TwinSets,
        run: int,
        method: str,
        run_lines: dict | None,
        deciding: str,
    ) -> dict:
        """The run's evidence columns from its W* (:meth:`w_star`) and its line statistics
        (``run_lines``, :func:`hcid.pipeline.line_statistics.record_statistics`; ``decide`` adds
        the deciding ones). The ``deciding`` statistic's p-value is over every FB twin drawn for
        it (each run stops at its own 5th, or all were drawn: Besag and Clifford's p); the others'
        over the calibration's FB twins only, a fixed number, since how many more were drawn
        depended on the deciding statistic. Each power is over the same FB twins as its p-value:
        the deciding one's then estimates the power of the test actually made (p <= alpha against
        up to all the draws) more precisely than the calibration's 20 can (the largest of 20 FB
        twins stands for their 95% quantile)."""
        own = used.of_run(run)
        forcing_set = used.sets.index(own) + 1
        fb, fb_lines = self.used(group, forcing_set, own, method, deciding)
        p_w, n_w, how_w = run_p_value(w_star, fb, EXCEEDANCES)
        out = {
            "forcing_set": forcing_set,
            "w_star": w_star,
            "p_w_star": p_w,
            "p_w_star_method": how_w,
            "power_w_star": evidence_power(self.thresholds(own, method)["FF"], fb, self.alpha),
            "fb_twins_w_star": n_w,
        }
        lines = self.lines(group, own)
        for name, (column, stem) in LINE_STATISTICS.items():
            cells = (math.nan, math.nan, "", math.nan, 0)
            if lines is not None and run_lines is not None:
                p, n, how = run_p_value(run_lines[name], fb_lines[name], EXCEEDANCES)
                cells = (
                    run_lines[name],
                    p,
                    how,
                    evidence_power(lines[name]["FF"], fb_lines[name], self.alpha),
                    n,
                )
            out.update(
                zip(
                    (column, f"p_{stem}", f"p_{stem}_method", f"power_{stem}", f"fb_twins_{stem}"),
                    cells,
                    strict=True,
                )
            )
        return out

    def twins_table(
        self, groups: dict, by: Sequence[str], evidence: dict, used: Mapping[tuple, Mapping[str, TwinSets]]
    ) -> pa.Table:
        """``evidence_twins.parquet``: the twins each group's runs were judged against (their W* and
        line statistics, as the p-values used them), once per group, method and forcing set (in
        the order of the groups and their runs); ``used``: each group's twins per method."""
        rows, done = [], set()
        for key, members in groups.items():
            name = group_name(by, key)
            for (run, method), e in sorted(evidence.items()):
                judged = (name, method, e["forcing_set"])
                if run not in members or judged in done:
                    continue
                done.add(judged)
                twin, forcing_set = used[key][method].of_run(run), e["forcing_set"]
                lines = self.lines(name, twin)
                fb_w, fb_lines = self.used(name, forcing_set, twin, method, e["decided_by"])
                drawn = {
                    "FB": (fb_w, fb_lines),
                    "FF": (
                        self.thresholds(twin, method)["FF"],
                        lines and {k: v["FF"] for k, v in lines.items()},
                    ),
                }
                for kind, (w_stars, values) in drawn.items():
                    columns = {"w_star": w_stars}
                    columns.update(
                        (col, (values or {}).get(stat)) for stat, (col, _) in LINE_STATISTICS.items()
                    )
                    columns = {c: np.full(0, math.nan) if v is None else v for c, v in columns.items()}
                    n = max(v.size for v in columns.values())
                    columns = {
                        c: np.pad(v, (0, n - v.size), constant_values=math.nan) for c, v in columns.items()
                    }
                    rows += [
                        {
                            "group": name,
                            "method": method,
                            "forcing_set": forcing_set,
                            "twin": kind,
                            "seed": i + 1,
                            **{c: float(v[i]) for c, v in columns.items()},
                        }
                        for i in range(n)
                    ]
        return pa.Table.from_pylist(rows, schema=tables.EVIDENCE_TWINS.arrow)


def decide(rows: list[dict], alpha: float, statistic: str) -> None:
    """Each row of a group and method gets the deciding ``statistic``'s (:meth:`Evidence.statistic`)
    ``decided_by``, ``p_value``, ``power`` and ``evidence``."""
    p_col, power_col = STATISTICS[statistic]
    for r in rows:
        r.update(
            decided_by=statistic,
            p_value=r[p_col],
            p_method=r[f"{p_col}_method"],
            power=r[power_col],
            evidence="feedforward" if r[p_col] <= alpha else "none shown",
        )


#: A group's verdict where its runs show feedforward (beside UNCERTAIN and NO FEEDFORWARD SHOWN).
FEEDFORWARD = "FEEDFORWARD"


def group_verdict(rows: list[dict], alpha: float) -> dict:
    """A group's (or subject's) summary over its runs: k of n with p <= alpha against the binomial,
    the runs' median power, the power of that binomial test (:func:`count_power`: were every run's
    feedforward its FF twins', the chance the count would be significant), and the verdict word:
    FEEDFORWARD where the count is significant, else UNCERTAIN where the test's power is below
    :data:`MIN_POWER`, else NO FEEDFORWARD SHOWN (a run without a p counts among the n, never
    found). The verdict is the count's test, so its power is
    the one to read: six runs each found with a power of 0.5 make a test of power 0.89, two of 0.8
    one of 0.64."""
    p_values = np.array([r["p_value"] for r in rows], dtype=np.float64)
    k, n, p = binomial_summary(p_values, alpha)
    powers = np.array([r["power"] for r in rows], dtype=np.float64)
    power = float(np.median(powers))
    # A run without a p (no value of the statistic) is one of the n and is never found: power 0.
    test_power = count_power(np.where(np.isnan(p_values), 0.0, powers), alpha)
    if p <= alpha:
        verdict = FEEDFORWARD
    elif not test_power >= MIN_POWER:  # NaN (no FF twin has the statistic): no power shown either
        verdict = "UNCERTAIN"
    else:
        verdict = "NO FEEDFORWARD SHOWN"
    return {
        "verdict": verdict,
        "n_evidence": k,
        "binomial_p": p,
        "median_power": power,
        "group_power": test_power,
        "alpha": alpha,
    }


# --------------------------------------------------------------------------- the group's parameters


@dataclass(frozen=True)
class ParameterSummary:
    """One parameter over a group's runs (rows of ``analysis.parquet``), from the runs that
    determine it (SPEC 11): ``median``, ``sd`` (over those runs) and ``median_se`` (NaN where
    none or one), ``kept`` of ``fitted`` runs, ``left_out``: ``{reason: runs}``, and ``flagged``:
    ``{flag: runs}`` among the kept (outside the plausible range, not told from 0)."""

    name: str
    unit: str
    fitted: int
    kept: int
    median: float
    sd: float
    median_se: float
    left_out: dict
    flagged: dict = field(default_factory=dict)


def determines(row: dict, p: str) -> bool:
    """Whether a run's fit determines parameter ``p`` (SPEC 11: not undetermined; a flagged value
    is kept) and gave it a value (a fit that failed, ``not fitted: ...``, gives NaN)."""
    return not is_undetermined(row[f"{p}_status"]) and math.isfinite(row[p])


def summarise_parameters(
    rows: Sequence[dict], names: Sequence[str] = tables.HC_PARAMETER_NAMES
) -> list[ParameterSummary]:
    """The parameters ``names`` over runs as the answer lines and the report give them (one home
    for the groups' and the disturbance-only runs' feedback alone)."""
    out = []
    for p in names:
        fitted = [r for r in rows if not r[f"{p}_status"].startswith("not fitted")]
        if not fitted:
            continue
        kept = [r for r in fitted if determines(r, p)]
        x = np.array([r[p] for r in kept], dtype=float)
        se = np.array([r[f"{p}_se"] for r in kept], dtype=float)
        left: dict[str, int] = {}
        flagged: dict[str, int] = {}
        for r in fitted:
            status = r[f"{p}_status"]
            if is_undetermined(status):
                left[reason(status)] = left.get(reason(status), 0) + 1
            elif is_flagged(status):
                flagged[status] = flagged.get(status, 0) + 1
        out.append(
            ParameterSummary(
                name=p,
                unit=hcfit.UNITS[p],
                fitted=len(fitted),
                kept=int(x.size),
                median=float(np.median(x)) if x.size else math.nan,
                sd=float(np.std(x, ddof=1)) if x.size > 1 else math.nan,
                median_se=float(np.median(se[np.isfinite(se)])) if np.isfinite(se).any() else math.nan,
                left_out=left,
                flagged=flagged,
            )
        )
    return out
