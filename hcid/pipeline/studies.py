"""The stages of a study over models x seeds (or measured runs) x methods, and the whole study.

Each ``*_study`` function reads what it needs from the run directory, runs its
tasks on :func:`~hcid.pipeline.parallel.parallel_map`, writes its tables
atomically and returns them. :func:`run_study` owns the chain "simulate if
missing, identify what is not done, sweep W"; the CLI calls one of these.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import calibration, criteria, measured, methods, paper, results, selection, tables
from hcid.calibration import calibrate
from hcid.config import Config, IdentifyConfig
from hcid.errors import ConfigError, DataError, IdentificationError
from hcid.pipeline.parallel import check_scheduler, parallel_map
from hcid.pipeline.rundir import check_run_dir, holds_run_dir, record_config
from hcid.simulate import remnant_gain, simulate_realization

__all__ = [
    "CalibrationRun",
    "IdentifyRun",
    "SimulationRun",
    "StudyRun",
    "SweepRun",
    "calibrate_study",
    "identify_study",
    "run_study",
    "simulate_study",
    "sweep_study",
]


# --------------------------------------------------------------------------- simulation


def _simulate_task(config: Config, model_name: str, seed: int, kn: float):
    model = config.model(model_name)
    return (
        simulate_realization(config, model, seed, kn),
        simulate_realization(config, model, seed, kn, disturbance_only=True),
    )


@dataclass(frozen=True)
class SimulationRun:
    """Tables of one simulation run and where they were written."""

    simulations: pa.Table
    summary: pa.Table
    kn: float
    run_dir: Path


@holds_run_dir(create=True)
def simulate_study(
    config: Config, run_dir: Path, *, jobs: int = 2, show_progress: bool = True, force: bool = False
) -> SimulationRun:
    """Simulate every model x seed of ``config`` and write the run's tables.

    Writes ``config.yaml``, ``simulations.parquet`` and
    ``simulation_summary.parquet`` in ``run_dir``, each atomically.
    """
    config.require_simulation("simulate")
    check_run_dir(config, run_dir, "simulate", force=force)
    start = time.perf_counter()
    kn = remnant_gain(config)
    tasks = [(config, m.name, seed, kn) for m in config.models for seed in config.seeds]
    pairs = list(
        parallel_map(_simulate_task, tasks, jobs=jobs, label="simulate", show_progress=show_progress)
    )
    realizations = [p[0] for p in pairs]
    simulations = results.realizations_table(realizations)
    summary = results.summary_table(realizations, [p[1] for p in pairs])
    record_config(config, run_dir)
    results.write(tables.SIMULATIONS, simulations, run_dir)
    results.write(tables.SIMULATION_SUMMARY, summary, run_dir)
    results.append_run_log(run_dir, "simulate", time.perf_counter() - start, jobs)
    return SimulationRun(simulations=simulations, summary=summary, kn=kn, run_dir=run_dir)


# --------------------------------------------------------------------------- identification


def _identify_task(
    settings: IdentifyConfig,
    rate: float,
    model: str,
    seed: int,
    method: str,
    record: dict[str, np.ndarray],
    noise_free: dict[str, np.ndarray] | None = None,
):
    result = methods.identify(record, settings, method, rate=rate, threads=1)
    stages = methods.get(method).choice_stages
    worker = f"{socket.gethostname()}:{os.getpid()}"  # the process that ran it (log only)
    parts = results.frontier_part(model, seed, result, stages, worker)
    if stages:
        parts["handoff"] = handoff_part(
            model, seed, methods.get(method), settings, result.choices, noise_free
        )
    return (model, seed, method), parts


def handoff_part(model, seed, method, settings, choices, noise_free) -> pa.Table:
    """VAF (%) of each handed-on signal against the noise-free simulated one.

    A choosing stage's output (e for stage 1) simulated without remnant is what
    its handed-on signal (e_r) estimates; measured data have none (NaN).
    ``vaf_noise_free`` is taken over the rows the next stage fits and validates
    on (what it uses), ``vaf_noise_free_record`` over the whole record, whose
    first samples no stage-1 V looks at unless stage 1 fits from the first sample.
    """
    rows = []
    for i, (spec, choice) in enumerate(zip(method.choice_stages, choices, strict=True)):
        name = spec.inputs[2]
        nxt = settings.stage(method.stages[i + 1].name)
        used = slice(
            min(nxt.estimation.first, nxt.validation.first) - 1, max(nxt.estimation.last, nxt.validation.last)
        )
        truth = None if noise_free is None else noise_free.get(name)
        vaf = vaf_record = np.nan
        if truth is not None and choice.signal is not None:
            vaf = _vaf(truth[used], choice.signal[used])
            vaf_record = _vaf(truth, choice.signal)
        rows.append(
            {
                "model": model,
                "seed": seed,
                "method": method.name,
                "stage": spec.name,
                "signal": name,
                "vaf_noise_free": vaf,
                "vaf_noise_free_record": vaf_record,
            }
        )
    return pa.Table.from_pylist(rows, schema=tables.HANDOFF.arrow)


def _vaf(truth: np.ndarray, estimate: np.ndarray) -> float:
    return float((1.0 - np.sum((truth - estimate) ** 2) / np.sum(truth**2)) * 100.0)


def noise_free_records(config: Config) -> dict[str, dict[str, np.ndarray]]:
    """Every model's record simulated without remnant (the same for every seed), by channel."""
    out = {}
    for m in config.models:
        rec = simulate_realization(config, m, config.seeds[0], 0.0)
        out[m.name] = {name: getattr(rec, name) for name in tables.SIGNALS}
    return out


