"""Result tables on disk: Parquet in a run directory, written atomically.

Layout of a run directory (default ``runs/<config name>``):

- ``config.yaml``: the resolved config of the run.
- ``simulations.parquet``: one row per model, seed and sample.
- ``simulation_summary.parquet``: one row per model and seed.

Every write goes to a temporary file beside the target and is renamed over it,
so a reader never sees a half-written table and an interrupted write leaves the
previous table intact.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from hcid.errors import DataError
from hcid.simulate import CHANNELS, Realization

__all__ = [
    "SIMULATIONS",
    "SIMULATION_SUMMARY",
    "read_table",
    "realizations_table",
    "records",
    "summary_table",
    "write_table",
    "write_text",
]

SIMULATIONS = "simulations.parquet"
SIMULATION_SUMMARY = "simulation_summary.parquet"

_SIMULATION_SCHEMA = pa.schema(
    [("model", pa.string()), ("seed", pa.int64()), ("k", pa.int64()), ("t", pa.float64())]
    + [(name, pa.float64()) for name in CHANNELS]
)


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _current_umask()


def _atomic(path: Path, write) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise DataError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_table(table: pa.Table, path: str | Path) -> None:
    """Write a Parquet table atomically (temporary file, then rename)."""
    _atomic(Path(path), lambda tmp: pq.write_table(table, tmp))


def write_text(text: str, path: str | Path) -> None:
    """Write a text file atomically."""
    _atomic(Path(path), lambda tmp: Path(tmp).write_text(text))


def read_table(path: str | Path, required: Sequence[str] = (), *, hint: str = "") -> pa.Table:
    """Read a Parquet table, checking that it exists, parses and has the columns.

    Raises
    ------
    DataError
        One line naming the file and what is wrong.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: missing{'; ' + hint if hint else ''}")
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise DataError(f"{path}: not a readable Parquet table ({str(exc).splitlines()[0]})") from exc
    missing = [c for c in required if c not in table.column_names]
    if missing:
        raise DataError(f"{path}: missing columns {missing}")
    return table


def realizations_table(realizations: Sequence[Realization]) -> pa.Table:
    """Stack realizations into the ``simulations.parquet`` table (given order)."""
    columns: dict[str, list] = {name: [] for name in _SIMULATION_SCHEMA.names}
    for r in realizations:
        n = r.t.size
        columns["model"].append(np.full(n, r.model, dtype=object))
        columns["seed"].append(np.full(n, r.seed, dtype=np.int64))
        columns["k"].append(np.arange(n, dtype=np.int64))
        columns["t"].append(r.t)
        for name in CHANNELS:
            columns[name].append(getattr(r, name))
    arrays = [pa.array(np.concatenate(columns[f.name]), type=f.type) for f in _SIMULATION_SCHEMA]
    return pa.Table.from_arrays(arrays, schema=_SIMULATION_SCHEMA)


def summary_table(realizations: Sequence[Realization], disturbance_only: Sequence[Realization]) -> pa.Table:
    """Per model and seed: RMS(e) in deg, var(n)/var(u), the same ratio in the
    disturbance-only task, and Kn."""
    return pa.table(
        {
            "model": pa.array([r.model for r in realizations], pa.string()),
            "seed": pa.array([r.seed for r in realizations], pa.int64()),
            "rms_e_deg": pa.array([r.rms_e_deg for r in realizations], pa.float64()),
            "noise_ratio": pa.array([r.noise_ratio for r in realizations], pa.float64()),
            "noise_ratio_disturbance_only": pa.array([r.noise_ratio for r in disturbance_only], pa.float64()),
            "kn": pa.array([r.kn for r in realizations], pa.float64()),
        }
    )


def records(table: pa.Table, path: str | Path = SIMULATIONS) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """Split a simulations table into one dict of float64 arrays per (model, seed).

    Raises
    ------
    DataError
        If a channel holds NaN or inf, or a record's samples are not 0..N-1.
    """
    missing = [c for c in _SIMULATION_SCHEMA.names if c not in table.column_names]
    if missing:
        raise DataError(f"{path}: missing columns {missing}")
    for field_ in _SIMULATION_SCHEMA:
        found = table.schema.field(field_.name).type
        if found != field_.type:
            raise DataError(f"{path}: column {field_.name!r} is {found}, expected {field_.type}")
    model = table.column("model").to_numpy(zero_copy_only=False).astype(str)
    seed = table.column("seed").to_numpy()
    k = table.column("k").to_numpy()
    data = {name: table.column(name).to_numpy().astype(np.float64) for name in ("t", *CHANNELS)}
    for name, values in data.items():
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            raise DataError(
                f"{path}: column {name!r} holds {values[i]} at model {model[i]}, seed {seed[i]}, k {k[i]}"
            )
    out: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    keys = np.char.add(np.char.add(model, "\0"), seed.astype(str))
    _, first = np.unique(keys, return_index=True)
    for start in np.sort(first):
        m, s = model[start], int(seed[start])
        rows = np.flatnonzero((model == m) & (seed == s))
        if not np.array_equal(k[rows], np.arange(rows.size)):
            raise DataError(f"{path}: samples of model {m}, seed {s} are not k = 0..{rows.size - 1} in order")
        out[(m, s)] = {name: values[rows] for name, values in data.items()}
    return out


# --------------------------------------------------------------------------- identification tables

