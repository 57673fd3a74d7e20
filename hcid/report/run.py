"""What a report is built from: the run's config and tables, read once and checked against their schemas."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from hcid import methods, tables
from hcid.assembly.resolve import parse_config, read_yaml, recorded_methods
from hcid.config import Config
from hcid.errors import ConfigError, DataError
from hcid.io import results
from hcid.selection import criteria

__all__ = ["RunTables", "marks_for_plot", "read_run"]

#: The columns each table must hold for the report (checked with their types on reading).
_READS = {
    "summary": (tables.SIMULATION_SUMMARY, None),
    "frontier": (tables.FRONTIER, None),
    "log": (tables.IDENTIFY_LOG, None),
    "selection": (tables.SELECTION, None),
    "thresholds": (tables.thresholds(), None),
    "runlog": (tables.RUN_LOG, None),
    "calibration": (tables.CALIBRATION, None),
    "hc_parameters": (tables.HC_PARAMETERS, None),
    "residuals": (tables.RESIDUALS, None),
    "hc_loop": (tables.HC_LOOP, None),
    "analysis": (tables.ANALYSIS, None),
    "analysis_groups": (tables.ANALYSIS_GROUPS, None),
    "fc_estimates": (tables.FC_ESTIMATES, None),
    "evidence_twins": (tables.EVIDENCE_TWINS, None),
    "set_aside": (tables.SET_ASIDE, None),
    "skipped": (tables.SKIPPED, None),
    "session_trials": (tables.SESSION_TRIALS, None),
    "session_lines": (tables.SESSION_LINES, None),
    "session_findings": (tables.SESSION_FINDINGS, None),
    "feedback_runs": (tables.FEEDBACK_RUNS, None),
    "study_effects": (tables.STUDY_EFFECTS, None),
    "remnant_spectrum": (tables.REMNANT_SPECTRUM, None),
    "rates": (tables.RATES, None),
    "handoff": (tables.HANDOFF, None),
}


@dataclass(frozen=True)
class RunTables:
    """A run directory's config and tables (None where a stage has not run).

    ``choices`` holds the table of each choosing stage of the registered
    methods that is present (``stage1``).
    """

    run_dir: Path
    config: Config
    summary: pa.Table | None
    frontier: pa.Table | None
    log: pa.Table | None
    selection: pa.Table | None
    thresholds: pa.Table | None
    runlog: pa.Table | None
    calibration: pa.Table | None
    choices: dict[str, pa.Table]
    hc_parameters: pa.Table | None = None
    residuals: pa.Table | None = None
    rates: pa.Table | None = None
    handoff: pa.Table | None = None
    hc_loop: pa.Table | None = None
    remnant_spectrum: pa.Table | None = None
    analysis: pa.Table | None = None
    analysis_groups: pa.Table | None = None
    fc_estimates: pa.Table | None = None
    evidence_twins: pa.Table | None = None
    set_aside: pa.Table | None = None
    skipped: pa.Table | None = None
    session_trials: pa.Table | None = None
    session_lines: pa.Table | None = None
    session_findings: pa.Table | None = None
    feedback_runs: pa.Table | None = None
    study_effects: pa.Table | None = None

    def simulations(self) -> dict | None:
        """The simulated records by (model, seed), or None without simulations."""
        table = results.read_optional(tables.SIMULATIONS, self.run_dir)
        return None if table is None else results.records(table, self.run_dir / tables.SIMULATIONS.file)

    def nf(self) -> dict[str, int]:
        """Nf of every registered method: the estimation rows of the stage that defines it."""
        return {
            name: m.nf(self.config.identify) for name, m in methods.resolved(self.config.identify).items()
        }

    def criterion_marks(self) -> dict[str, dict[str, float]]:
        """Per configured criterion label, its W per method (each method's own Nf)."""
        nf = self.nf()
        return {
            c.label: {m: c.w(n) for m, n in nf.items()}
            for c in criteria.configured(self.config.selection.criteria)
        }

    def w_bic(self) -> dict[str, float]:
        """W_BIC per method (the paper's figures are drawn at W_BIC)."""
        return {m: criteria.w_bic(n) for m, n in self.nf().items()}


def marks_for_plot(marks: dict[str, dict[str, float]]) -> dict[str, float]:
    """Flatten criterion marks to plot labels: one line per criterion, or one per method if they differ."""
    out = {}
    for label, per_method in marks.items():
        values = set(per_method.values())
        if len(values) == 1:
            out[label] = values.pop()
        else:
            out.update({f"{label} {m}": w for m, w in per_method.items()})
    return out


def _load_config(run_dir: Path) -> Config:
    path = run_dir / "config.yaml"
    if not path.is_file():
        raise DataError(
            f"{path}: missing; is {run_dir} a run directory (made by `hcid run CONFIG` or "
            "`hcid analyse CONFIG --data DATA`)?"
        )
    try:
        data = read_yaml(path, "run config")
        return parse_config(data, run_dir.name, method_names=recorded_methods(data))
    except ConfigError as exc:
        raise DataError(f"{path}: {exc}" if not str(exc).startswith(str(path)) else str(exc)) from exc


def _with_optional(table: pa.Table, schema: tables.Schema) -> pa.Table:
    """``table`` with the schema's optional columns an older hcid did not write: NaN, or ""."""
    types = dict(schema.fields)
    for name in schema.optional:
        if name not in table.column_names:
            kind = types[name]
            value = "" if kind == pa.string() else float("nan")
            table = table.append_column(pa.field(name, kind), pa.array([value] * table.num_rows, kind))
    return table


def read_run(run_dir: Path) -> RunTables:
    """Read a run directory for its report; one-line DataError for a damaged table or config."""
    loaded = {name: results.read_optional(schema, run_dir, cols) for name, (schema, cols) in _READS.items()}
    choices = {}
    for method in methods.METHODS.values():
        for stage in method.choice_stages:
            table = results.read_optional(tables.stage_choice(stage.name, stage.inputs), run_dir)
            if table is not None:
                choices[stage.name] = table
    config = _load_config(run_dir)
    for name, table in loaded.items():
        if table is not None:
            results.check_against_config(table, config, run_dir / _READS[name][0].file)
    if loaded["hc_parameters"] is not None:
        loaded["hc_parameters"] = _with_optional(loaded["hc_parameters"], tables.HC_PARAMETERS)
    return RunTables(run_dir=run_dir, config=config, choices=choices, **loaded)
