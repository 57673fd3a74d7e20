"""``hcid analyse`` on a whole experiment: each run's condition kind from its data, and every
condition combined per person (SPEC 12; :mod:`hcid.analysis.conditions` computes).

Two-input runs go through the analysis of feedforward (identification, twins, p-values);
every run, whatever its kind, goes into the combination per person: the responses at every
line, the feedback and feedforward paths and the model inversion |Ht Yc|, and the study's
comparisons (model inversion by band, superposition, prediction across conditions), written
as ``session_trials``, ``session_lines`` and ``session_findings`` (docs/tables.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import api, hcfit, methods, tables
from hcid.analysis import conditions
from hcid.analysis.conditions import Kind, PersonLines, TrialLines
from hcid.analysis.descriptors import loop_margins
from hcid.config import Config, IdentifyConfig
from hcid.config.fit_settings import FEEDBACK_PARAMETERS
from hcid.errors import ConfigError, DataError, HcidError
from hcid.io import folders, results
from hcid.io.datasets import DataSet
from hcid.loop.hcmodel import plant
from hcid.pipeline.fit_hc import tracking_record

__all__ = [
    "BANDS",
    "PERSON",
    "Session",
    "classify",
    "combine_session",
    "is_whole_experiment",
    "person_factor",
    "subset",
    "write_session",
]

#: The factor that names a person, by default (``--person``).
PERSON = "subject"
#: ``person`` of a row over every person (the findings' summaries across people).
ALL_PEOPLE = "all people"
#: ``person`` of every run where the data set names no person: one person, said so.
ONE_PERSON = "one person (no person factor)"
#: The study's bands of the model inversion (Hz): "close to the inverse up to 0.15 Hz, lower from
#: 0.25 Hz up" (CPHS 2017's finding); a line belongs to a band when within 1e-6 Hz of it.
BANDS = {"up to 0.15 Hz": (0.0, 0.15), "from 0.25 Hz": (0.25, math.inf)}
_PREDICTIONS = {
    Kind.TWO_INPUT: "single-input trials",
    Kind.TARGET_ONLY: "two-input trials",
    Kind.DISTURBANCE_ONLY: "two-input trials",
}


def classify(data: DataSet, config: Config) -> dict[int, TrialLines]:
    """Each run's kind and lines over the analysis window (:func:`hcid.analysis.conditions.trial_lines`).

    Raises
    ------
    DataError
        For a run with neither a target nor a disturbance (its file named).
    """
    rate, n = config.timing.output_rate, config.timing.record_samples
    files = {int(r["run"]): r["file"] for r in data.runs}
    out = {}
    for run_id, record in data.records.items():
        trial = conditions.trial_lines(record, rate, n)
        if trial.kind is None:
            raise DataError(f"{files.get(run_id, 'data')}: run {run_id}: {trial.problem}: nothing to analyse")
        out[run_id] = trial
    return out


def check_factors(factors: Sequence[str], person: str | None) -> None:
    """Refuse a factor named like a column of ``session_trials.parquet`` (other than the person
    factor named ``person``), before any work.

    Raises
    ------
    ConfigError
        Naming the factor.
    """
    taken = sorted(set(factors) & set(tables.SESSION_TRIALS.names) - {person})
    if taken:
        raise ConfigError(
            f"factor {taken[0]!r}: the whole experiment's tables have a column of that name; rename "
            "the factor (data.pattern, the manifest's header or data.dimensions)"
        )


def person_factor(data: DataSet, person: str | None) -> str | None:
    """The factor naming people (``--person``; default :data:`PERSON` where the data set
    has it, else None: one person)."""
    if person is None:
        return PERSON if PERSON in data.factors else None
    if person not in data.factors:
        raise ConfigError(
            f"--person {person}: the data set has no factor {person!r} (its factors: "
            f"{', '.join(data.factors) or 'none'})"
        )
    return person


def subset(data: DataSet, run_ids: Sequence[int]) -> DataSet:
    """The data set's runs ``run_ids``, their ids and factors kept."""
    keep = set(run_ids)
    return replace(
        data,
        records={s: r for s, r in data.records.items() if s in keep},
        runs=[r for r in data.runs if int(r["run"]) in keep],
    )


def is_whole_experiment(trials: Mapping[int, TrialLines]) -> bool:
    """Whether the runs mix conditions that combine: a single-input run, or lines swapped between
    two-input runs (otherwise the analysis of feedforward answers alone)."""
    kinds = {t.kind for t in trials.values()}
    return kinds != {Kind.TWO_INPUT} or conditions.swapped([t for t in trials.values() if t.problem is None])


