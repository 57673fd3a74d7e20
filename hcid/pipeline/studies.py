"""The stages of a study over models x seeds (or measured runs) x methods, and the whole study.

Each ``*_study`` function reads what it needs from the run directory, runs its
tasks on an :class:`~hcid.pipeline.execution.Execution`, writes its tables
atomically and returns them. :func:`run_study` owns the chain "simulate if
missing, identify what is not done, sweep W"; the CLI calls one of these.
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import methods, tables
from hcid.assembly.resolve import with_data
from hcid.config import Config, IdentifyConfig
from hcid.errors import ConfigError, DataError
from hcid.io import datasets, results
from hcid.loop.simulate import remnant_gain, simulate_realization
from hcid.pipeline.execution import Execution
from hcid.pipeline.measured_data import check_data, import_data, write_skipped
from hcid.pipeline.parallel import compile_before_fork
from hcid.pipeline.rundir import check_run_dir, holds_run_dir, record_config, using
from hcid.pipeline.sweep import SweepRun, selections, sweep_study
from hcid.selection.calibration import Selections, calibrate
from hcid.selection.frontier import Frontier

__all__ = [
    "CalibrationRun",
    "IdentifyRun",
    "SimulationRun",
    "StudyRun",
    "calibrate_study",
    "identify_studies",
    "identify_study",
    "run_study",
    "simulate_studies",
    "simulate_study",
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
    """One simulation run: its records by (model, seed) as written to ``simulations.parquet``
    (:func:`hcid.io.results.records`' arrays), its summary table and where they were written."""

    records: dict[tuple[str, int], dict[str, np.ndarray]]
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
    return simulate_studies([(config, run_dir)], execution=execution, force=force)[0]


def simulate_studies(
    studies: Sequence[tuple[Config, Path]], *, execution: Execution = Execution(), force: bool = False
) -> list[SimulationRun]:
    """:func:`simulate_study` of several ``(config, run_dir)`` at once: their tasks in one pool, so
    that the workers stay busy across them (many small studies, e.g. a group's twins of every
    forcing set); each run directory's tables are those its own simulation writes."""
    with contextlib.ExitStack() as held:
        for config, run_dir in studies:
            held.enter_context(using(Path(run_dir)))
            config.require_simulation("simulate")
            check_run_dir(config, Path(run_dir), "simulate", force=force)
        start = time.perf_counter()
        kns = [remnant_gain(config) for config, _ in studies]
        tasks = [
            [(config, m.name, seed, kn) for m in config.models for seed in config.seeds]
            for (config, _), kn in zip(studies, kns, strict=True)
        ]
        pairs = execution.run(_simulate_task, [t for each in tasks for t in each], "simulate")
        seconds = time.perf_counter() - start
        out, first = [], 0
        for (config, run_dir), kn, each in zip(studies, kns, tasks, strict=True):
            mine, first = pairs[first : first + len(each)], first + len(each)
            realizations = [p[0] for p in mine]
            simulations = results.realizations_table(realizations)
            summary = results.summary_table(realizations, [p[1] for p in mine])
            record_config(config, Path(run_dir))
            results.write(tables.SIMULATIONS, simulations, Path(run_dir))
            results.write(tables.SIMULATION_SUMMARY, summary, Path(run_dir))
            results.append_run_log(Path(run_dir), "simulate", seconds, execution.jobs)
            records = results.records_of(realizations)
            out.append(SimulationRun(records=records, summary=summary, kn=kn, run_dir=Path(run_dir)))
    return out


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
    """The identification of a run: each record's frontier per method, each choosing stage's
    choice per record (``choices``: stage -> (model, seed) -> StageChoice) and the log table.

    ``simulation`` is set when the run had no simulations and they were made
    first; ``imported`` counts the measured runs read from a data file.
    """

    frontiers: dict[tuple[str, int, str], Frontier]
    choices: dict[str, dict[tuple[str, int], methods.StageChoice]]
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


def _choice_stages() -> list:
    """Every registered method's choosing stages (:class:`hcid.methods.StageSpec`)."""
    return [s for m in methods.METHODS.values() for s in m.choice_stages]


def _choice_schemas() -> dict[str, tables.Schema]:
    return {s.name: tables.stage_choice(s.name, s.inputs) for s in _choice_stages()}


def _existing(run_dir: Path) -> dict[tuple[str, int, str], dict[str, pa.Table]]:
    """Finished realizations of the run's assembled tables, keyed by (model, seed, method)."""
    if not (run_dir / tables.FRONTIER.file).is_file():
        return {}
    hint = "use --force to recompute it"
    key = tables.FRONTIER.key
    frontier = results.read(tables.FRONTIER, run_dir, hint=hint)  # every column: it is kept as it is
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
    config: Config, run_dir: Path, made: dict | None = None
) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """Each simulated record by (model, seed): ``made`` where the caller has just made the
    simulations (not read back), else from the run's ``simulations.parquet``."""
    path = run_dir / tables.SIMULATIONS.file
    if made is None:
        table = results.read(tables.SIMULATIONS, run_dir, hint="run `hcid simulate` first")
        recs = results.records(table, path)
    else:
        results.check_records(made, path)
        recs = made
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