@dataclass(frozen=True)
class IdentifyRun:
    """Tables of the identification of a run.

    ``simulation`` is set when the run had no simulations and they were made
    first; ``imported`` counts the measured runs read from a data file.
    """

    frontier: pa.Table
    choices: dict[str, pa.Table]
    log: pa.Table
    computed: int
    reused: int
    run_dir: Path
    simulation: SimulationRun | None = None
    imported: int = 0


def _part_kinds() -> dict[str, dict[str, tables.Schema]]:
    """Per method, the schema of each part a finished task has."""
    return {
        name: {
            "frontier": tables.FRONTIER,
            "log": tables.IDENTIFY_LOG,
            **{s.name: tables.stage_choice(s.name, s.inputs) for s in m.choice_stages},
            **({"handoff": tables.HANDOFF} if m.choice_stages else {}),
        }
        for name, m in methods.METHODS.items()
    }


def _choice_schemas() -> dict[str, tables.Schema]:
    return {
        s.name: tables.stage_choice(s.name, s.inputs)
        for m in methods.METHODS.values()
        for s in m.choice_stages
    }


def _existing(run_dir: Path) -> dict[tuple[str, int, str], dict[str, pa.Table]]:
    """Finished realizations of the run's assembled tables, keyed by (model, seed, method)."""
    if not (run_dir / tables.FRONTIER.file).is_file():
        return {}
    hint = "use --force to recompute it"
    key = tables.FRONTIER.key
    frontier = results.read(tables.FRONTIER, run_dir, key, hint=hint)
    logs = tables.split_by_key(results.read(tables.IDENTIFY_LOG, run_dir, key, hint=hint), key)
    choices = {}
    for name, schema in _choice_schemas().items():
        table = results.read_optional(schema, run_dir, schema.key)
        choices[name] = tables.split_by_key(table, schema.key) if table is not None else {}
    handoff = results.read_optional(tables.HANDOFF, run_dir)
    handoffs = tables.split_by_key(handoff, key) if handoff is not None else {}
    out = {}
    for k, table in tables.split_by_key(frontier, key).items():
        method = methods.METHODS.get(k[2])
        if k not in logs or method is None:
            continue
        entry = {"frontier": table, "log": logs[k]}
        if k in handoffs:
            entry["handoff"] = handoffs[k]
        for stage in method.choice_stages:
            if k[:2] in choices[stage.name]:
                entry[stage.name] = choices[stage.name][k[:2]]
        if all(s.name in entry for s in method.choice_stages):
            out[k] = entry
    return out


