"""Batch runs over models x seeds on a joblib pool, with a progress bar.

Each task is one realization; results come back in task order whatever the
number of workers, and every task is deterministic in its seed, so the tables
are identical for any ``jobs``.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from hcid import results, selection
from hcid.config import Config, IdentifyConfig
from hcid.errors import ConfigError, DataError, HcidError, IdentificationError
from hcid.identify import METHODS, identify
from hcid.simulate import remnant_gain, simulate_realization

__all__ = [
    "CalibrationRun",
    "IdentifyRun",
    "SimulationRun",
    "SweepRun",
    "check_run_dir",
    "calibrate_study",
    "identify_study",
    "import_data",
    "parallel_map",
    "simulate_study",
    "sweep_study",
]

BACKENDS = ("loky", "dask")


def _first_difference(a: Any, b: Any, path: str = "") -> str | None:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in list(a) + [k for k in b if k not in a]:
            where = f"{path}.{key}" if path else str(key)
            if key not in a or key not in b:
                return where
            found = _first_difference(a[key], b[key], where)
            if found:
                return found
        return None
    return None if a == b else (path or "<top>")


#: Config sections each stage's tables depend on, and the tables that go stale with them.
SIMULATION_SECTIONS = ("models", "loop", "signals", "timing", "seeds")
IDENTIFICATION_SECTIONS = (*SIMULATION_SECTIONS, "identify", "data")
_IDENTIFICATION_TABLES = (
    results.FRONTIER,
    results.STAGE1,
    results.IDENTIFY_LOG,
    results.SELECTION,
    results.BREAKPOINTS,
    results.THRESHOLDS,
    results.CALIBRATION,
    results.MEASURED,
)


def check_run_dir(config: Config, run_dir: Path, stage: str, *, force: bool = False) -> None:
    """Refuse to mix results of two configs in one run directory.

    ``stage`` is 'simulate', 'identify' or 'select'. If ``run_dir/config.yaml``
    differs from ``config`` in a section the stage's inputs depend on, raise
    :class:`DataError` naming the first differing key, unless ``force``: then
    the tables made from the old sections are removed (simulate: every table;
    identify: identification and later). A difference only in later sections
    (e.g. the W grid for a sweep) is fine; the stage's caller records the new
    config when it writes.
    """
    import yaml

    if run_dir.exists() and not run_dir.is_dir():
        raise DataError(f"{run_dir}: not a directory; choose another --run")
    path = run_dir / "config.yaml"
    if not path.is_file():
        return
    try:
        previous = yaml.safe_load(path.read_text())
        if not isinstance(previous, dict):
            raise TypeError
    except (yaml.YAMLError, OSError, TypeError) as exc:
        raise DataError(
            f"{path}: not a readable config; remove the run directory or use another --run"
        ) from exc
    current = yaml.safe_load(config.to_yaml())
    if stage == "simulate":
        sections, stale, redo = SIMULATION_SECTIONS, None, "hcid simulate --force"
    elif stage == "identify":
        sim_key = _first_difference(
            {k: previous.get(k) for k in SIMULATION_SECTIONS},
            {k: current.get(k) for k in SIMULATION_SECTIONS},
        )
        if sim_key is not None:
            raise DataError(
                f"{run_dir}: simulated with another config ({sim_key} differs); "
                "use `hcid simulate --force` to redo it or --run for another directory"
            )
        sections, stale, redo = IDENTIFICATION_SECTIONS, _IDENTIFICATION_TABLES, "hcid identify --force"
    else:
        sections, stale, redo = IDENTIFICATION_SECTIONS, None, "hcid identify --force"
    key = _first_difference({k: previous.get(k) for k in sections}, {k: current.get(k) for k in sections})
    if key is None:
        return
    if not force:
        raise DataError(
            f"{run_dir}: made with another config ({key} differs); use `{redo}` to redo it "
            "or --run for another directory"
        )
    tables = run_dir.glob("*.parquet") if stale is None else (run_dir / name for name in stale)
    for table in tables:
        table.unlink(missing_ok=True)
    results.clear_parts(run_dir)


def _record_config(config: Config, run_dir: Path) -> None:
    results.write_text(config.to_yaml(), run_dir / "config.yaml")


def parallel_map(
    func: Callable[..., Any],
    tasks: Sequence[tuple],
    *,
    jobs: int,
    label: str,
    show_progress: bool = True,
    backend: str = "loky",
    scheduler: str | None = None,
) -> Iterable[Any]:
    """Yield ``func(*task)`` for every task, in task order, on ``jobs`` workers.

    A progress bar on stderr counts finished tasks; ``jobs = 1`` runs
    in-process. ``backend = 'dask'`` sends the tasks to a dask.distributed
    scheduler at ``scheduler`` (``tcp://host:port``), or to a local cluster of
    ``jobs`` single-threaded worker processes when ``scheduler`` is None.
    """
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    if backend not in BACKENDS:
        raise HcidError(f"--backend: must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if not tasks:
        return
    with contextlib.ExitStack() as stack:
        stream = _stream(func, tasks, jobs, backend, scheduler, stack)
        progress = stack.enter_context(
            Progress(
                "[progress.description]{task.description}",
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
                disable=not show_progress,
            )
        )
        bar = progress.add_task(label, total=len(tasks))
        for result in stream:
            progress.advance(bar)
            yield result


def _stream(func, tasks, jobs, backend, scheduler, stack: contextlib.ExitStack) -> Iterator:
    from joblib import Parallel, delayed, parallel_config

    if backend == "loky" and jobs == 1:
        return (func(*task) for task in tasks)
    if backend == "dask":
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:
            raise HcidError("--backend dask: needs dask.distributed (pip install 'hcid[dask]')") from exc
        if scheduler:
            try:
                client = stack.enter_context(Client(scheduler, timeout="20s"))
            except OSError as exc:
                raise HcidError(f"--scheduler: cannot reach {scheduler} ({exc})") from exc
        else:
            cluster = stack.enter_context(
                LocalCluster(
                    n_workers=jobs,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    host="127.0.0.1",
                )
            )
            client = stack.enter_context(Client(cluster))
        del client
        stack.enter_context(parallel_config(backend="dask"))
    return Parallel(n_jobs=jobs, backend=None if backend == "dask" else backend, return_as="generator")(
        delayed(func)(*task) for task in tasks
    )


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


def simulate_study(
    config: Config,
    run_dir: Path,
    *,
    jobs: int = 2,
    show_progress: bool = True,
    force: bool = False,
) -> SimulationRun:
    """Simulate every model x seed of ``config`` and write the run's tables.

    Writes ``config.yaml``, ``simulations.parquet`` and
    ``simulation_summary.parquet`` in ``run_dir``, each atomically.
    """
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
    _record_config(config, run_dir)
    results.write_table(simulations, run_dir / results.SIMULATIONS)
    results.write_table(summary, run_dir / results.SIMULATION_SUMMARY)
    results.append_run_log(run_dir, "simulate", time.perf_counter() - start, jobs)
    return SimulationRun(simulations=simulations, summary=summary, kn=kn, run_dir=run_dir)


# --------------------------------------------------------------------------- identification


def _identify_task(
    settings: IdentifyConfig, rate: float, model: str, seed: int, method: str, record: dict[str, np.ndarray]
):
    result = identify(record, settings, method, rate=rate, threads=1)
    return (model, seed, method), results.frontier_part(model, seed, result)


@dataclass(frozen=True)
class IdentifyRun:
    """Tables of the identification of a run."""

    frontier: pa.Table
    stage1: pa.Table
    log: pa.Table
    computed: int
    reused: int
    run_dir: Path


def _existing(run_dir: Path) -> dict[tuple[str, int, str], dict[str, pa.Table]]:
    """Finished realizations of the run's assembled tables, keyed by (model, seed, method)."""
    path = run_dir / results.FRONTIER
    if not path.is_file():
        return {}
    hint = "use --force to recompute it"
    frontier = results.read_table(path, results.KEY_COLUMNS, hint=hint)
    log = results.read_table(run_dir / results.IDENTIFY_LOG, results.KEY_COLUMNS, hint=hint)
    stage1_path = run_dir / results.STAGE1
    stage1 = (
        results.split_by_key(results.read_table(stage1_path, ("model", "seed"), hint=hint), ("model", "seed"))
        if stage1_path.is_file()
        else {}
    )
    logs = results.split_by_key(log, results.KEY_COLUMNS)
    out = {}
    for key, table in results.split_by_key(frontier, results.KEY_COLUMNS).items():
        if key not in logs:
            continue
        entry = {"frontier": table, "log": logs[key]}
        if key[2] == "indirect":
            if key[:2] not in stage1:
                continue
            entry["stage1"] = stage1[key[:2]]
        out[key] = entry
    return out


def _load_records(config: Config, run_dir: Path) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    path = run_dir / results.SIMULATIONS
    table = results.read_table(path, hint="run `hcid simulate` first")
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


def identify_study(
    config: Config,
    run_dir: Path,
    methods: Sequence[str] = METHODS,
    *,
    data: dict[int, dict[str, np.ndarray]] | None = None,
    jobs: int = 2,
    force: bool = False,
    backend: str = "loky",
    scheduler: str | None = None,
    show_progress: bool = True,
) -> IdentifyRun:
    """Identify every model x seed x method of ``config`` from the run's simulations.

    Realizations already in ``frontier.parquet`` (or finished by an
    interrupted run, in ``.parts/``) are not recomputed unless ``force``.
    Writes ``frontier.parquet``, ``stage1.parquet`` and ``identify_log.parquet``;
    the first two are identical whatever ``jobs``, backend or interruptions.

    With ``data`` (measured runs from :func:`hcid.measured.load_data`), those
    runs are identified instead, under model name ``config.data.name`` and
    seed = run number, beside any simulated realizations already in the tables.
    """
    check_run_dir(config, run_dir, "identify", force=force)
    start = time.perf_counter()
    if data is None:
        records = _load_records(config, run_dir)
        keys = [(m.name, s) for m in config.models for s in config.seeds]
    else:
        name = config.data.name
        records = {(name, run): rec for run, rec in data.items()}
        keys = list(records)
    if force:
        results.clear_parts(run_dir)
        redo = {(*k, me) for k in keys for me in methods}
        try:
            done = {k: v for k, v in _existing(run_dir).items() if k not in redo}
        except DataError:
            done = {}  # damaged tables: --force recomputes from the records
    else:
        done = _existing(run_dir)
        done.update(results.read_parts(run_dir))
    _record_config(config, run_dir)
    rate = config.timing.output_rate
    tasks = [
        (config.identify, rate, model, seed, method, records[(model, seed)])
        for model, seed in keys
        for method in methods
        if (model, seed, method) not in done
    ]
    reused = sum(1 for k in keys for me in methods if (*k, me) in done)
    for key, tables in parallel_map(
        _identify_task,
        tasks,
        jobs=jobs,
        label="identify",
        show_progress=show_progress,
        backend=backend,
        scheduler=scheduler,
    ):
        results.write_part(run_dir, *key, tables)
    done.update(results.read_parts(run_dir))

    order = _canonical_order(config, done)
    frontier = results.concat([done[k]["frontier"] for k in order])
    log = results.concat([done[k]["log"] for k in order])
    stage1_parts = [done[k]["stage1"] for k in order if k[2] == "indirect"]
    results.write_table(frontier, run_dir / results.FRONTIER)
    results.write_table(log, run_dir / results.IDENTIFY_LOG)
    if stage1_parts:
        stage1 = results.concat(stage1_parts)
        results.write_table(stage1, run_dir / results.STAGE1)
    else:
        stage1 = pa.table({})
    results.clear_parts(run_dir)
    if tasks:
        results.append_run_log(run_dir, f"identify ({len(tasks)} tasks)", time.perf_counter() - start, jobs)
    return IdentifyRun(
        frontier=frontier, stage1=stage1, log=log, computed=len(tasks), reused=reused, run_dir=run_dir
    )


def _canonical_order(config: Config, done: dict) -> list[tuple[str, int, str]]:
    """Simulated realizations in config order, then measured runs, each by method."""
    simulated = [(m.name, s, me) for m in config.models for s in config.seeds for me in METHODS]
    order = [k for k in simulated if k in done]
    rest = sorted((k for k in done if k not in set(order)), key=lambda k: (k[0], k[1], METHODS.index(k[2])))
    return order + rest


def import_data(config: Config, run_dir: Path, path: Path) -> dict[int, dict[str, np.ndarray]]:
    """Read and check a measured-data file and keep a copy in ``run_dir/measured.parquet``."""
    from hcid import measured

    records = measured.load_data(path, config)
    check_run_dir(config, run_dir, "identify")
    _record_config(config, run_dir)
    results.write_table(measured.records_table(config.data.name, records), run_dir / results.MEASURED)
    return records


# --------------------------------------------------------------------------- W sweep


@dataclass(frozen=True)
class SweepRun:
    """Selections over the W grid, exact breakpoints, and thresholds."""

    selection: pa.Table
    breakpoints: pa.Table
    thresholds: pa.Table
    run_dir: Path


_ORDER_COLUMNS = ("na", "nb_ft", "nb_e", "nk_ft", "nk_e")
_SELECTED_COLUMNS = (*_ORDER_COLUMNS, "d", "v", "vaf_estimation", "vaf_validation")


def sweep_study(config: Config, run_dir: Path) -> SweepRun:
    """Select by ``MSC = log V + W d`` for every realization, method and W of the grid.

    Writes ``selection.parquet`` (one row per model, seed, method and W),
    ``breakpoints.parquet`` (the exact intervals of W over which each
    selection holds) and ``thresholds.parquet`` (W_AIC, W_BIC, W_FP, W_FN per
    method and model, computed from the breakpoints).
    """
    check_run_dir(config, run_dir, "select")
    path = run_dir / results.FRONTIER
    frontier = results.read_table(
        path, (*results.KEY_COLUMNS, *_SELECTED_COLUMNS), hint="run `hcid identify` first"
    )
    w = np.asarray(config.w_grid)
    sel_parts, bp_parts = [], []
    segments: dict[tuple[str, str], list] = {}
    nb_ft: dict[tuple[str, str], list] = {}
    for (model, seed, method), (seg, cols) in _selections(frontier, path).items():
        segments.setdefault((model, method), []).append(seg)
        nb_ft.setdefault((model, method), []).append(cols["nb_ft"])
        chosen = seg.at(w)
        sel_parts.append(_rows_table(model, seed, method, {"w": w}, cols, chosen))
        bp_parts.append(
            _rows_table(model, seed, method, {"w_from": seg.w_from, "w_to": seg.w_to}, cols, seg.index)
        )
    selection_table = results.concat(sel_parts)
    breakpoints_table = results.concat(bp_parts)
    thresholds = _thresholds(config, segments, nb_ft)
    _record_config(config, run_dir)
    results.write_table(selection_table, run_dir / results.SELECTION)
    results.write_table(breakpoints_table, run_dir / results.BREAKPOINTS)
    results.write_table(thresholds, run_dir / results.THRESHOLDS)
    return SweepRun(selection_table, breakpoints_table, thresholds, run_dir)


def _selections(frontier: pa.Table, path: Path) -> dict[tuple[str, int, str], tuple]:
    """Per realization and method: its selection over W and its frontier columns."""
    out = {}
    for (model, seed, method), t in results.split_by_key(frontier, results.KEY_COLUMNS).items():
        cols = {c: t.column(c).to_numpy() for c in _SELECTED_COLUMNS}
        orders = np.column_stack([cols[c] for c in _ORDER_COLUMNS])
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
    data.update({c: pa.array(cols[c][rows]) for c in _SELECTED_COLUMNS})
    return pa.table(data)


def _thresholds(config: Config, segments: dict, nb_ft: dict) -> pa.Table:
    rows = []
    for model in config.models:
        for method in METHODS:
            key = (model.name, method)
            if key not in segments:
                continue
            stage = config.identify.direct if method == "direct" else config.identify.stage2
            nf = stage.estimation.length
            ff = model.has_feedforward
            rows.append(
                {
                    "method": method,
                    "model": model.name,
                    "has_feedforward": ff,
                    "n_realizations": len(segments[key]),
                    "nf": nf,
                    "w_aic": selection.w_aic(nf),
                    "w_bic": selection.w_bic(nf),
                    "w_fp": None if ff else selection.false_positive_threshold(segments[key], nb_ft[key]),
                    "w_fn": selection.false_negative_threshold(segments[key], nb_ft[key]) if ff else None,
                }
            )
    schema = pa.schema(
        [
            ("method", pa.string()),
            ("model", pa.string()),
            ("has_feedforward", pa.bool_()),
            ("n_realizations", pa.int64()),
            ("nf", pa.int64()),
            ("w_aic", pa.float64()),
            ("w_bic", pa.float64()),
            ("w_fp", pa.float64()),
            ("w_fn", pa.float64()),
        ]
    )
    return pa.Table.from_pylist(rows, schema=schema)


# --------------------------------------------------------------------------- W calibration


@dataclass(frozen=True)
class CalibrationRun:
    """Calibration of W per method from the config's FB and FF twins."""

    calibrations: list
    run_dir: Path


def calibrate_study(
    config: Config,
    run_dir: Path,
    *,
    jobs: int = 2,
    backend: str = "loky",
    scheduler: str | None = None,
    show_progress: bool = True,
) -> CalibrationRun:
    """Simulate and identify the config's HC hypothesis (what is not done yet), then
    compute false-positive and false-negative rates over W and the safe interval.

    Writes ``calibration.parquet`` (one row per method and W of the grid, with the
    safe interval and recommended W repeated on every row).
    """
    from hcid.calibration import calibrate

    fb = next((m for m in config.models if not m.has_feedforward), None)
    ff = next((m for m in config.models if m.has_feedforward), None)
    if fb is None or ff is None:
        raise ConfigError(
            "models: calibration needs a feedback-only model (Kpt = 0) and a feedforward "
            f"model (Kpt > 0), got {[m.name for m in config.models]}"
        )
    if not (run_dir / results.SIMULATIONS).is_file():
        simulate_study(config, run_dir, jobs=jobs, show_progress=show_progress)
    identify_study(
        config, run_dir, jobs=jobs, backend=backend, scheduler=scheduler, show_progress=show_progress
    )
    path = run_dir / results.FRONTIER
    chosen = _selections(results.read_table(path), path)
    out = []
    for method in METHODS:
        twins = []
        for model in (fb, ff):
            keys = [(model.name, s, method) for s in config.seeds]
            twins.append(([chosen[k][0] for k in keys], [chosen[k][1]["nb_ft"] for k in keys]))
        out.append(calibrate(method, twins[0], twins[1], np.asarray(config.w_grid), config.target_rate))
    results.write_table(results.concat([c.to_arrow() for c in out]), run_dir / results.CALIBRATION)
    return CalibrationRun(out, run_dir)