@dataclass(frozen=True)
class Session:
    """What the combination found: the three tables it writes."""

    trials: pa.Table
    lines: pa.Table
    findings: pa.Table
    person: str | None
    #: The disturbance-only runs' feedback alone (``feedback_runs.parquet``; None without them).
    feedback: pa.Table | None = None


def _lines_text(trial: TrialLines, bins: np.ndarray) -> str:
    return ";".join(f"{w:.4g}" for w in trial.omega(bins))


def _in_band(hz: np.ndarray, band: str) -> np.ndarray:
    low, high = BANDS[band]
    return (hz >= low - 1e-6) & (hz <= high + 1e-6)


def _line_rows(person: str, source: str, p: PersonLines) -> list[dict]:
    def db(h):
        return 20.0 * np.log10(np.abs(h))

    def deg(h):
        return np.degrees(np.angle(h))

    rows = []
    for i, omega in enumerate(p.omega):
        runs = p.inversion_runs[i]
        q25, q75 = np.percentile(runs, [25.0, 75.0]) if runs.size else (math.nan, math.nan)
        rows.append(
            {
                "person": person,
                "source": source,
                "omega": float(omega),
                "hz": float(omega / (2 * np.pi)),
                "h_ur_db": float(db(p.h_ur[i])),
                "h_ur_deg": float(deg(p.h_ur[i])),
                "h_ud_db": float(db(p.h_ud[i])),
                "h_ud_deg": float(deg(p.h_ud[i])),
                "he_db": float(db(p.he[i])),
                "he_deg": float(deg(p.he[i])),
                "ht_db": float(db(p.ht[i])),
                "ht_deg": float(deg(p.ht[i])),
                "inversion": float(np.abs(p.inversion[i])),
                "inversion_deg": float(deg(p.inversion[i])),
                "inversion_q25": float(q25),
                "inversion_q75": float(q75),
                "he_measured": bool(p.he_measured[i]),
                "n_target_trials": int(p.n_target[i]),
                "n_disturbance_trials": int(p.n_disturbance[i]),
            }
        )
    return rows


def _median_rows(source: str, people: list[PersonLines]) -> list[dict]:
    """Per line, the median over people of each magnitude and the circular mean of each phase."""
    rows = []
    for i, omega in enumerate(people[0].omega):
        row = {"person": "median", "source": source, "omega": float(omega), "hz": float(omega / (2 * np.pi))}
        for name, attr in (("h_ur", "h_ur"), ("h_ud", "h_ud"), ("he", "he"), ("ht", "ht")):
            h = np.array([getattr(p, attr)[i] for p in people])
            ok = np.isfinite(h)
            row[f"{name}_db"] = float(np.median(20.0 * np.log10(np.abs(h[ok])))) if ok.any() else math.nan
            row[f"{name}_deg"] = (
                float(np.degrees(np.angle(np.mean(h[ok] / np.abs(h[ok]))))) if ok.any() else math.nan
            )
        inv = np.array([p.inversion[i] for p in people])
        ok = np.isfinite(inv)
        mags = np.abs(inv[ok])
        row["inversion"] = float(np.median(mags)) if ok.any() else math.nan
        row["inversion_deg"] = float(np.degrees(np.angle(np.mean(inv[ok] / mags)))) if ok.any() else math.nan
        row["inversion_q25"], row["inversion_q75"] = (
            (float(mags.min()), float(mags.max())) if ok.any() else (math.nan, math.nan)
        )
        row["he_measured"] = bool(all(p.he_measured[i] for p in people))
        row["n_target_trials"] = int(sum(p.n_target[i] for p in people))
        row["n_disturbance_trials"] = int(sum(p.n_disturbance[i] for p in people))
        rows.append(row)
    return rows


def _finding(finding, person, source, quantity, band, omega, estimate, low, high, spread, p, test, n) -> dict:
    return {
        "finding": finding,
        "person": person,
        "source": source,
        "quantity": quantity,
        "band": band,
        "omega": float(omega),
        "estimate": float(estimate),
        "low": float(low),
        "high": float(high),
        "spread": spread,
        "p": float(p),
        "test": test,
        "n": int(n),
    }