def _load_records(config: Config, run_dir: Path) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    table = results.read(tables.SIMULATIONS, run_dir, hint="run `hcid simulate` first")
    path = run_dir / tables.SIMULATIONS.file
    recs = results.records(table, path)
    n = config.timing.record_samples
    for m in config.models:
        for seed in config.seeds:
            rec = recs.get((m.name, seed))
            if rec is None:
                raise DataError(
                    f"{path}: has no record of model {m.name}, seed {seed}; rerun `hcid simulate`"
                )
            if rec["e"].size != n:
                raise DataError(
                    f"{path}: model {m.name}, seed {seed} has {rec['e'].size} samples, expected {n}"
                )
    return recs


def _import_data(config: Config, run_dir: Path, path: Path) -> dict[int, dict[str, np.ndarray]]:
    """Read and check a measured-data file and keep a copy in ``run_dir/measured.parquet``."""
    records = measured.load_data(path, config)
    check_run_dir(config, run_dir, "identify")
    record_config(config, run_dir)
    results.write(tables.MEASURED, measured.records_table(config.data.name, records), run_dir)
    return records


@holds_run_dir(create=True)
def identify_study(
    config: Config,
    run_dir: Path,
    method_names: Sequence[str] | None = None,
    *,
    data_path: Path | None = None,
    jobs: int = 2,
    force: bool = False,
    backend: str = "loky",
    scheduler: str | None = None,
    worker_timeout: float = 60.0,
    show_progress: bool = True,
) -> IdentifyRun:
    """Identify every model x seed x method of ``config``, simulating first if the run has no simulations.

    Realizations already in ``frontier.parquet`` (or finished by an
    interrupted run, in ``.parts/``) are not recomputed unless ``force``.
    Writes ``frontier.parquet``, one table per choosing stage
    (``stage1.parquet``) and ``identify_log.parquet``; the first two are
    identical whatever ``jobs``, backend or interruptions.

    With ``data_path`` (a measured-data file, :func:`hcid.measured.load_data`),
    its runs are identified instead, under model name ``config.data.name`` and
    seed = run number, beside any simulated realizations already in the tables.
    ``method_names`` defaults to every registered method.
    """
    names = tuple(methods.METHODS) if method_names is None else tuple(method_names)
    for name in names:
        methods.get(name)
    check_scheduler(backend, scheduler, worker_timeout)  # refused before anything is read or written
    simulation = None
    if data_path is not None:
        data = _import_data(config, run_dir, data_path)
        records = {(config.data.name, run): rec for run, rec in data.items()}
        keys = list(records)
        noise_free = {}
    else:
        config.require_simulation("identify (without --data)")
        # Before the simulations: forked workers then start with this process's loops,
        # forcing functions and compiled loop kernel (hcid.pipeline.parallel).
        noise_free = noise_free_records(config)
        if not (run_dir / tables.SIMULATIONS.file).exists():
            simulation = simulate_study(config, run_dir, jobs=jobs, show_progress=show_progress)
        keys = [(m.name, s) for m in config.models for s in config.seeds]
    check_run_dir(config, run_dir, "identify", force=force)
    if data_path is None:
        records = _load_records(config, run_dir)
    start = time.perf_counter()
    if force:
        results.clear_parts(run_dir)
        redo = {(*k, me) for k in keys for me in names}
        try:
            done = {k: v for k, v in _existing(run_dir).items() if k not in redo}
        except DataError:
            done = {}  # damaged tables: --force recomputes from the records
    else:
        done = _existing(run_dir)
        done.update(results.read_parts(run_dir, _part_kinds()))
    record_config(config, run_dir)
    rate = config.timing.output_rate
    tasks = [
        (config.identify, rate, model, seed, method, records[(model, seed)], noise_free.get(model))
        for model, seed in keys
        for method in names
        if (model, seed, method) not in done
    ]
    reused = sum(1 for k in keys for me in names if (*k, me) in done)
    for key, parts in parallel_map(
        _identify_task,
        tasks,
        jobs=jobs,
        label="identify",
        show_progress=show_progress,
        backend=backend,
        scheduler=scheduler,
        worker_timeout=worker_timeout,
    ):
        results.write_part(run_dir, *key, parts)  # for a resume, if this run is interrupted
        done[key] = parts

    order = _canonical_order(config, done)
    frontier = tables.concat([done[k]["frontier"] for k in order])
    log = tables.concat([_with_worker(done[k]["log"]) for k in order])
    results.write(tables.FRONTIER, frontier, run_dir)
    results.write(tables.IDENTIFY_LOG, log, run_dir)
    choices = {}
    for name, schema in _choice_schemas().items():
        parts = [done[k][name] for k in order if name in done[k]]
        if parts:
            choices[name] = tables.concat(parts)
            results.write(schema, choices[name], run_dir)
    handoff = [done[k]["handoff"] for k in order if "handoff" in done[k]]
    if handoff:
        results.write(tables.HANDOFF, tables.concat(handoff), run_dir)
    results.clear_parts(run_dir)
    if tasks:
        results.append_run_log(run_dir, f"identify ({len(tasks)} tasks)", time.perf_counter() - start, jobs)
    return IdentifyRun(
        frontier=frontier,
        choices=choices,
        log=log,
        computed=len(tasks),
        reused=reused,
        run_dir=run_dir,
        simulation=simulation,
        imported=len(keys) if data_path is not None else 0,
    )