def _write_identification(config: Config, run_dir: Path, done: dict) -> tuple[dict, dict, pa.Table]:
    """Write frontier, identify_log, each choosing stage's table and the handoff; drop the parts.
    Returns the frontiers by (model, seed, method), the choosing stages' choices and the log.
    A frontier kept from an earlier run is checked against the config as one read is."""
    order = _canonical_order(config, done)
    frontier = results.concat([done[k]["frontier"] for k in order])
    results.check_against_config(frontier, config, run_dir / tables.FRONTIER.file)
    log = results.concat([_with_worker(done[k]["log"]) for k in order])
    results.write(tables.FRONTIER, frontier, run_dir)
    results.write(tables.IDENTIFY_LOG, log, run_dir)
    choices = {}
    for stage in _choice_stages():
        parts = [done[k][stage.name] for k in order if stage.name in done[k]]
        if parts:
            table = results.concat(parts)
            results.write(tables.stage_choice(stage.name, stage.inputs), table, run_dir)
            choices[stage.name] = results.stage_choices_of(table, stage)
    handoff = [done[k]["handoff"] for k in order if "handoff" in done[k]]
    if handoff:
        results.write(tables.HANDOFF, results.concat(handoff), run_dir)
    results.clear_parts(run_dir)
    return {k: Frontier.from_table(done[k]["frontier"]) for k in order}, choices, log


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

    With ``data`` (a measured data set, read once: :func:`hcid.assembly.resolve.read_study`), its
    runs are identified instead, under model name ``config.data.name`` and seed = run id (the
    file's own for one file; 1, 2, ... over a set of files, whose files and factors
    ``runs.parquet`` keeps), beside any simulated realizations already in the tables.
    ``method_names`` defaults to every registered method.
    """
    if data is None:
        return identify_studies([(config, run_dir, method_names)], execution=execution, force=force)[0]
    names = _method_names(method_names)
    config = with_data(config)
    execution.check()  # a dask scheduler without workers is refused before anything is written
    check_data(config, data)
    import_data(config, run_dir, data, force)
    records = {(config.data.name, run): rec for run, rec in data.records.items()}
    check_run_dir(config, run_dir, "identify", force=force)
    job = _prepare_identification(config, run_dir, names, records, list(records), {}, None, force)
    _run_identifications([job], execution)
    return _finish_identification(job, execution, data)


def identify_studies(
    studies: Sequence[tuple[Config, Path, Sequence[str] | None]],
    *,
    execution: Execution = Execution(),
    force: bool = False,
) -> list[IdentifyRun]:
    """:func:`identify_study` of several simulated studies ``(config, run_dir, method_names)`` at
    once: the ones without simulations simulated together (:func:`simulate_studies`), then every
    identification task in one pool, so that the workers stay busy across them (a group's twins
    of every forcing set, the twins of every group); each run directory's tables are those its
    own :func:`identify_study` writes, bit for bit."""
    names = [_method_names(n) for _, _, n in studies]
    with contextlib.ExitStack() as held:
        for _, run_dir, _ in studies:
            held.enter_context(using(Path(run_dir)))
        execution.check()  # a dask scheduler without workers is refused before anything is written
        for config, _, _ in studies:
            config.require_simulation("identify (without --data)")
        # Before the simulations: forked workers then start with this process's loops,
        # forcing functions and compiled loop kernel (hcid.pipeline.parallel).
        noise_free = [noise_free_records(config) for config, _, _ in studies]
        missing = [
            i
            for i, (_, run_dir, _) in enumerate(studies)
            if not (Path(run_dir) / tables.SIMULATIONS.file).exists()
        ]
        made = dict(
            zip(
                missing, simulate_studies([studies[i][:2] for i in missing], execution=execution), strict=True
            )
        )
        jobs = []
        for i, (config, run_dir, _) in enumerate(studies):
            run_dir = Path(run_dir)
            keys = [(m.name, s) for m in config.models for s in config.seeds]
            check_run_dir(config, run_dir, "identify", force=force)
            simulation = made.get(i)
            records = _load_records(config, run_dir, simulation.records if simulation else None)
            jobs.append(
                _prepare_identification(
                    config, run_dir, names[i], records, keys, noise_free[i], simulation, force
                )
            )
        _run_identifications(jobs, execution)
        return [_finish_identification(job, execution, None) for job in jobs]


def _method_names(method_names: Sequence[str] | None) -> tuple[str, ...]:
    names = tuple(methods.METHODS) if method_names is None else tuple(method_names)
    for name in names:
        methods.get(name)
    return names


@dataclass
class _Identification:
    """One run directory's identification in the making: its tasks, and what they add to."""

    config: Config
    run_dir: Path
    keys: list
    names: tuple[str, ...]
    done: dict
    tasks: list
    reused: int
    simulation: SimulationRun | None
    start: float