def _inversion_findings(combined: dict[str, dict[str, PersonLines]]) -> list[dict]:
    """Per source and band: each person's median |Ht Yc| over the band's lines, the median over
    people with their range, and a Wilcoxon signed-rank test of log |Ht Yc| against 0 (the exact
    inverse) over every person's lines in the band."""
    rows = []
    nan = math.nan
    for source, people in combined.items():
        for band in BANDS:
            medians, pooled = [], []
            for person, p in people.items():
                inv = np.abs(p.inversion[_in_band(p.omega / (2 * np.pi), band)])
                inv = inv[np.isfinite(inv)]
                if not inv.size:
                    continue
                medians.append(float(np.median(inv)))
                pooled.append(np.log(inv))
                rows.append(
                    _finding(
                        "model inversion",
                        person,
                        source,
                        "|Ht Yc| median over lines",
                        band,
                        nan,
                        medians[-1],
                        inv.min(),
                        inv.max(),
                        "range over lines",
                        nan,
                        "",
                        inv.size,
                    )
                )
            if medians:
                logs = np.concatenate(pooled)
                rows.append(
                    _finding(
                        "model inversion",
                        ALL_PEOPLE,
                        source,
                        "|Ht Yc| median over people",
                        band,
                        nan,
                        np.median(medians),
                        min(medians),
                        max(medians),
                        "range over people",
                        conditions.wilcoxon_p(logs),
                        f"Wilcoxon signed-rank of log |Ht Yc| against 0 over {logs.size} person-lines "
                        "(not independent: a person's lines share a model)",
                        len(medians),
                    )
                )
    return rows


def _superposition_findings(combined: dict[str, dict[str, PersonLines]]) -> list[dict]:
    single, two = combined.get("single-input trials", {}), combined.get("two-input trials", {})
    people = sorted(set(single) & set(two))
    if not people:
        return []
    rows = []
    test = "Wilcoxon signed-rank, paired across people"
    for c in conditions.superposition([single[p] for p in people], [two[p] for p in people]):
        band = "pooled over lines" if math.isnan(c.omega) else ""
        rows.append(
            _finding(
                "superposition",
                ALL_PEOPLE,
                "single-input / two-input trials",
                f"{c.response} magnitude ratio",
                band,
                c.omega,
                c.ratio,
                c.ratio_low,
                c.ratio_high,
                "range over pairs",
                c.p_magnitude,
                test + " (log magnitude)",
                c.pairs,
            )
        )
        rows.append(
            _finding(
                "superposition",
                ALL_PEOPLE,
                "single-input / two-input trials",
                f"{c.response} phase difference deg",
                band,
                c.omega,
                c.phase,
                c.phase_low,
                c.phase_high,
                "range over pairs",
                c.p_phase,
                test + " (phase, wrapped)",
                c.pairs,
            )
        )
    return rows


#: The prediction's findings: (quantity, where it is counted, the trial's numerator and
#: denominator columns, or its one column with no denominator).
_PREDICTION_QUANTITIES = (
    ("error, feedback only", "window", "error_fb", None),
    ("error, feedback and feedforward", "window", "error_ff", None),
    ("error ratio (feedback and feedforward / feedback only)", "window", "error_ff", "error_fb"),
    ("error ratio at the lines", "lines", "lines_error_ff", "lines_error_fb"),
)


def _prediction_findings(trial_rows: list[dict]) -> list[dict]:
    """Per direction and person: the median over trials of each error and of the ratio
    (feedback plus feedforward over feedback-only), with their range over trials; over people,
    the median of the people's ratios with their range. A disturbance-only trial (no target: both
    models predict alike) is left out."""
    nan = math.nan
    directions: dict[str, dict[str, list[dict]]] = {}
    for r in trial_rows:
        if r["predicted_by"] and r["kind"] != Kind.DISTURBANCE_ONLY.value:
            direction = f"{r['predicted_by']} -> {_to(r['kind'])}"
            directions.setdefault(direction, {}).setdefault(r["person"], []).append(r)
    rows = []
    for direction, people in directions.items():
        ratios: dict[tuple[str, str], list[float]] = {}
        for person, members in people.items():
            for what, where, num, den in _PREDICTION_QUANTITIES:
                values = np.array([m[num] / (m[den] if den else 1.0) for m in members])
                rows.append(
                    _finding("prediction", person, direction, what, where, nan, np.median(values),
                             values.min(), values.max(), "range over trials", nan, "", values.size)
                )  # fmt: skip
                if den:
                    ratios.setdefault((what, where), []).append(float(np.median(values)))
        for (what, where), values in ratios.items():
            v = np.array(values)
            rows.append(
                _finding("prediction", ALL_PEOPLE, direction, what, where, nan, np.median(v), v.min(),
                         v.max(), "range over people", nan, "", v.size)
            )  # fmt: skip
    return rows


def _to(kind: str) -> str:
    return "two-input trials" if kind == Kind.TWO_INPUT.value else f"{kind} trials"