def _with_worker(log: pa.Table) -> pa.Table:
    """A log row of an hcid that did not record the worker gets an empty one."""
    if "worker" in log.column_names:
        return log
    return log.append_column("worker", pa.array([""] * log.num_rows, pa.string()))


def _canonical_order(config: Config, done: dict) -> list[tuple[str, int, str]]:
    """Simulated realizations in config order, then measured runs, each by method (registry order)."""
    names = list(methods.METHODS)
    simulated = [(m.name, s, me) for m in config.models for s in config.seeds for me in names]
    order = [k for k in simulated if k in done]
    seen = set(order)
    rank = {name: i for i, name in enumerate(names)}
    rest = sorted((k for k in done if k not in seen), key=lambda k: (k[0], k[1], rank.get(k[2], len(rank))))
    return order + rest


# --------------------------------------------------------------------------- W sweep


@dataclass(frozen=True)
class SweepRun:
    """Selections over the W grid, exact breakpoints, and thresholds."""

    selection: pa.Table
    breakpoints: pa.Table
    thresholds: pa.Table
    criteria: tuple[criteria.Criterion, ...]
    run_dir: Path
    rates: pa.Table | None = None


@holds_run_dir(create=False)
def sweep_study(config: Config, run_dir: Path) -> SweepRun:
    """Select by ``MSC = log V + W d`` for every realization, method and W of the grid.

    Writes ``selection.parquet`` (one row per model, seed, method and W),
    ``breakpoints.parquet`` (the exact intervals of W over which each
    selection holds), ``thresholds.parquet`` (each configured criterion's W,
    W_FP and W_FN per method and model with their sampling uncertainty, and
    the error rate at each criterion's W, computed from the breakpoints) and
    ``rates.parquet`` (the false-positive rate of a model without feedforward,
    the false-negative rate of one with it, over the W grid with exact 95% bands).
    """
    check_run_dir(config, run_dir, "select")
    frontier = results.read(
        tables.FRONTIER,
        run_dir,
        (*tables.FRONTIER.key, *tables.SELECTED_COLUMNS),
        hint="run `hcid identify` first",
    )
    results.check_against_config(frontier, config, run_dir / tables.FRONTIER.file)
    w = np.asarray(config.selection.w_grid)
    sel_parts, bp_parts = [], []
    segments: dict[tuple[str, str], list] = {}
    nb_ft: dict[tuple[str, str], list] = {}
    for (model, seed, method), (seg, cols) in _selections(frontier, run_dir).items():
        segments.setdefault((model, method), []).append(seg)
        nb_ft.setdefault((model, method), []).append(cols["nb_ft"])
        sel_parts.append(_rows_table(model, seed, method, {"w": w}, cols, seg.at(w)))
        bp_parts.append(
            _rows_table(model, seed, method, {"w_from": seg.w_from, "w_to": seg.w_to}, cols, seg.index)
        )
    selection_table = tables.concat(sel_parts)
    breakpoints_table = tables.concat(bp_parts)
    chosen = criteria.configured(config.selection.criteria)
    thresholds = _thresholds(config, chosen, segments, nb_ft)
    rates = _rates(config, segments, nb_ft, w)
    record_config(config, run_dir)
    results.write(tables.SELECTION, selection_table, run_dir)
    results.write(tables.BREAKPOINTS, breakpoints_table, run_dir)
    results.write(tables.thresholds([c.column for c in chosen]), thresholds, run_dir)
    results.write(tables.RATES, rates, run_dir)
    return SweepRun(selection_table, breakpoints_table, thresholds, chosen, run_dir, rates)


