"""The stages of a study over models x seeds (or measured runs) x methods, and the whole study.

Each ``*_study`` function reads what it needs from the run directory, runs its
tasks on an :class:`~hcid.pipeline.execution.Execution`, writes its tables
atomically and returns them. :func:`run_study` owns the chain "simulate if
missing, identify what is not done, sweep W"; the CLI calls one of these.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import methods, tables
from hcid.analysis.fourier import PLANT_MISMATCH_LIMIT, is_other_plant, plant_mismatch
from hcid.config import Config, IdentifyConfig
from hcid.errors import ConfigError, DataError
from hcid.io import datasets, measured, results
from hcid.io.resolve import with_data
from hcid.loop.simulate import remnant_gain, simulate_realization
from hcid.pipeline.execution import Execution
from hcid.pipeline.parallel import compile_before_fork
from hcid.pipeline.plants import RunPlants, run_plants
from hcid.pipeline.rundir import check_run_dir, holds_run_dir, record_config
from hcid.pipeline.sweep import SweepRun, selections, sweep_study
from hcid.selection.calibration import calibrate

__all__ = [
    "CalibrationRun",
    "IdentifyRun",
    "SimulationRun",
    "StudyRun",
    "calibrate_study",
    "check_plant",
    "identify_study",
    "run_study",
    "simulate_study",
    "write_skipped",
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
    config: Config, run_dir: Path, *, execution: Execution = Execution(), force: bool = False
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
    pairs = execution.run(_simulate_task, tasks, "simulate")
    realizations = [p[0] for p in pairs]
    simulations = results.realizations_table(realizations)
    summary = results.summary_table(realizations, [p[1] for p in pairs])
    record_config(config, run_dir)
    results.write(tables.SIMULATIONS, simulations, run_dir)
    results.write(tables.SIMULATION_SUMMARY, summary, run_dir)
    results.append_run_log(run_dir, "simulate", time.perf_counter() - start, execution.jobs)
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
    #: Measured files left out (``skip_unreadable``): (path, reason).
    set_aside: tuple[tuple[str, str], ...] = ()


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
    logs = results.split_by_key(results.read(tables.IDENTIFY_LOG, run_dir, key, hint=hint), key)
    choices = {}
    for name, schema in _choice_schemas().items():
        table = results.read_optional(schema, run_dir, schema.key)
        choices[name] = results.split_by_key(table, schema.key) if table is not None else {}
    handoff = results.read_optional(tables.HANDOFF, run_dir)
    handoffs = results.split_by_key(handoff, key) if handoff is not None else {}
    out = {}
    for k, table in results.split_by_key(frontier, key).items():
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


def _load_records(
    config: Config, run_dir: Path, table: pa.Table | None = None
) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """Each simulated record by (model, seed): from ``table`` where the caller has just made the
    simulations (not read back), else from the run's ``simulations.parquet``."""
    if table is None:
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


def _import_data(config: Config, run_dir: Path, data_set: datasets.DataSet, force: bool) -> None:
    """Keep a copy of a data set in ``measured.parquet`` and its runs' factors in
    ``runs.parquet``. Other data than the run's earlier identification results were made from
    are refused without ``force``: their results would be reused as if they were these data's."""
    data = config.data
    check_run_dir(config, run_dir, "identify", force=force)
    table = measured.records_table(data.name, data_set.records)
    if not force:
        old = results.read_optional(tables.MEASURED, run_dir)
        if old is not None and (run_dir / tables.FRONTIER.file).exists() and not old.equals(table):
            raise DataError(
                f"{run_dir}: holds identification results of other measured data (its "
                f"{tables.MEASURED.file} differs from these files); use --force to replace them, "
                "or another --run"
            )
    record_config(config, run_dir)
    results.write(tables.MEASURED, table, run_dir)
    results.write(tables.RUNS, datasets.runs_table(data.name, data_set), run_dir)


def _done(run_dir: Path, keys: list, names: tuple[str, ...], force: bool) -> dict:
    """The finished (model, seed, method) tasks to keep: tables and an interrupted run's parts."""
    if not force:
        done = _existing(run_dir)
        done.update(results.read_parts(run_dir, _part_kinds()))
        return done
    results.clear_parts(run_dir)
    redo = {(*k, me) for k in keys for me in names}
    try:
        return {k: v for k, v in _existing(run_dir).items() if k not in redo}
    except DataError:
        return {}  # damaged tables: --force recomputes from the records


def _write_identification(config: Config, run_dir: Path, done: dict) -> tuple[pa.Table, dict, pa.Table]:
    """Write frontier, identify_log, each choosing stage's table and the handoff; drop the parts."""
    order = _canonical_order(config, done)
    frontier = results.concat([done[k]["frontier"] for k in order])
    log = results.concat([_with_worker(done[k]["log"]) for k in order])
    results.write(tables.FRONTIER, frontier, run_dir)
    results.write(tables.IDENTIFY_LOG, log, run_dir)
    choices = {}
    for name, schema in _choice_schemas().items():
        parts = [done[k][name] for k in order if name in done[k]]
        if parts:
            choices[name] = results.concat(parts)
            results.write(schema, choices[name], run_dir)
    handoff = [done[k]["handoff"] for k in order if "handoff" in done[k]]
    if handoff:
        results.write(tables.HANDOFF, results.concat(handoff), run_dir)
    results.clear_parts(run_dir)
    return frontier, choices, log