FRONTIER = "frontier.parquet"
STAGE1 = "stage1.parquet"
IDENTIFY_LOG = "identify_log.parquet"
SELECTION = "selection.parquet"
BREAKPOINTS = "breakpoints.parquet"
THRESHOLDS = "thresholds.parquet"
PARTS = ".parts"
MEASURED = "measured.parquet"
CALIBRATION = "calibration.parquet"

#: Engine column names -> table column names (input 1 is ft, input 2 is e).
FRONTIER_NAMES = {"nb1": "nb_ft", "nb2": "nb_e", "nk1": "nk_ft", "nk2": "nk_e", "b1": "b_ft", "b2": "b_e"}
KEY_COLUMNS = ("model", "seed", "method")


def frontier_part(model: str, seed: int, result) -> dict[str, pa.Table]:
    """Tables of one realization and method: frontier rows, stage-1 row, log row.

    ``result`` is a :class:`hcid.identify.MethodResult`. Wall times go to the log
    only, so the frontier and stage-1 tables are deterministic.
    """
    fit = result.fit.to_arrow().replace_schema_metadata(None)
    fit = fit.rename_columns([FRONTIER_NAMES.get(c, c) for c in fit.column_names])
    n = fit.num_rows
    keys = [
        pa.array([model] * n, pa.string()),
        pa.array([seed] * n, pa.int64()),
        pa.array([result.method] * n, pa.string()),
    ]
    frontier = pa.Table.from_arrays(keys + fit.columns, names=[*KEY_COLUMNS, *fit.column_names])
    log = {
        "model": [model],
        "seed": [seed],
        "method": [result.method],
        "n_candidates": [result.fit.n_candidates],
        "n_unstable": [result.fit.n_unstable_total],
        "stage1_candidates": [0],
        "stage1_unstable": [0],
        "seconds_stage1": [0.0],
        "seconds": [result.seconds],
    }
    tables = {"frontier": frontier}
    s1 = result.stage1
    if s1 is not None:
        tables["stage1"] = pa.table(
            {
                "model": [model],
                "seed": [seed],
                "na": [s1.na],
                "nb_ft": [s1.nb1],
                "nb_fd": [s1.nb2],
                "nk_ft": [s1.nk1],
                "nk_fd": [s1.nk2],
                "v": [s1.v],
                "n_candidates": [s1.n_candidates],
                "n_unstable": [s1.n_unstable],
            }
        )
        log.update(
            stage1_candidates=[s1.n_candidates], stage1_unstable=[s1.n_unstable], seconds_stage1=[s1.seconds]
        )
    tables["log"] = pa.table(log)
    return tables


def write_part(run_dir: Path, model: str, seed: int, method: str, tables: dict[str, pa.Table]) -> None:
    """Store one finished task so an interrupted run can resume from it."""
    folder = Path(run_dir) / PARTS / method
    for kind, table in tables.items():
        write_table(table, folder / f"{model}__{seed}.{kind}.parquet")


def read_parts(run_dir: Path) -> dict[tuple[str, int, str], dict[str, pa.Table]]:
    """Finished tasks of an interrupted run, keyed by (model, seed, method).

    A task counts only when its frontier and log parts are both readable.
    """
    found: dict[tuple[str, int, str], dict[str, pa.Table]] = {}
    root = Path(run_dir) / PARTS
    if not root.is_dir():
        return found
    for path in sorted(root.glob("*/*.frontier.parquet")):
        method = path.parent.name
        stem = path.name[: -len(".frontier.parquet")]
        model, _, seed = stem.rpartition("__")
        tables = {}
        try:
            for kind in ("frontier", "log", "stage1"):
                part = path.with_name(f"{stem}.{kind}.parquet")
                if part.is_file():
                    tables[kind] = pq.read_table(part)
        except (pa.ArrowException, OSError):
            continue  # a part cut off mid-write is simply recomputed
        if "log" in tables and (method == "direct" or "stage1" in tables):
            found[(model, int(seed), method)] = tables
    return found


def clear_parts(run_dir: Path) -> None:
    import shutil

    shutil.rmtree(Path(run_dir) / PARTS, ignore_errors=True)


def split_by_key(table: pa.Table, keys: Sequence[str]) -> dict[tuple, pa.Table]:
    """Rows of ``table`` grouped by the values of ``keys``, in first-seen order."""
    if table.num_rows == 0:
        return {}
    cols = [table.column(k).to_pylist() for k in keys]
    groups: dict[tuple, list[int]] = {}
    for i, key in enumerate(zip(*cols, strict=True)):
        groups.setdefault(key, []).append(i)
    return {key: table.take(pa.array(rows, pa.int64())) for key, rows in groups.items()}


def concat(tables: Sequence[pa.Table]) -> pa.Table:
    """Concatenate tables of one schema into a single-chunk table."""
    return pa.concat_tables(tables).combine_chunks()


RUN_LOG = "run_log.parquet"


def append_run_log(run_dir: Path, stage: str, seconds: float, jobs: int) -> None:
    """Add one line (stage, wall seconds, workers, finish time) to the run's log.

    The log holds wall times only; it is the one table that differs between
    otherwise identical runs.
    """
    import datetime

    path = Path(run_dir) / RUN_LOG
    row = pa.table(
        {
            "stage": [stage],
            "seconds": [float(seconds)],
            "jobs": [int(jobs)],
            "finished": [datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")],
        }
    )
    try:
        previous = pq.read_table(path) if path.is_file() else None
    except (pa.ArrowException, OSError):
        previous = None  # a damaged log is replaced, never a reason to fail a run
    write_table(row if previous is None else pa.concat_tables([previous, row]), path)