def combine_session(
    config: Config, data: DataSet, trials: Mapping[int, TrialLines], person: str | None, execution=None
) -> Session:
    """Every run combined per person (``person``: the factor naming people; None: one person)
    and plant (the config's): the tables of :mod:`hcid.pipeline.sessions`; with ``execution``
    (:class:`hcid.pipeline.execution.Execution`), also each disturbance-only run's feedback alone
    (:func:`fit_feedback`)."""
    plant_ = config.loop.plant
    num, den = np.asarray(plant_.num, dtype=np.float64), np.asarray(plant_.den, dtype=np.float64)

    def yc_of(omega: np.ndarray) -> np.ndarray:
        s = 1j * np.asarray(omega)
        return np.polyval(num, s) / np.polyval(den, s)

    runs = {int(r["run"]): r for r in data.runs}
    who = {run_id: str(runs[run_id][person]) if person else ONE_PERSON for run_id in trials}
    combined: dict[str, dict[str, PersonLines]] = {}
    people = sorted(set(who.values()))
    # Every person on the study's lines (NaN where a person's trials did not measure one), so that
    # people are compared line by line.
    lined = [t for t in trials.values() if t.problem is None]
    bins = np.array(
        sorted(set().union(*(set(t.target.tolist()) | set(t.disturbance.tolist()) for t in lined)))
    )
    for name in people:
        own = [t for s, t in trials.items() if who[s] == name and t.problem is None]
        if not own:
            continue
        for source in conditions.SOURCES:
            found = conditions.combine(
                conditions.of_kinds(own, source), yc_of, config.loop.disturbance_at, bins
            )
            if found is not None:
                combined.setdefault(source, {})[name] = found
    trial_rows = []
    factors = [f for f in data.factors]
    for run_id in sorted(trials):
        t = trials[run_id]
        row = {
            "data_set": config.data.name,
            "run_id": run_id,
            "file": str(runs[run_id]["file"]),
            "person": who[run_id],
            "kind": t.kind.value,
            "target_lines": _lines_text(t, t.target),
            "disturbance_lines": _lines_text(t, t.disturbance),
            "problem": t.problem or "",
            "predicted_by": "",
            "error_fb": math.nan,
            "error_ff": math.nan,
            "lines_error_fb": math.nan,
            "lines_error_ff": math.nan,
        }
        model = combined.get(_PREDICTIONS[t.kind], {}).get(who[run_id])
        if t.problem is None and model is not None:
            index = {b: i for i, b in enumerate(bins.tolist())}
            unknown = [b for b in t.target.tolist() if not np.isfinite(model.ht[index[b]])]
            if unknown:  # Ht = 0 there would understate the feedforward model: not predicted
                row["problem"] = (
                    f"not predicted: the {_PREDICTIONS[t.kind]}' model has no Ht at {len(unknown)} of "
                    f"its {t.target.size} target lines (none of them measured a target there)"
                )
            else:
                found = conditions.prediction(t, model, bins)
                row.update(
                    predicted_by=_PREDICTIONS[t.kind],
                    error_fb=found.error_fb,
                    error_ff=found.error_ff,
                    lines_error_fb=found.lines_fb,
                    lines_error_ff=found.lines_ff,
                )
        trial_rows.append({**{f: str(runs[run_id][f]) for f in factors}, **row})
    line_rows = []
    for source, by_person in combined.items():
        for name, p in by_person.items():
            line_rows += _line_rows(name, source, p)
        if len(by_person) > 1:
            line_rows += _median_rows(source, list(by_person.values()))
    findings = (
        _inversion_findings(combined) + _superposition_findings(combined) + _prediction_findings(trial_rows)
    )
    feedback = None if execution is None else fit_feedback(config, data.records, trials, who, execution)
    return Session(
        pa.Table.from_pylist(trial_rows),
        pa.Table.from_pylist(line_rows, schema=tables.SESSION_LINES.arrow),
        pa.Table.from_pylist(findings, schema=tables.SESSION_FINDINGS.arrow),
        person,
        feedback,
    )


#: The tables a whole experiment's combination writes.
SESSION_TABLES = (tables.SESSION_TRIALS, tables.SESSION_LINES, tables.SESSION_FINDINGS, tables.FEEDBACK_RUNS)


def forget_session(run_dir, keep: Sequence[tables.Schema] = ()) -> None:
    """Remove an earlier data set's session tables but ``keep`` (data that are not a whole
    experiment now, or without disturbance-only runs), so that the report shows only this one's."""
    names = [t.file for t in SESSION_TABLES if t not in keep and (Path(run_dir) / t.file).is_file()]
    if names:
        folders.remove_owned(Path(run_dir), names)