def _selections(frontier: pa.Table, run_dir: Path) -> dict[tuple[str, int, str], tuple]:
    """Per realization and method: its selection over W and its frontier columns."""
    path = run_dir / tables.FRONTIER.file
    out = {}
    for (model, seed, method), t in tables.split_by_key(frontier, tables.FRONTIER.key).items():
        cols = {c: t.column(c).to_numpy() for c in tables.SELECTED_COLUMNS}
        orders = np.column_stack([cols[c] for c in tables.ORDER_COLUMNS])
        try:
            out[(model, seed, method)] = (selection.breakpoints(cols["d"], cols["v"], orders), cols)
        except IdentificationError as exc:
            raise DataError(f"{path}: model {model}, seed {seed}, {method}: {exc}") from exc
    return out


def _rows_table(model, seed, method, w_columns: dict, cols: dict, rows: np.ndarray) -> pa.Table:
    n = rows.size
    data = {
        "model": pa.array([model] * n, pa.string()),
        "seed": pa.array([seed] * n, pa.int64()),
        "method": pa.array([method] * n, pa.string()),
    }
    data.update({k: pa.array(v, pa.float64()) for k, v in w_columns.items()})
    data.update({c: pa.array(cols[c][rows]) for c in tables.SELECTED_COLUMNS})
    return pa.table(data)


def _error(model) -> str:
    """The error a model's realizations are judged for (SPEC 4): FB false positives, FF false negatives."""
    return "false_negative" if model.has_feedforward else "false_positive"


def _uncertainty(method: str, ff: bool, segs: list, nbs: list) -> dict:
    """SPEC 9: P(W_FP >= the paper's) for a study of the paper's size; a bootstrap interval of W_FN."""
    if not ff:
        extents = [selection.false_positive_extent(s, nb) for s, nb in zip(segs, nbs, strict=True)]
        ref = paper.W_FP.get(method)
        p = None if ref is None else selection.threshold_exceedance(extents, ref, paper.N_REALIZATIONS)
        return {"p_w_fp_at_paper": p}
    boot = selection.false_negative_bootstrap(segs, nbs)
    return {
        "w_fn_low": boot.low,
        "w_fn_high": boot.high,
        "p_w_fn_at_paper": boot.share_at_or_above(paper.W_FN),
    }


def _thresholds(config: Config, chosen, segments: dict, nb_ft: dict) -> pa.Table:
    rows = []
    for model in config.models:
        for method in methods.METHODS.values():
            key = (model.name, method.name)
            if key not in segments:
                continue
            nf = method.nf(config.identify)
            ff = model.has_feedforward
            marks = {c.column: c.w(nf) for c in chosen}
            at_marks = calibration.error_rates(
                method.name, model.name, _error(model), segments[key], nb_ft[key], list(marks.values())
            )
            rows.append(
                {
                    "method": method.name,
                    "model": model.name,
                    "has_feedforward": ff,
                    "n_realizations": len(segments[key]),
                    "nf": nf,
                    **marks,
                    "w_fp": None if ff else selection.false_positive_threshold(segments[key], nb_ft[key]),
                    "w_fn": selection.false_negative_threshold(segments[key], nb_ft[key]) if ff else None,
                    **_uncertainty(method.name, ff, segments[key], nb_ft[key]),
                    **{tables.rate_column(c): float(r) for c, r in zip(marks, at_marks.rate, strict=True)},
                }
            )
    return pa.Table.from_pylist(rows, schema=tables.thresholds([c.column for c in chosen]).arrow)


