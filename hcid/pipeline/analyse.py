"""``hcid analyse``: a measured study end to end, W calibrated on twins of each group's fitted model.

1. Identify every run of the data set by every method (:func:`identify_study`).
2. Fit the parametric HC model (the config's estimator: ``auto``, the ``lines`` estimator where
   the forcing functions are multisines, by default) to every run
   with and without its feedforward path, and SPEC 1's remnant filter to what the
   feedforward fit leaves.
3. Per group of runs (``--by``, default the factor ``condition``; one group without it; with a
   plant per level of a factor, that factor too, so that a group holds one plant and every run is
   fitted and described with its own plant: :mod:`hcid.pipeline.plants`):
   the twins are the group's fitted model (medians over its runs; the FF twin) and the
   same with ``Kpt = 0`` (the FB twin), with the group's fitted neuromuscular system
   and remnant, driven by the group's first run's recorded ft and fd at the data's
   rate and window (SPEC 10). ``calibrate-w`` on them (``RUN/twins/<group>/``) gives
   the safe interval and the recommended W per method.
4. Per group and method the statistic that decides (W*, the Fourier size or the likelihood
   ratio: the one whose twins show the most power), and more FB twins wherever a run's p-value
   is not settled (:mod:`hcid.pipeline.analyse_twins`, :class:`hcid.pipeline.evidence.Evidence`).
5. Every run's evidence (its p-value against its forcing set's FB twins), its model selected at
   its group's W, and the selected structure's parametric fit
   (:func:`hcid.hcfit.selected.analyse_selected`).
6. The tables (:mod:`hcid.pipeline.analysis_tables`).

Where no W separates a group's own twins and another group's fitted feedforward is stronger
(``--ff-twin auto``, the default: a group where nobody uses feedforward has twins that nearly
coincide), the group is calibrated again with that group's feedforward path on its own
feedback: "would feedforward of the size this study shows be found here?"; ``ff_twin`` says
which twins gave W. Where no W separates the twins used, the W of the grid with the least
total error rate (FP + FN) is used and every decision there is marked ``uncertain``.

Each run's kind comes from its data first (SPEC 12, :mod:`hcid.pipeline.sessions`): only runs
with both a target and a disturbance go through the steps above; in a whole experiment (runs of
one input, or line sets swapped between runs) every run is then combined per person, and each
disturbance-only run's feedback fitted alone.

Writes ``analysis.parquet`` and ``analysis.csv`` (one row per run and method, with the run's
factors: statistics-ready), ``analysis_groups.parquet`` and ``fc_estimates.parquet`` (each
group's model-free estimates of both paths, SPEC 10, beside its fitted model), ``skipped.parquet``
(files found that are not runs) and, for a whole experiment, the session tables.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from hcid import methods, tables
from hcid.analysis.conditions import Kind
from hcid.assembly.resolve import read_study, with_data
from hcid.config import Config
from hcid.errors import ConfigError, DataError
from hcid.hcfit.selected import SelectedModel, analyse_selected
from hcid.io.datasets import DataSet
from hcid.pipeline import effects, sessions
from hcid.pipeline.analyse_state import Group, GroupTwins, RunOutcome, RunPath, Selected, Study, Tested
from hcid.pipeline.analyse_twins import make_twins, more_fb_twins
from hcid.pipeline.analysis_tables import build_tables, write_analysis
from hcid.pipeline.evidence import (
    Checks,
    Evidence,
    decide,
    group_name,
)
from hcid.pipeline.execution import Execution
from hcid.pipeline.fit_hc import RunFits, fit_run, fit_windows, stage_choices
from hcid.pipeline.line_statistics import deviations, run_statistics
from hcid.pipeline.measured_data import check_plant
from hcid.pipeline.options import AnalysisOptions
from hcid.pipeline.parallel import labelled
from hcid.pipeline.plants import run_plants
from hcid.pipeline.rundir import holds_run_dir
from hcid.pipeline.sessions import Session
from hcid.pipeline.studies import IdentifyRun, identify_study
from hcid.pipeline.twin_values import twin_rate
from hcid.pipeline.twins import forget_twins
from hcid.selection.calibration import benjamini_hochberg, choose_w

__all__ = ["AnalysisOptions", "AnalysisRun", "analyse", "analyse_study"]


@dataclass(frozen=True)
class AnalysisRun:
    """What ``hcid analyse`` found: ``groups`` (one row per group and method) and ``runs``
    (one row per run and method), as written to the run directory."""

    groups: pa.Table
    runs: pa.Table
    seconds: float
    run_dir: Path
    #: Wall seconds per step: identify, fit runs, twins, more FB twins, fit selected, combine
    #: conditions (a whole experiment only), tables.
    stages: dict[str, float] = field(default_factory=dict)
    #: The files left out because they could not be read: (path, reason).
    set_aside: tuple[tuple[str, str], ...] = ()
    #: The files a folder or glob found that are not runs: (path, reason).
    skipped: tuple[tuple[str, str], ...] = ()
    #: Runs per condition kind (:class:`hcid.analysis.conditions.Kind` values), from the data.
    kinds: dict[str, int] = field(default_factory=dict)
    #: A whole experiment's conditions combined per person (None: the runs need no combining).
    session: Session | None = None
    #: ``study_effects.parquet`` (``compare``; None without a comparison).
    effects: pa.Table | None = None


def _groups(runs: Sequence[Mapping], by: Sequence[str]) -> dict[tuple[str, ...], list[int]]:
    """The runs (ids) of each group: the values of the ``by`` factors (checked by the caller)."""
    out: dict[tuple[str, ...], list[int]] = {}
    for row in runs:
        out.setdefault(tuple(str(row[f]) for f in by), []).append(int(row["run"]))
    return out


def _final_task(config, run, record, method_name, sel, choices, fit):
    analysis = analyse_selected(sel, record, config, methods.get(method_name), choices, fit=fit)
    return run, method_name, analysis


def _same_fit(config: Config, sel: SelectedModel, fits: RunFits):
    """The run's own fit (step 2) of the selected structure when it is the one
    :func:`hcid.hcfit.selected.fit_selected` would make (same windows: the direct method's final
    stage's), else None (fitted again)."""
    if (sel.estimation.rows(), sel.validation.rows()) != fit_windows(config):
        return None
    return fits.of(bool(sel.has_feedforward))


def _factors_and_groups(data: DataSet, by: Sequence[str] | None) -> tuple[str, ...]:
    """The data set's factors checked against the tables' columns, and the ``by`` factors (the
    default: ``condition`` where the data set has it); refused before any work."""
    factors = list(data.factors)
    taken = sorted(set(factors) & (set(tables.ANALYSIS.names) | set(tables.ANALYSIS_GROUPS.names)))
    if taken:
        raise ConfigError(
            f"factor {taken[0]!r}: the analysis tables have a column of that name; rename the factor "
            "(data.pattern, the manifest's header or data.dimensions)"
        )
    if by is None:
        by = ["condition"] if "condition" in factors else []
    missing = [f for f in by if f not in factors]
    if missing:
        raise ConfigError(
            f"--by {','.join(by)}: the data set has no factor {missing[0]!r} (its factors: "
            f"{', '.join(factors) or 'none'}; name them with data.pattern or a manifest)"
        )
    return tuple(by)


def _check_config(config: Config) -> None:
    if config.loop is None:
        raise ConfigError(
            "loop: missing; `hcid analyse` needs the plant of the experiment (loop.plant and "
            "loop.disturbance_at) for the parametric fit and the twins"
        )
    if config.fit_hc.target == "frequency":
        raise ConfigError(
            "fit_hc.target: frequency fits an ARX model's responses, and hcid analyse fits every run "
            "before any model is selected; use auto (the default), lines, time or closed_loop"
        )


def _fit_runs(study: Study) -> dict[int, RunFits]:
    """Step 2: every run fitted with and without feedforward."""
    tasks = [(study.plants.of_run(s), s, study.records[s], study.kn_rate) for s in sorted(study.records)]
    return {fits.run: fits for fits in study.execution.map(fit_run, tasks, "fit runs")}


def _selection_paths(study: Study, identified: IdentifyRun) -> dict[tuple[int, str], RunPath]:
    """Every run's frontier, selection path over W and earlier stages' choices, per method, from
    its identification (held in memory, not read back)."""
    name = study.config.data.name
    out = {}
    for run in study.records:
        for method_name in methods.METHODS:
            frontier = identified.frontiers[(name, run, method_name)]
            choices = stage_choices(study.run_dir, identified.choices, method_name, name, run)
            out[(run, method_name)] = RunPath(frontier, frontier.path(), choices)
    return out


def _select_and_fit(
    study: Study,
    fitted: Mapping[int, RunFits],
    twins: Mapping[Group, GroupTwins],
    tested: Mapping[Group, Tested],
    paths: Mapping[tuple[int, str], RunPath],
    judge: Evidence,
    run_lines: dict,
) -> Selected:
    """Step 5: every run's evidence, its selection at its group's W, and the selected
    structure's parametric fit."""
    config = study.config
    tasks, chosen, evidence = [], {}, {}
    for key, members in study.groups.items():
        for method_name in methods.METHODS:
            used = twins[key].used[method_name]
            choice = chosen[(key, method_name)] = choose_w(used.calibrations[method_name])
            stage = config.identify.stage(methods.get(method_name).final_stage.name)
            deciding = tested[key].deciding[method_name]
            for run in members:
                identified = paths[(run, method_name)]
                evidence[(run, method_name)] = judge.run(
                    group_name(study.by, key),
                    judge.w_star(identified.path, identified.frontier.nb_ft),
                    used,
                    run,
                    method_name,
                    run_lines.get(run),
                    deciding,
                )
                row = int(identified.path.at(np.array([choice.w]))[0])
                shift = config.identify.target_shift
                rate = config.timing.output_rate
                sel = SelectedModel.from_frontier(
                    identified.frontier, row, choice.w, rate=rate, target_shift=shift, stage=stage
                )
                own = _same_fit(config, sel, fitted[run])  # shared, not fitted twice
                mine = study.plants.of_run(run)  # the run's own plant
                tasks.append((mine, run, study.records[run], method_name, sel, identified.choices, own))
            decide([evidence[(run, method_name)] for run in members], study.options.alpha, deciding)
    finals = {
        (run, method_name): analysis
        for run, method_name, analysis in study.execution.map(_final_task, tasks, "fit selected")
    }
    if study.options.fdr:  # Benjamini-Hochberg over the study's runs, per method
        for method_name in methods.METHODS:
            keys = [k for k in evidence if k[1] == method_name]
            hits = benjamini_hochberg(np.array([evidence[k]["p_value"] for k in keys]), study.options.alpha)
            for k, hit in zip(keys, hits, strict=True):
                evidence[k] = {**evidence[k], "evidence": "feedforward" if hit else "none shown"}
    return Selected(chosen, {k: RunOutcome(evidence[k], finals[k]) for k in evidence})


@holds_run_dir(create=True)
def analyse_study(
    config: Config,
    run_dir: Path,
    data: DataSet,
    options: AnalysisOptions = AnalysisOptions(),
    *,
    execution: Execution = Execution(),
    force: bool = False,
) -> AnalysisRun:
    """Analyse a measured study with W calibrated on twins of each group's fitted model (module
    notes), in its steps (1-6 of the module's notes, each returning a frozen result of
    :mod:`hcid.pipeline.analyse_state`): identify, fit runs, twins, more FB twins, fit selected,
    tables.

    ``data``: the study's data set, read once (:func:`hcid.assembly.resolve.read_study`); the files it
    set aside (``--skip-unreadable``) are written to ``set_aside.parquet`` so that the answer and
    the report list them.

    Raises
    ------
    ConfigError
        Without a plant (``loop``), for a ``by`` factor or a plant factor (``loop.plant.by``) the
        data set does not have, or a plant per level in a whole experiment.
    DataError
        For a bad data set, or a run whose level has no plant (one line, nothing written).
    """
    _check_config(config)
    config = with_data(config)
    plants = run_plants(config, data)  # each run's plant: its factor and levels checked first
    check_plant(config, data, plants)  # every run, the single-input ones too (identify checks its own)
    trials = sessions.classify(data, config)
    person = sessions.person_factor(data, options.person)
    whole_experiment = sessions.is_whole_experiment(trials)
    if whole_experiment:
        sessions.check_factors(data.factors, person)
        config.require_one_plant("a whole experiment, its conditions combined per person,")
    whole = data
    two_input = [run for run, t in trials.items() if t.kind is Kind.TWO_INPUT]
    if len(two_input) < len(trials):  # single-input runs: combined per person, not tested for feedforward
        data = sessions.subset(data, two_input)
    by = plants.grouping(_factors_and_groups(data, options.by))  # a group never mixes plants
    if options.compare is not None:  # refused before anything is written
        # the data set's factors only (its rows also name the run and its file)
        effects.compare_levels([{f: r[f] for f in data.factors} for r in data.runs], options.compare, person)
    start = time.perf_counter()
    stages, lap = {}, [start]

    def lap_done(name: str) -> None:
        now = time.perf_counter()
        stages[name], lap[0] = now - lap[0], now

    kinds = {kind.value: sum(t.kind is kind for t in trials.values()) for kind in Kind}
    if not two_input:  # refused before anything is written
        counts = ", ".join(f"{n} {k}" for k, n in kinds.items() if n)
        raise DataError(
            f"no run has both a target and a disturbance ({counts}): hcid analyse tests feedforward on "
            "two-input runs and combines the other conditions with them; add the study's two-input runs"
        )

    with labelled("runs: "):
        identified = identify_study(
            config, run_dir, tuple(methods.METHODS), data=data, execution=execution, force=force
        )
    if force:  # after the data's checks (in identify_study): a refused --force keeps the twins
        forget_twins(run_dir)
    lap_done("identify")
    study = Study(
        config,
        run_dir,
        options,
        execution,
        by,
        {int(r["run"]): r for r in data.runs},
        data.factors,
        data.records,
        _groups(data.runs, by),
        twin_rate(config.timing.output_rate),
        plants,
    )
    fitted = _fit_runs(study)
    lap_done("fit runs")
    twins = make_twins(study, fitted)
    lap_done("twins")
    paths = _selection_paths(study, identified)
    # Each run over the analysis window, as long as its twins (a file may run on beyond it).
    n = config.timing.record_samples
    windowed = {s: {k: np.asarray(v)[:n] for k, v in r.items()} for s, r in data.records.items()}
    checks = Checks(config, windowed, {s: plants.of_run(s).loop for s in data.records})
    starts = {key: twins[key].model.values for key in study.groups}  # each group's model
    with labelled("runs: "):
        run_lines = run_statistics(
            windowed,
            {s: plants.of_run(s) for s in data.records},
            {s: starts[key] for key, members in study.groups.items() for s in members},
            execution,
        )
    judge = Evidence(
        config,
        run_dir,
        options.alpha,
        options.most_fb_twins,
        {
            group_name(by, key): (
                plants.of_runs(members),
                starts[key],
                deviations(starts[key], [fitted[s].with_ff for s in sorted(members)]),
            )
            for key, members in study.groups.items()
        },
        execution,
        # Beyond every twin, settled at a tail p of alpha / 10; not under --fdr, whose thresholds
        # go down to alpha / (runs): there more twins can still change a decision.
        None if options.fdr else options.alpha / 10,
    )
    tested, judge = more_fb_twins(study, twins, paths, judge, run_lines)
    lap_done("more FB twins")
    selected = _select_and_fit(study, fitted, twins, tested, paths, judge, run_lines)
    lap_done("fit selected")
    session = None
    if whole_experiment:
        with labelled("conditions: "):
            session = sessions.combine_session(config, whole, trials, person, execution)
        lap_done("combine conditions")
    built = build_tables(study, twins, tested, selected, checks, judge, data.set_aside, whole.skipped)
    rows = []
    if options.compare is not None:
        timing = config.timing
        # |Ht Yc| at the lines too where the runs' plants differ (each run's own plant).
        own = {s: plants.plant_of(s) for s in data.records} if plants.several else None
        lines = effects.line_values(data.records, timing.output_rate, timing.record_samples, own)
        rows = effects.effects_rows(built.runs.to_pylist(), options.compare, person, lines)
    if session is not None:
        rows += effects.superposition_rows(session.lines)
    built = dataclasses.replace(built, session=session, effects=effects.effects_table(rows) if rows else None)
    write_analysis(run_dir, built)
    lap_done("tables")
    aside = tuple((str(f), str(why)) for f, why in data.set_aside)
    return AnalysisRun(
        built.groups,
        built.runs,
        time.perf_counter() - start,
        run_dir,
        stages,
        aside,
        tuple(whole.skipped),
        kinds,
        session,
        built.effects,
    )


def analyse(
    config: str | Path | Mapping[str, Any],
    data: str | Path | Sequence[str | Path],
    run: str | Path | None = None,
    options: AnalysisOptions | None = None,
    *,
    execution: Execution | None = None,
    skip_unreadable: bool = False,
    force: bool = False,
) -> AnalysisRun:
    """Analyse a measured study end to end, as ``hcid analyse`` does (the same function).

    Every run identified by each method, W calibrated per group on twins of the group's
    fitted model, each run's feedforward tested against its FB twins (its p-value), its
    model selected and its parameters fitted with their standard errors (SPEC 10 and 11); in
    a whole experiment, every condition combined per person (SPEC 12).

    Parameters
    ----------
    config : str, Path or mapping
        The study's YAML config (``data`` and ``loop`` sections: docs/configuration.md), or the
        mapping such a file holds (its relative paths then from the working folder).
    data : str, Path or a sequence of them
        Files, quoted globs (``"trials/*.csv"``), folders or a manifest CSV.
    run : str or Path, optional
        The run directory: the tables, the twins and ``report/``; a second call with the same
        inputs reuses what is there (``force`` starts again). Default: ``runs/<the study's
        name>`` (the config's ``name``, else its file's stem), as ``hcid analyse`` without ``--run``.
    options : AnalysisOptions, optional
        Grouping (``by="subject,condition"``), twins, the test's level (``hcid analyse``'s
        options); default: ``AnalysisOptions()``.
    execution : Execution, optional
        Workers and progress bars; default ``Execution(jobs=2)``.
    skip_unreadable : bool
        Set aside files that cannot be read (``AnalysisRun.set_aside``) instead of refusing.

    Returns
    -------
    AnalysisRun
        ``runs``: one row per run and method (its factors, ``p_value``, ``feedforward_at_w``,
        the parameters with ``_se`` and ``_status``; docs/tables.md), ``groups``: one per group
        and method (W, its rule, the verdict); the same tables as ``RUN/analysis.parquet`` and
        ``analysis_groups.parquet``. ``hcid.build_report(run)`` writes the HTML report.
        A whole experiment (single-input runs, or line sets swapped between runs: SPEC 12): only
        the two-input runs are tested for feedforward; ``kinds`` counts the runs of each kind and
        ``session`` holds every run combined per person (``session_lines``, ``session_findings``,
        ``session_trials`` and ``feedback_runs`` tables). ``skipped``: the files a folder or glob
        found that are not runs, with why.

    Raises
    ------
    HcidError
        One line naming what is wrong (config, data, a run directory in use); nothing written.
    """
    execution = Execution() if execution is None else execution
    options = AnalysisOptions() if options is None else options
    for name, value, kind in (("options", options, AnalysisOptions), ("execution", execution, Execution)):
        if not isinstance(value, kind):
            raise ConfigError(f"{name}: must be a hcid.{kind.__name__}, got {type(value).__name__}")
    if not isinstance(config, str | Path | Mapping):
        raise ConfigError(
            f"config: must be a YAML file's path or the mapping it holds, got {type(config).__name__}"
        )
    if run is not None and not isinstance(run, str | Path):
        raise ConfigError(f"run: must be the run directory's path (str or Path), got {type(run).__name__}")
    sources = [data] if isinstance(data, str | Path) else list(data) if isinstance(data, Sequence) else []
    if not sources or not all(isinstance(x, str | Path) for x in sources):
        raise DataError(
            f"data: must be files, globs or folders (str or Path, or a list of them), got {data!r}"
        )
    execution.check()
    study_config, data_set = read_study(config, sources, skip_unreadable=skip_unreadable, single_input=True)
    run_dir = Path(run) if run is not None else Path("runs") / study_config.name  # the config read once
    return analyse_study(study_config, run_dir, data_set, options, execution=execution, force=force)
