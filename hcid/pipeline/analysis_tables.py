"""The tables ``hcid analyse`` writes (:mod:`hcid.pipeline.analyse`, its last step): one row per
run and method (``analysis.parquet``, ``analysis.csv``), per group and method
(``analysis_groups.parquet``), each group's Fourier-coefficient estimates beside its fitted
model (``fc_estimates.parquet``), the FB twins each run's p-value used (``evidence_twins``)
and the files set aside (``set_aside.parquet``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import hcfit, methods, tables
from hcid.analysis.fourier import Inversion, InversionRuns, fc_estimate, off_line_share
from hcid.config import Config
from hcid.errors import DataError
from hcid.hcfit.determined import parameter_status
from hcid.io import folders, results
from hcid.loop.hcmodel import plant
from hcid.pipeline import effects, sessions
from hcid.pipeline.analyse_state import Group, GroupTwins, Selected, Study, Tested
from hcid.pipeline.evidence import (
    MIN_POWER,
    Checks,
    Evidence,
    consistency_columns,
    group_name,
    group_verdict,
)
from hcid.pipeline.sessions import Session
from hcid.selection.calibration import rates_at, separates

__all__ = ["AnalysisTables", "build_tables", "write_analysis"]


@dataclass(frozen=True)
class AnalysisTables:
    """Everything ``hcid analyse`` writes into its run directory beside the identification and
    the twins folders (step 6), as tables: :func:`build_tables` makes them, :func:`write_analysis`
    writes them, each atomically (the analysis's one writer)."""

    groups: pa.Table  # analysis_groups.parquet
    runs: pa.Table  # analysis.parquet and analysis.csv
    fc_estimates: pa.Table
    evidence_twins: pa.Table
    set_aside: pa.Table
    skipped: pa.Table
    session: Session | None = None  # a whole experiment's session tables
    effects: pa.Table | None = None  # study_effects.parquet and .csv (--compare, a whole experiment)


def build_tables(
    study: Study,
    twins: dict[Group, GroupTwins],
    tested: dict[Group, Tested],
    selected: Selected,
    checks: Checks,
    judge: Evidence,
    set_aside: Sequence[tuple[str, str]],
    skipped: Sequence[tuple[str, str]],
) -> AnalysisTables:
    """The analysis tables (a row per run and method, per group and method), the groups'
    Fourier-coefficient estimates, the evidence's twins, and the data set's files set aside and
    skipped (each ``(path, reason)``); nothing written."""
    group_table, run_table = _tables(_Rows(study, twins, tested, selected, checks))
    fc_rows = []
    for key, members in study.groups.items():
        config = study.plants.of_runs(members)  # the group's plant
        name, model = group_name(study.by, key), twins[key].model.values
        fc_rows += _fc_rows(config, name, members, study.records, model)
    evidence = {k: outcome.evidence for k, outcome in selected.runs.items()}
    aside = [{"file": f, "reason": why} for f, why in set_aside]
    left_out = [{"file": f, "reason": why} for f, why in skipped]
    return AnalysisTables(
        group_table,
        run_table,
        pa.Table.from_pylist(fc_rows, schema=tables.FC_ESTIMATES.arrow),
        judge.twins_table(study.groups, study.by, evidence, {key: twins[key].used for key in study.groups}),
        pa.Table.from_pylist(aside, schema=tables.SET_ASIDE.arrow),
        pa.Table.from_pylist(left_out, schema=tables.SKIPPED.arrow),
    )


def write_analysis(run_dir: Path, out: AnalysisTables) -> None:
    """Write an analysis's tables, each atomically; an earlier analysis's session or comparison
    tables that this one does not make are removed (the report shows only this one's)."""
    results.write(tables.FC_ESTIMATES, out.fc_estimates, run_dir)
    results.write(tables.EVIDENCE_TWINS, out.evidence_twins, run_dir)
    results.write(tables.SET_ASIDE, out.set_aside, run_dir)
    results.write(tables.ANALYSIS_GROUPS, out.groups, run_dir)
    results.write(tables.ANALYSIS, out.runs, run_dir)
    folders.atomic_write(run_dir / "analysis.csv", lambda tmp: _write_csv(out.runs, tmp))
    results.write(tables.SKIPPED, out.skipped, run_dir)
    if out.session is not None:
        sessions.write_session(run_dir, out.session)
    else:
        sessions.forget_session(run_dir)
    if out.effects is not None:
        effects.write_effects(run_dir, out.effects)
    else:
        effects.forget_effects(run_dir)


class _Rows:
    """The analysis tables' rows: one per run and method, one per group and method."""

    def __init__(
        self,
        study: Study,
        twins: dict[Group, GroupTwins],
        tested: dict[Group, Tested],
        selected: Selected,
        checks: Checks,
    ):
        self.study, self.twins, self.tested = study, twins, tested
        self.selected, self.checks = selected, checks
        self.factors = list(study.factors)
        self.factor_of = study.runs
        # Each group's check and, where it has none, why.
        self.group_checks = {
            key: checks.group(members, twins[key].model.values) for key, members in study.groups.items()
        }
        # Each run's remnant share from the data alone (the same for both methods), over the
        # window as the FC estimates.
        rate, n = study.config.timing.output_rate, study.config.timing.record_samples
        self.remnant_share = {
            run: off_line_share(r["u"][:n], r["ft"][:n], r["fd"][:n], rate)
            for run, r in study.records.items()
        }

    def choice(self, key, method_name: str) -> dict:
        """The group's W for a method, how it was chosen, and its twins' rates there."""
        used = self.twins[key].used[method_name]
        cal = used.calibrations[method_name]
        chosen = self.selected.chosen[(key, method_name)]
        return {
            "group": group_name(self.study.by, key),
            "method": method_name,
            "w": chosen.w,
            "w_rule": str(chosen.rule),
            "uncertain": chosen.uncertain,
            "ff_twin": used.kind,
            # The safe interval, NaN where there is none (the calibration's backward pair, false
            # positives up to safe_low and negatives from safe_high, would read as an interval).
            "safe_low": float(cal.safe_low) if separates(cal) else math.nan,
            "safe_high": float(cal.safe_high) if separates(cal) else math.nan,
            # Exactly at W, from the twins' selection paths (W need not be on the grid).
            **rates_at(*used.paths[method_name], chosen.w),
        }

    def run(self, run: int, method_name: str, choice: dict) -> tuple[dict, bool]:
        """A run's row, and whether the data contradict its own fit at W."""
        config, factor_of = self.study.config, self.factor_of
        outcome = self.selected.runs[(run, method_name)]
        a = outcome.final
        sel, fit = a.model, a.fit
        values = dict(zip(fit.names, fit.estimates, strict=True)) if fit else {}
        ses = dict(zip(fit.names, fit.se, strict=True)) if fit else {}
        fitted_loop = next((d for d in a.loop if d.source == "fitted"), None)
        row = {
            "data_set": config.data.name,
            "run_id": run,
            "file": str(factor_of[run]["file"]),
            "file_run": int(factor_of[run]["file_run"]),
            **choice,
            **dict(zip(tables.ORDER_COLUMNS, sel.orders, strict=True)),
            "feedforward_at_w": bool(sel.nb_ft > 0),
            "vaf_arx_validation": sel.vaf_validation,
            "vaf_validation": fit.vaf_validation if fit else math.nan,
        }
        status = parameter_status(fit) if fit else {}
        row["estimator"] = fit.target if fit else config.fit_hc.target
        row["hc_form"] = ("nms fixed" if fit.fixed else "full") if fit else ""
        for p in tables.HC_PARAMETER_NAMES:
            row[p] = values.get(p, math.nan)
            row[f"{p}_se"] = ses.get(p, math.nan)
            row[f"{p}_status"] = status.get(p, "not fitted")
        row["crossover"] = fitted_loop.crossover if fitted_loop else math.nan
        row["phase_margin"] = fitted_loop.phase_margin if fitted_loop else math.nan
        row["share_remnant"] = fitted_loop.shares["remnant"] if fitted_loop else math.nan
        row["remnant_share_data"] = self.remnant_share[run]
        row.update(outcome.evidence)
        row["evidence_uncertain"] = bool(row["power"] < MIN_POWER)
        check = self.checks.run(run, fit) if fit else None
        row.update(consistency_columns(check, self.checks.problem([run]) if fit else "not fitted"))
        for f in self.factors:
            row[f] = str(factor_of[run][f])
        return row, bool(check is not None and check.contradicted)

    def group(self, key, method_name: str, choice: dict, runs: list[dict], n_contradicted: int) -> dict:
        """A group's row from its choice of W and its runs' rows."""
        members = self.study.groups[key]
        used, model = self.twins[key].used[method_name], self.twins[key].model
        mine = [self.selected.runs[(run, method_name)].evidence for run in members]
        return {
            **choice,
            "n_runs": len(members),
            "n_feedforward_at_w": int(sum(r["feedforward_at_w"] for r in runs)),
            **group_verdict(mine, self.study.options.alpha),
            "forcing_sets": len(used.sets),
            "decided_by": mine[0]["decided_by"],
            **{f"twin_{p}": used.model[p] for p in tables.HC_PARAMETER_NAMES},
            **{f"fitted_{p}": model.values[p] for p in tables.HC_PARAMETER_NAMES},
            "twin_kn": used.remnant.kn,
            "twin_w_n": used.remnant.w_n,
            "twin_zeta_n": used.remnant.zeta_n,
            "twins": self.study.options.twins,
            "fb_twins": self.tested[key].fb_drawn[method_name],
            "twins_folder": used.folder,
            "twin_source": model.source,
            "twin_undetermined": ", ".join(model.undetermined),
            "n_contradicted": int(n_contradicted),
            **consistency_columns(*self.group_checks[key]),
        }


def _tables(rows: _Rows) -> tuple[pa.Table, pa.Table]:
    """The groups' and the runs' analysis tables (one row per group or run, and method)."""
    study = rows.study
    group_rows, run_rows = [], []
    for key, members in study.groups.items():
        for method_name in methods.METHODS:
            choice = rows.choice(key, method_name)
            mine, n_contradicted = [], 0
            for run in members:
                row, contradicted = rows.run(run, method_name, choice)
                mine.append(row)
                n_contradicted += contradicted
            run_rows += mine
            group_rows.append(rows.group(key, method_name, choice, mine, n_contradicted))
    schema = tables.ANALYSIS.arrow
    for f in rows.factors:
        schema = schema.append(pa.field(f, pa.string()))
    return (
        pa.Table.from_pylist(group_rows, schema=tables.ANALYSIS_GROUPS.arrow),
        pa.Table.from_pylist(run_rows, schema=schema),
    )


def _fc_rows(config: Config, name: str, members: list[int], records: dict, median: dict) -> list[dict]:
    """The group's Fourier-coefficient estimates and its fitted model at the same lines."""
    rows = slice(0, config.timing.record_samples)
    base = {"group": name, "n_runs": len(members)}
    try:
        fc = fc_estimate([records[s] for s in members], config.timing.output_rate, rows)
    except DataError as exc:  # one row saying why, NaN in every number
        numbers = {name: math.nan for name, kind in tables.FC_ESTIMATES.fields if pa.types.is_floating(kind)}
        return [{**base, **numbers, "path": "", "extrapolated": False, "problem": str(exc)}]
    yc = plant(config.loop)
    out = []
    yc_t = np.asarray(yc(1j * fc.omega_t), dtype=complex)
    inversion, spread = fc.inversion(yc_t), fc.inversion_runs(yc_t)
    for path, omega, h, extrapolated in (
        ("e", fc.omega_e, fc.he, np.zeros(fc.omega_e.size, dtype=bool)),
        ("ft", fc.omega_t, fc.ht, fc.extrapolated),
    ):
        sd_db, sd_deg = fc.spread(path)
        hft, he = hcfit.hc_response(median, yc, omega)
        model = he if path == "e" else hft
        if path == "e":  # Ht Yc only at the target lines
            nan = np.full(omega.size, math.nan)
            inv, runs = Inversion(nan, nan, nan, nan), InversionRuns(nan, nan, nan)
        else:
            inv, runs = inversion, spread
        for i in range(omega.size):
            out.append(
                {
                    **base,
                    "path": path,
                    "omega": float(omega[i]),
                    "magnitude_db": float(20 * np.log10(abs(h[i]))),
                    "phase_deg": float(np.degrees(np.angle(h[i]))),
                    "sd_db": float(sd_db[i]),
                    "sd_deg": float(sd_deg[i]),
                    "extrapolated": bool(extrapolated[i]),
                    "model_db": float(20 * np.log10(abs(model[i]))),
                    "model_deg": float(np.degrees(np.angle(model[i] / h[i])) + np.degrees(np.angle(h[i]))),
                    "inversion": float(inv.magnitude[i]),
                    "inversion_deg": float(inv.phase_deg[i]),
                    "inversion_sd": float(inv.sd[i]),
                    "inversion_sd_deg": float(inv.sd_deg[i]),
                    "inversion_median": float(runs.median[i]),
                    "inversion_q25": float(runs.q25[i]),
                    "inversion_q75": float(runs.q75[i]),
                    "problem": "",
                }
            )
    return out


def _write_csv(table: pa.Table, path: str) -> None:
    import pyarrow.csv as pacsv

    pacsv.write_csv(table, path)