def _rates(config: Config, segments: dict, nb_ft: dict, w: np.ndarray) -> pa.Table:
    parts = []
    for model in config.models:
        for method in methods.METHODS:
            key = (model.name, method)
            if key in segments:
                curve = calibration.error_rates(
                    method, model.name, _error(model), segments[key], nb_ft[key], w
                )
                parts.append(curve.to_arrow())
    return tables.concat(parts) if parts else tables.RATES.arrow.empty_table()


# --------------------------------------------------------------------------- the whole study


@dataclass(frozen=True)
class StudyRun:
    """A whole study: its identification (with the simulation if it was made) and its W sweep."""

    identification: IdentifyRun
    sweep: SweepRun
    seconds: float


@holds_run_dir(create=True)
def run_study(
    config: Config,
    run_dir: Path,
    *,
    jobs: int = 2,
    backend: str = "loky",
    scheduler: str | None = None,
    worker_timeout: float = 60.0,
    show_progress: bool = True,
) -> StudyRun:
    """Simulate (if missing), identify every method (what is not done yet), then sweep W."""
    config.require_simulation("run")
    start = time.perf_counter()
    identification = identify_study(
        config,
        run_dir,
        jobs=jobs,
        backend=backend,
        scheduler=scheduler,
        worker_timeout=worker_timeout,
        show_progress=show_progress,
    )
    sweep = sweep_study(config, run_dir)
    return StudyRun(identification, sweep, time.perf_counter() - start)


# --------------------------------------------------------------------------- W calibration


@dataclass(frozen=True)
class CalibrationRun:
    """Calibration of W per method from the config's FB and FF twins, after the study it ran."""

    calibrations: list
    study: StudyRun
    run_dir: Path


@holds_run_dir(create=True)
def calibrate_study(
    config: Config,
    run_dir: Path,
    *,
    jobs: int = 2,
    backend: str = "loky",
    scheduler: str | None = None,
    worker_timeout: float = 60.0,
    show_progress: bool = True,
) -> CalibrationRun:
    """Run the study of the config's HC hypothesis (what is not done yet), then compute
    false-positive and false-negative rates over W and the safe interval per method.

    Writes ``calibration.parquet`` (one row per method and W of the grid, with the
    safe interval and recommended W repeated on every row).
    """
    config.require_simulation("calibrate-w")
    fb = next((m for m in config.models if not m.has_feedforward), None)
    ff = next((m for m in config.models if m.has_feedforward), None)
    if fb is None or ff is None:
        raise ConfigError(
            "models: calibration needs a feedback-only model (Kpt = 0) and a feedforward "
            f"model (Kpt > 0), got {[m.name for m in config.models]}"
        )
    study = run_study(
        config,
        run_dir,
        jobs=jobs,
        backend=backend,
        scheduler=scheduler,
        worker_timeout=worker_timeout,
        show_progress=show_progress,
    )
    chosen = _selections(results.read(tables.FRONTIER, run_dir), run_dir)
    out = []
    for method in methods.METHODS:
        twins = []
        for model in (fb, ff):
            keys = [(model.name, s, method) for s in config.seeds]
            twins.append(([chosen[k][0] for k in keys], [chosen[k][1]["nb_ft"] for k in keys]))
        w = np.asarray(config.selection.w_grid)
        out.append(calibrate(method, twins[0], twins[1], w, config.selection.target_rate))
    results.write(tables.CALIBRATION, tables.concat([c.to_arrow() for c in out]), run_dir)
    return CalibrationRun(out, study, run_dir)
