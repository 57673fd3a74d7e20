"""Result tables on disk: Parquet in a run directory, written atomically, read against their schemas.

The schemas and the run directory's layout are in :mod:`hcid.tables`. Every
write goes to a temporary file beside the target and is renamed over it, so a
reader never sees a half-written table and an interrupted write leaves the
previous table intact. Finished identification tasks are kept in
``RUN/.parts/<method>/`` until the tables are assembled, so an interrupted run
resumes where it stopped.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from hcid import tables
from hcid.errors import DataError
from hcid.simulate import Realization
from hcid.tables import CHANNELS, Schema

__all__ = [
    "append_run_log",
    "clear_parts",
    "frontier_part",
    "read",
    "read_optional",
    "read_parts",
    "realizations_table",
    "records",
    "summary_table",
    "write",
    "write_part",
    "write_text",
]

PARTS = ".parts"


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


def write(schema: Schema, table: pa.Table, run_dir: str | Path) -> Path:
    """Check ``table`` against ``schema`` and write it atomically as ``run_dir/schema.file``."""
    problem = schema.problem(table)
    if problem is not None:  # a bug, not a user's mistake: keep the traceback
        raise AssertionError(f"{schema.file}: {problem}")
    path = Path(run_dir) / schema.file
    write_table(table, path)
    return path


def write_text(text: str, path: str | Path) -> None:
    """Write a text file atomically."""
    _atomic(Path(path), lambda tmp: Path(tmp).write_text(text))


def read(
    schema: Schema, run_dir: str | Path, columns: Sequence[str] | None = None, *, hint: str = ""
) -> pa.Table:
    """Read ``run_dir/schema.file``, checking it exists, parses and has the columns with their types.

    ``columns`` limits the check to the columns the caller reads (default: all).

    Raises
    ------
    DataError
        One line naming the file and what is wrong.
    """
    path = Path(run_dir) / schema.file
    if not path.is_file():
        raise DataError(f"{path}: missing{'; ' + hint if hint else ''}")
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise DataError(f"{path}: not a readable Parquet table ({str(exc).splitlines()[0]})") from exc
    problem = schema.problem(table, columns)
    if problem is not None:
        raise DataError(f"{path}: {problem}{'; ' + hint if hint else ''}")
    return table


def read_optional(
    schema: Schema, run_dir: str | Path, columns: Sequence[str] | None = None
) -> pa.Table | None:
    """:func:`read`, or None when the table has not been written."""
    return read(schema, run_dir, columns) if (Path(run_dir) / schema.file).is_file() else None


# --------------------------------------------------------------------------- simulation tables


def realizations_table(realizations: Sequence[Realization]) -> pa.Table:
    """Stack realizations into the ``simulations.parquet`` table (given order)."""
    schema = tables.SIMULATIONS.arrow
    columns: dict[str, list] = {name: [] for name in schema.names}
    for r in realizations:
        n = r.t.size
        columns["model"].append(np.full(n, r.model, dtype=object))
        columns["seed"].append(np.full(n, r.seed, dtype=np.int64))
        columns["k"].append(np.arange(n, dtype=np.int64))
        columns["t"].append(r.t)
        for name in CHANNELS:
            columns[name].append(getattr(r, name))
    arrays = [pa.array(np.concatenate(columns[f.name]), type=f.type) for f in schema]
    return pa.Table.from_arrays(arrays, schema=schema)


def summary_table(realizations: Sequence[Realization], disturbance_only: Sequence[Realization]) -> pa.Table:
    """Per model and seed: RMS(e) in deg, var(n)/var(u), the same ratio in the
    disturbance-only task, and Kn."""
    return pa.Table.from_pydict(
        {
            "model": [r.model for r in realizations],
            "seed": [r.seed for r in realizations],
            "rms_e_deg": [r.rms_e_deg for r in realizations],
            "noise_ratio": [r.noise_ratio for r in realizations],
            "noise_ratio_disturbance_only": [r.noise_ratio for r in disturbance_only],
            "kn": [r.kn for r in realizations],
        },
        schema=tables.SIMULATION_SUMMARY.arrow,
    )


def records(table: pa.Table, path: str | Path) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """Split a simulations table into one dict of float64 arrays per (model, seed).

    Raises
    ------
    DataError
        If a column is missing or mistyped, a channel holds NaN or inf, or a
        record's samples are not 0..N-1.
    """
    problem = tables.SIMULATIONS.problem(table)
    if problem is not None:
        raise DataError(f"{path}: {problem}")
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


def frontier_part(model: str, seed: int, result, stages) -> dict[str, pa.Table]:
    """Tables of one realization and method: its frontier rows, a row per choosing stage, a log row.

    ``result`` is a :class:`hcid.methods.MethodResult`, ``stages`` the method's
    choosing stages (:attr:`hcid.methods.Method.choice_stages`). Wall times go to
    the log only, so the frontier and stage tables are deterministic.
    """
    fit = result.fit.to_arrow().replace_schema_metadata(None)
    fit = fit.rename_columns([tables.FRONTIER_NAMES.get(c, c) for c in fit.column_names])
    n = fit.num_rows
    keys = [
        pa.array([model] * n, pa.string()),
        pa.array([seed] * n, pa.int64()),
        pa.array([result.method] * n, pa.string()),
    ]
    frontier = pa.Table.from_arrays(keys + fit.columns, names=[*tables.FRONTIER.key, *fit.column_names])
    out = {"frontier": frontier}
    for spec, c in zip(stages, result.choices, strict=True):
        schema = tables.stage_choice(spec.name, spec.inputs)
        values = [model, seed, c.na, c.nb1, c.nb2, c.nk1, c.nk2, c.v, c.n_candidates, c.n_unstable]
        out[spec.name] = pa.Table.from_pydict(
            {name: [v] for name, v in zip(schema.names, values, strict=True)}, schema=schema.arrow
        )
    out["log"] = pa.Table.from_pydict(
        {
            "model": [model],
            "seed": [seed],
            "method": [result.method],
            "n_candidates": [result.fit.n_candidates],
            "n_unstable": [result.fit.n_unstable_total],
            "stage1_candidates": [sum(c.n_candidates for c in result.choices)],
            "stage1_unstable": [sum(c.n_unstable for c in result.choices)],
            "seconds_stage1": [sum(c.seconds for c in result.choices)],
            "seconds": [result.seconds],
        },
        schema=tables.IDENTIFY_LOG.arrow,
    )
    return out


def write_part(run_dir: Path, model: str, seed: int, method: str, parts: dict[str, pa.Table]) -> None:
    """Store one finished task so an interrupted run can resume from it."""
    folder = Path(run_dir) / PARTS / method
    for kind, table in parts.items():
        write_table(table, folder / f"{model}__{seed}.{kind}.parquet")


def read_parts(run_dir: Path, kinds: dict[str, tuple[str, ...]]) -> dict[tuple[str, int, str], dict]:
    """Finished tasks of an interrupted run, keyed by (model, seed, method).

    ``kinds`` names, per method, the parts a finished task has besides its
    frontier (its log and its choosing stages); a task with any of them missing
    or unreadable is left out, to be recomputed.
    """
    found: dict[tuple[str, int, str], dict[str, pa.Table]] = {}
    root = Path(run_dir) / PARTS
    if not root.is_dir():
        return found
    for path in sorted(root.glob("*/*.frontier.parquet")):
        method = path.parent.name
        if method not in kinds:
            continue
        stem = path.name[: -len(".frontier.parquet")]
        model, _, seed = stem.rpartition("__")
        parts = {}
        try:
            for kind in ("frontier", *kinds[method]):
                part = path.with_name(f"{stem}.{kind}.parquet")
                if part.is_file():
                    parts[kind] = pq.read_table(part)
        except (pa.ArrowException, OSError):
            continue  # a part cut off mid-write is simply recomputed
        if all(kind in parts for kind in kinds[method]):
            found[(model, int(seed), method)] = parts
    return found


def clear_parts(run_dir: Path) -> None:
    shutil.rmtree(Path(run_dir) / PARTS, ignore_errors=True)


def append_run_log(run_dir: Path, stage: str, seconds: float, jobs: int) -> None:
    """Add one line (stage, wall seconds, workers, finish time) to the run's log.

    The log holds wall times only; it is the one table that differs between
    otherwise identical runs.
    """
    import datetime

    path = Path(run_dir) / tables.RUN_LOG.file
    row = pa.Table.from_pydict(
        {
            "stage": [stage],
            "seconds": [float(seconds)],
            "jobs": [int(jobs)],
            "finished": [datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")],
        },
        schema=tables.RUN_LOG.arrow,
    )
    try:
        previous = pq.read_table(path) if path.is_file() else None
    except (pa.ArrowException, OSError):
        previous = None  # a damaged log is replaced, never a reason to fail a run
    write_table(row if previous is None else pa.concat_tables([previous, row]), path)