def write_session(run_dir, session: Session) -> None:
    """The combination's tables, each written atomically."""
    forget_session(run_dir, keep=SESSION_TABLES if session.feedback is not None else SESSION_TABLES[:3])
    results.write(tables.SESSION_TRIALS, session.trials, run_dir)
    results.write(tables.SESSION_LINES, session.lines, run_dir)
    results.write(tables.SESSION_FINDINGS, session.findings, run_dir)
    if session.feedback is not None:
        results.write(tables.FEEDBACK_RUNS, session.feedback, run_dir)


# --------------------------------------------------------------------------- feedback alone


def feedback_settings(identify: IdentifyConfig) -> IdentifyConfig:
    """The study's identification without the target path: every stage's ``nb_ft`` held at 0 (a
    disturbance-only run's ft is 0, so any other candidate has a zero regressor)."""
    stages = tuple((name, replace(st, grid=replace(st.grid, nb1=(0, 0)))) for name, st in identify.stages)
    return replace(identify, stages=stages)


def _feedback_task(config: Config, run_id: int, record: dict, person: str) -> list[dict]:
    """A disturbance-only run's feedback alone: each method's ARX model without the target path
    selected at W_BIC (no feedforward question, so no calibrated W), and the parametric feedback
    path fitted to the run (the config's estimator), with its loop's crossover and phase margin."""
    rate = config.timing.output_rate
    settings = feedback_settings(config.identify)
    signals = {k: record[k] for k in ("t", "ft", "fd", "e", "u")}
    run = api.Record(run_id, rate, **signals)
    yc = plant(config.loop)
    # Over the analysis window, whole periods of the multisine: the lines estimator's lines (a
    # sample more, as a 45 s file at 25 Hz leaves, can smear them below its threshold).
    window = {k: x[: config.timing.record_samples] for k, x in record.items()}
    tracking = tracking_record(window, config)
    fitted = _feedback_fit(config, tracking, yc)
    rows = []
    for method in methods.METHODS:
        row = {"data_set": config.data.name, "run_id": run_id, "person": person, "method": method}
        try:
            found = api.identify(run, method, settings)
            chosen = found.select(found.w_bic)
        except HcidError:  # every candidate unstable: counted, the run's other answers kept
            row.update(w=math.nan, na=None, nb_e=None, nk_e=None, vaf_validation=math.nan)
        else:
            na, _, nb_e, _, nk_e = chosen.orders
            row.update(w=float(found.w_bic), na=int(na), nb_e=int(nb_e), nk_e=int(nk_e))
            row["vaf_validation"] = float(chosen.vaf_validation)
        rows.append({**row, **fitted})
    return rows


def _feedback_fit(config: Config, tracking, yc) -> dict:
    """The feedback path's parametric fit and its loop's margins (a fit that fails: every value
    NaN, its status the reason; the study goes on)."""
    try:
        fit = hcfit.fit_parametric(
            config.fit_hc, yc, False, record=tracking, disturbance_at=config.loop.disturbance_at
        )
        values, status = fit.values, fit.status
        se = dict(zip(fit.names, fit.se or [math.nan] * len(fit.names), strict=True))
        margins = loop_margins(lambda w: hcfit.hc_response(values, yc, w)[1] * yc(1j * w))
    except HcidError as exc:
        nan = math.nan
        fitted = {"fit_target": "", "fit_vaf_validation": nan, "crossover": nan, "phase_margin": nan}
        for p in FEEDBACK_PARAMETERS:
            fitted.update({p: nan, f"{p}_se": nan, f"{p}_status": f"not fitted: {exc}"})
        return fitted
    fitted = {
        "fit_target": fit.target,
        "fit_vaf_validation": float(fit.vaf_validation),
        "crossover": float(margins.crossover),
        "phase_margin": float(margins.phase_margin),
    }
    for p in FEEDBACK_PARAMETERS:
        fitted.update({p: float(values[p]), f"{p}_se": float(se[p]), f"{p}_status": status[p]})
    return fitted


def fit_feedback(
    config: Config, records: Mapping[int, dict], trials: Mapping[int, TrialLines], who: Mapping, execution
) -> pa.Table | None:
    """Every disturbance-only run's feedback alone (:func:`_feedback_task`), on the worker pool;
    ``who`` maps a run to its person. None without such runs."""
    run_ids = [s for s in sorted(trials) if trials[s].kind is Kind.DISTURBANCE_ONLY]
    if not run_ids:
        return None
    tasks = [(config, s, records[s], who[s]) for s in run_ids]
    rows = [row for found in execution.map(_feedback_task, tasks, "feedback alone") for row in found]
    return pa.Table.from_pylist(rows, schema=tables.FEEDBACK_RUNS.arrow)