@holds_run_dir(create=True)
def identify_study(
    config: Config,
    run_dir: Path,
    method_names: Sequence[str] | None = None,
    *,
    data: datasets.DataSet | None = None,
    execution: Execution = Execution(),
    force: bool = False,
) -> IdentifyRun:
    """Identify every model x seed x method of ``config``, simulating first if the run has no simulations.

    Realizations already in ``frontier.parquet`` (or finished by an
    interrupted run, in ``.parts/``) are not recomputed unless ``force``.
    Writes ``frontier.parquet``, one table per choosing stage
    (``stage1.parquet``) and ``identify_log.parquet``; the first two are
    identical whatever ``execution`` (jobs, backend) or interruptions.

    With ``data`` (a measured data set, read once: :func:`hcid.io.resolve.read_study`), its
    runs are identified instead, under model name ``config.data.name`` and seed = run id (the
    file's own for one file; 1, 2, ... over a set of files, whose files and factors
    ``runs.parquet`` keeps), beside any simulated realizations already in the tables.
    ``method_names`` defaults to every registered method.
    """
    names = tuple(methods.METHODS) if method_names is None else tuple(method_names)
    for name in names:
        methods.get(name)
    if data is not None:
        config = with_data(config)
    execution.check()  # a dask scheduler without workers is refused before anything is written
    records, keys, noise_free, simulation = _records_to_identify(config, run_dir, data, execution, force)
    start = time.perf_counter()
    done = _done(run_dir, keys, names, force)
    record_config(config, run_dir)
    rate = config.timing.output_rate
    tasks = [
        (config.identify, rate, model, seed, method, records[(model, seed)], noise_free.get(model))
        for model, seed in keys
        for method in names
        if (model, seed, method) not in done
    ]
    reused = sum(1 for k in keys for me in names if (*k, me) in done)
    if tasks and execution.backend == "loky":
        compile_before_fork()  # once, here: forked workers start with them (hcid.pipeline.parallel)
    for key, parts in execution.map(_identify_task, tasks, "identify"):
        results.write_part(run_dir, *key, parts)  # for a resume, if this run is interrupted
        done[key] = parts

    frontier, choices, log = _write_identification(config, run_dir, done)
    if data is not None:
        write_skipped(run_dir, data)
    if tasks:
        results.append_run_log(
            run_dir, f"identify ({len(tasks)} tasks)", time.perf_counter() - start, execution.jobs
        )
    return IdentifyRun(
        frontier=frontier,
        choices=choices,
        log=log,
        computed=len(tasks),
        reused=reused,
        run_dir=run_dir,
        simulation=simulation,
        imported=len(keys) if data is not None else 0,
        set_aside=data.set_aside if data is not None else (),
    )


def _check_data(config: Config, data: datasets.DataSet) -> None:
    """A data set made for this config: at its analysis rate, every run as long as its windows
    need (what :func:`hcid.io.resolve.read_study` gives; a data set read otherwise may not be)."""
    rate = config.timing.output_rate
    if not np.isclose(data.rate, rate, rtol=1e-9):
        raise DataError(
            f"data: the data set is at {data.rate:g} Hz, the config analyses at {rate:g} Hz; read it "
            "for this config (hcid.io.resolve.read_study)"
        )
    need = measured.samples_needed(config)
    short = next((run for run, rec in data.records.items() if rec["u"].size < need), None)
    if short is not None:
        raise DataError(
            f"data: run {short} holds {data.records[short]['u'].size} samples, the config's windows "
            f"need {need}; read it for this config (hcid.io.resolve.read_study)"
        )
    check_plant(config, data)


def write_skipped(run_dir: Path, data: datasets.DataSet) -> None:
    """``skipped.parquet``: the files a folder or glob of the data set found that are not runs."""
    rows = [{"file": f, "reason": why} for f, why in data.skipped]
    results.write(tables.SKIPPED, pa.Table.from_pylist(rows, schema=tables.SKIPPED.arrow), run_dir)