def _prepare_identification(config, run_dir, names, records, keys, noise_free, simulation, force):
    """What is left to identify in ``run_dir`` (finished tasks kept unless ``force``)."""
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
    return _Identification(config, run_dir, keys, names, done, tasks, reused, simulation, start)


def _identify_in(index: int, *task):
    """:func:`_identify_task` of one task of the ``index``-th run directory (:func:`identify_studies`)."""
    return index, *_identify_task(*task)


def _run_identifications(jobs: Sequence[_Identification], execution: Execution) -> None:
    """Every job's tasks in one pool, each result kept as a part (for a resume) as it arrives."""
    tasks = [(i, *task) for i, job in enumerate(jobs) for task in job.tasks]
    if tasks and execution.backend == "loky":
        compile_before_fork()  # once, here: forked workers start with them (hcid.pipeline.parallel)
    for i, key, parts in execution.map(_identify_in, tasks, "identify"):
        results.write_part(jobs[i].run_dir, *key, parts)  # for a resume, if this run is interrupted
        jobs[i].done[key] = parts


def _finish_identification(job: _Identification, execution: Execution, data) -> IdentifyRun:
    frontiers, choices, log = _write_identification(job.config, job.run_dir, job.done)
    if data is not None:
        write_skipped(job.run_dir, data)
    if job.tasks:
        results.append_run_log(
            job.run_dir, f"identify ({len(job.tasks)} tasks)", time.perf_counter() - job.start, execution.jobs
        )
    return IdentifyRun(
        frontiers=frontiers,
        choices=choices,
        log=log,
        computed=len(job.tasks),
        reused=job.reused,
        run_dir=job.run_dir,
        simulation=job.simulation,
        imported=len(job.keys) if data is not None else 0,
        set_aside=data.set_aside if data is not None else (),
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
    sweep = sweep_study(config, run_dir, identification.frontiers)
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
    config: Config,
    run_dir: Path,
    models: Sequence[str],
    method_names: Sequence[str] | None = None,
    frontiers: dict[tuple[str, int, str], Frontier] | None = None,
) -> dict[str, tuple[Selections, ...]]:
    """Per method (``method_names``, default every registered one), each of ``models``' seeds'
    selection paths and nb_ft, in the order of ``models``: what rates at any W are taken from.
    ``frontiers``: the run's, where the caller has just made them (not read back)."""
    if frontiers is None:
        frontiers = results.frontiers(results.read(tables.FRONTIER, run_dir))
    chosen = selections(frontiers, run_dir)
    out = {}
    for method in methods.METHODS if method_names is None else method_names:
        per_model = []
        for model in models:
            mine = [chosen[(model, s, method)] for s in config.seeds]
            per_model.append(Selections([c.path for c in mine], [c.frontier.nb_ft for c in mine]))
        out[method] = tuple(per_model)
    return out


def calibrate_paths(config: Config, run_dir: Path, paths: dict[str, tuple[Selections, Selections]]) -> list:
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
    paths = model_paths(config, run_dir, (fb.name, ff.name), frontiers=study.identification.frontiers)
    return CalibrationRun(calibrate_paths(config, run_dir, paths), study, run_dir, paths)