def check_plant(config: Config, data: datasets.DataSet, plants: RunPlants | None = None) -> None:
    """Refuse runs whose e is not ft minus the configured plant's output (a data set of another
    plant, or the disturbance at the other point): every result would be for the wrong loop.
    Each run is checked over the analysis window (where its multisines have whole periods; a
    single-input run at its input's lines) against its own plant (``plants``, from
    :func:`hcid.pipeline.plants.run_plants` where not given); runs whose forcing functions have no
    lines there, a config without a loop (identification alone) and one with
    ``data.plant_check: false`` are not checked."""
    loop, rate = config.loop, config.timing.output_rate
    if loop is None:
        return
    plants = run_plants(config, data) if plants is None else plants  # the factor checked first
    if not config.data.plant_check:
        return
    n = config.timing.record_samples
    found = {
        run: plant_mismatch({k: rec[k][:n] for k in ("ft", "fd", "e", "u")}, rate,
                            plants.plant_of(run).num, plants.plant_of(run).den, loop.disturbance_at)
        for run, rec in data.records.items()
    }  # fmt: skip
    over = {run: m for run, m in found.items() if is_other_plant(m)}
    if not over:
        return
    worst = max(over, key=over.get)
    file = next((r["file"] for r in data.runs if r.get("run") == worst), None)
    key = "loop.plant" if plants.factor is None else f"loop.plant.levels.{plants.level_of[worst]}"
    raise DataError(
        f"data: run {worst}{f' ({file})' if file else ''} is not the configured plant: "
        f"{over[worst]:.0%} (RMS) of its theta = ft - e at the forcing lines is not what "
        f"{key} {plants.plant_of(worst).text} with the disturbance at its {loop.disturbance_at} gives "
        f"({len(over)} of {len(found)} runs over {PLANT_MISMATCH_LIMIT:.0%}); check loop.plant and "
        "loop.disturbance_at, or the data files (data.plant_check: false where the plant leaves out "
        "a display delay)"
    )


def _records_to_identify(config: Config, run_dir: Path, data, execution: Execution, force: bool):
    """The records to identify by (model, seed) and their keys in order, each simulated model's
    noise-free record, and the simulation if it was made here (a study without one yet)."""
    if data is not None:
        _check_data(config, data)
        _import_data(config, run_dir, data, force)
        records = {(config.data.name, run): rec for run, rec in data.records.items()}
        check_run_dir(config, run_dir, "identify", force=force)
        return records, list(records), {}, None
    config.require_simulation("identify (without --data)")
    # Before the simulations: forked workers then start with this process's loops,
    # forcing functions and compiled loop kernel (hcid.pipeline.parallel).
    noise_free = noise_free_records(config)
    simulation = None
    if not (run_dir / tables.SIMULATIONS.file).exists():
        simulation = simulate_study(config, run_dir, execution=execution)
    keys = [(m.name, s) for m in config.models for s in config.seeds]
    check_run_dir(config, run_dir, "identify", force=force)
    made = simulation.simulations if simulation is not None else None
    return _load_records(config, run_dir, made), keys, noise_free, simulation


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
    execution: Execution = Execution(),
) -> StudyRun:
    """Simulate (if missing), identify every method (what is not done yet), then sweep W."""
    config.require_simulation("run")
    start = time.perf_counter()
    identification = identify_study(config, run_dir, execution=execution)
    sweep = sweep_study(config, run_dir, identification.frontier)
    return StudyRun(identification, sweep, time.perf_counter() - start)


# --------------------------------------------------------------------------- W calibration


@dataclass(frozen=True)
class CalibrationRun:
    """Calibration of W per method from the config's FB and FF twins, after the study it ran."""

    calibrations: list
    study: StudyRun
    run_dir: Path
    #: Per method, the FB and FF twins' selection paths and nb_ft (:func:`model_paths`).
    paths: dict = field(default_factory=dict)


def model_paths(
    config: Config, run_dir: Path, models: Sequence[str], method_names: Sequence[str] | None = None
) -> dict[str, tuple]:
    """Per method (``method_names``, default every registered one), each of ``models``' seeds'
    selection paths and nb_ft, in the order of ``models``: what rates at any W are taken from."""
    chosen = selections(results.read(tables.FRONTIER, run_dir), run_dir)
    out = {}
    for method in methods.METHODS if method_names is None else method_names:
        pair = []
        for model in models:
            keys = [(model, s, method) for s in config.seeds]
            pair.append(([chosen[k][0] for k in keys], [chosen[k][1]["nb_ft"] for k in keys]))
        out[method] = tuple(pair)
    return out


def calibrate_paths(config: Config, run_dir: Path, paths: dict[str, tuple]) -> list:
    """Per method, W calibrated on its (FB, FF) twins' selection ``paths`` over the config's W
    grid; written to ``calibration.parquet``."""
    w = np.asarray(config.selection.w_grid)
    out = [calibrate(m, *paths[m], w, config.selection.target_rate) for m in methods.METHODS]
    results.write(tables.CALIBRATION, results.concat([c.to_arrow() for c in out]), run_dir)
    return out


@holds_run_dir(create=True)
def calibrate_study(
    config: Config,
    run_dir: Path,
    *,
    execution: Execution = Execution(),
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
    study = run_study(config, run_dir, execution=execution)
    paths = model_paths(config, run_dir, (fb.name, ff.name))
    return CalibrationRun(calibrate_paths(config, run_dir, paths), study, run_dir, paths)
