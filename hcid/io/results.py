"""Result tables on disk: Parquet in a run directory, written atomically, read against their schemas.

The schemas and the run directory's layout are in :mod:`hcid.tables`. Every
write goes to a temporary file beside the target and is renamed over it, so a
reader never sees a half-written table and an interrupted write leaves the
previous table intact. Finished tasks are kept in ``RUN/.parts/`` until the
tables are assembled, so an interrupted run resumes where it stopped. Parts
are hcid's own scratch, so they are Arrow IPC files, several times faster to
write and read than Parquet (hundreds a run); a part hcid cannot read or
that is off its schema (one left by an older hcid, say) is recomputed.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from hcid import tables
from hcid.errors import DataError
from hcid.io.folders import atomic_write
from hcid.loop.simulate import Realization
from hcid.methods import METHODS, StageChoice
from hcid.selection.frontier import Frontier
from hcid.tables import CHANNELS, Schema

__all__ = [
    "append_run_log",
    "clear_parts",
    "frontier_part",
    "frontiers",
    "read",
    "read_optional",
    "read_part_table",
    "read_parts",
    "realizations_table",
    "records",
    "records_of",
    "check_records",
    "stage_choices_of",
    "summary_table",
    "write",
    "write_part",
    "write_part_table",
    "write_text",
]

PARTS = ".parts"
#: Suffix of a part file (:func:`write_part_table`).
PART_SUFFIX = ".arrow"


def write_table(table: pa.Table, path: str | Path, plain: Sequence[str] = ()) -> None:
    """Write a Parquet table atomically (temporary file, then rename); ``plain`` columns without
    dictionary encoding (:attr:`hcid.tables.Schema.plain`)."""
    path = Path(path)
    atomic_write(path, lambda tmp: _write_parquet(table, tmp, plain))


def _write_parquet(table: pa.Table, where, plain: Sequence[str] = ()) -> None:
    """``pq.write_table`` without dictionary-encoding list columns and ``plain`` ones, whose
    values are each their own (ARX coefficients, a record's noisy signals): the paper study's
    frontier is written in 50 instead of 187 ms and its simulations in 19 instead of 69 ms,
    each file smaller; the values read back are the same."""
    pq.write_table(table, where, use_dictionary=_dictionary_columns(table, plain))


def _dictionary_columns(table: pa.Table, plain: Sequence[str]) -> list[str] | bool:
    """The columns :func:`_write_parquet` dictionary-encodes; True where that is every one
    (pyarrow's default, the same bytes)."""
    skip = set(plain) | {f.name for f in table.schema if pa.types.is_list(f.type)}
    names = table.column_names
    return True if skip.isdisjoint(names) else [n for n in names if n not in skip]


def write(schema: Schema, table: pa.Table, run_dir: str | Path) -> Path:
    """Check ``table`` against ``schema`` and write it atomically as ``run_dir/schema.file``."""
    problem = schema.problem(table)
    if problem is not None:  # a bug, not a user's mistake: keep the traceback
        raise AssertionError(f"{schema.file}: {problem}")
    table = schema.conform(table)
    path = Path(run_dir) / schema.file
    if _same_table(path, table, schema.plain):
        return path  # nothing changed: a complete run needs no write (and may be read-only)
    write_table(table, path, schema.plain)
    return path


def _same_table(path: Path, table: pa.Table, plain: Sequence[str] = ()) -> bool:
    """Whether ``path`` holds exactly the bytes ``table`` would be written as (NaN-safe)."""
    if not path.is_file():
        return False
    try:
        held = path.read_bytes()
    except OSError:
        return False
    # This hcid's encoding, then pyarrow's default where it differs (an earlier hcid's: a
    # complete run directory it wrote, perhaps read-only, needs no write either).
    ours = _dictionary_columns(table, plain)
    for dictionary in (ours,) if ours is True else (ours, True):
        sink = pa.BufferOutputStream()
        pq.write_table(table, sink, use_dictionary=dictionary)
        if held == sink.getvalue().to_pybytes():
            return True
    return False


def write_text(text: str, path: str | Path) -> None:
    """Write a text file atomically (nothing is written when the file already holds ``text``)."""
    path = Path(path)
    try:
        if path.is_file() and path.read_text() == text:
            return
    except (OSError, UnicodeDecodeError):
        pass
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))


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
        if not hint and problem.startswith("missing columns"):  # most likely an older hcid's table
            who = f"`{schema.command} ...`" if schema.command else "the command that wrote it"
            hint = f"written by an older hcid? run {who} again on this run directory (it reuses what it can)"
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
    encoded = pc.dictionary_encode(table.column("model")).combine_chunks()  # no string sort
    names, model_code = encoded.dictionary.to_pylist(), encoded.indices.to_numpy(zero_copy_only=False)
    seed = table.column("seed").to_numpy()
    k = table.column("k").to_numpy()
    data = {name: table.column(name).to_numpy().astype(np.float64) for name in ("t", *CHANNELS)}
    for name, values in data.items():
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            raise _not_finite(path, name, values[i], names[model_code[i]], seed[i], k[i])
    out: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    _, seed_code = np.unique(seed, return_inverse=True)
    key = model_code.astype(np.int64) * (int(seed_code.max(initial=0)) + 1) + seed_code
    _, first, group, counts = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    grouped = np.argsort(group, kind="stable")  # rows by record, each record's in row order
    rows_of = np.split(grouped, np.cumsum(counts)[:-1])
    for g in np.argsort(first):  # records in order of first appearance
        start = first[g]
        m, s = names[model_code[start]], int(seed[start])
        rows = rows_of[g]
        if not np.array_equal(k[rows], np.arange(rows.size)):
            raise DataError(f"{path}: samples of model {m}, seed {s} are not k = 0..{rows.size - 1} in order")
        out[(m, s)] = {name: values[rows] for name, values in data.items()}
    return out


def records_of(realizations: Sequence[Realization]) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """The arrays :func:`records` gives of the table :func:`realizations_table` stacks, from the
    realizations themselves (without the table; :func:`check_records` refuses what it refuses)."""
    return {
        (r.model, int(r.seed)): {
            name: np.ascontiguousarray(getattr(r, name), dtype=np.float64) for name in ("t", *CHANNELS)
        }
        for r in realizations
    }


def check_records(records: dict[tuple[str, int], dict[str, np.ndarray]], path: str | Path) -> None:
    """Refuse records (:func:`records_of`) with a sample that is not finite, as :func:`records`
    refuses their table (there: the first in the table's column order; here: in each record's)."""
    for (model, seed), record in records.items():
        for name in ("t", *CHANNELS):
            bad = ~np.isfinite(record[name])
            if bad.any():
                i = int(np.argmax(bad))
                raise _not_finite(path, name, record[name][i], model, seed, i)


def _not_finite(path, name: str, value, model: str, seed, k) -> DataError:
    return DataError(f"{path}: column {name!r} holds {value} at model {model}, seed {seed}, k {k}")


# --------------------------------------------------------------------------- grouping and joining tables


def split_by_key(table: pa.Table, keys: Sequence[str]) -> dict[tuple, pa.Table]:
    """Rows of ``table`` grouped by the values of ``keys``, groups in first-seen order and rows
    in table order: one ``take`` of the whole table, then a slice per group (the paper study's
    frontier of 89,600 rows in 200 groups: 10 times faster than a take per group). Key values
    group as a dict's keys do (-0.0 with 0.0), but NaN keys form one group."""
    if table.num_rows == 0 or not keys:
        return {}
    codes, values = [], []
    group = np.zeros(table.num_rows, dtype=np.int64)
    for k in keys:
        column = table.column(k)
        if pa.types.is_dictionary(column.type):  # its dictionary may repeat a value
            column = column.cast(column.type.value_type)
        if pa.types.is_floating(column.type):  # -0.0 + 0.0 is 0.0: one key, as in a dict
            column = pc.add(column, 0.0)
        encoded = pc.dictionary_encode(column, null_encoding="encode").combine_chunks()
        codes.append(encoded.indices.to_numpy(zero_copy_only=False).astype(np.int64))
        values.append(encoded.dictionary.to_pylist())
        # the groups so far numbered 0.. again (no overflow however many keys)
        group = np.unique(group * len(values[-1]) + codes[-1], return_inverse=True)[1].ravel()
    _, first, inverse = np.unique(group, return_index=True, return_inverse=True)
    order = np.argsort(first)  # the groups in first-seen order
    rank = np.empty(order.size, dtype=np.int64)
    rank[order] = np.arange(order.size)
    row_rank = rank[inverse.ravel()]
    rows = np.argsort(row_rank, kind="stable")
    taken = table.take(pa.array(rows, pa.int64()))
    ends = np.cumsum(np.bincount(row_rank, minlength=order.size))
    out = {}
    for g, start in enumerate(np.concatenate([[0], ends[:-1]])):
        key = tuple(v[c[first[order[g]]]] for v, c in zip(values, codes, strict=True))
        out[key] = taken.slice(start, ends[g] - start)
    assert len(out) == order.size, "split_by_key: two groups with equal keys"
    return out


def frontiers(table: pa.Table) -> dict[tuple[str, int, str], Frontier]:
    """A frontier table's (``frontier.parquet``'s columns) frontiers by (model, seed, method)."""
    return {k: Frontier.from_table(t) for k, t in split_by_key(table, tables.FRONTIER.key).items()}


def concat(parts: Sequence[pa.Table]) -> pa.Table:
    """Concatenate tables of one schema into a single-chunk table."""
    return pa.concat_tables(parts).combine_chunks()


# --------------------------------------------------------------------------- consistency with the config


def check_against_config(table: pa.Table, config, path: str | Path) -> None:
    """Refuse a table whose keys or values contradict the run's config (a tampered run directory).

    Every model must be one of the config's (or its data name), the seeds of a
    simulated model the config's seeds, the methods registered ones; a ``v``
    column must hold positive numbers or inf (unstable), never NaN.

    Raises
    ------
    DataError
        One line naming the file and the first contradiction.
    """
    names = table.column_names
    simulated = {m.name for m in config.models}
    allowed = simulated | ({config.data.name} if config.data is not None else set())
    if "model" in names:
        models = set(pc.unique(table.column("model")).to_pylist())
        if not models <= allowed:
            bad = sorted(models - allowed, key=str)[0]
            raise DataError(
                f"{path}: holds model {str(bad)[:40]!r}, which the run's config.yaml does not name "
                f"({', '.join(sorted(allowed))}); the tables and config.yaml disagree"
            )
        if "seed" in names:
            seeds = set(config.seeds)
            distinct = table.select(["model", "seed"]).group_by(["model", "seed"]).aggregate([])
            pairs = set(
                zip(distinct.column("model").to_pylist(), distinct.column("seed").to_pylist(), strict=True)
            )
            wrong = sorted(p for p in pairs if p[0] in simulated and p[1] not in seeds)
            if wrong:
                raise DataError(
                    f"{path}: holds model {wrong[0][0]}, seed {wrong[0][1]}, not among the run's seeds; "
                    "the tables and config.yaml disagree"
                )
    if "method" in names:
        unknown = set(pc.unique(table.column("method")).to_pylist()) - set(METHODS)
        if unknown:
            raise DataError(
                f"{path}: holds method {str(sorted(unknown, key=str)[0])[:40]!r}, not a registered one"
            )
    if "v" in names:
        v = table.column("v").to_numpy(zero_copy_only=False).astype(np.float64)
        bad = np.isnan(v) | (v <= 0)
        if bad.any():
            raise DataError(
                f"{path}: column 'v' holds {v[np.argmax(bad)]} (row {int(np.argmax(bad))}); V must be > 0"
            )


# --------------------------------------------------------------------------- identification tables


def frontier_part(model: str, seed: int, result, stages, worker: str = "") -> dict[str, pa.Table]:
    """Tables of one realization and method: its frontier rows, a row per choosing stage, a log row.

    ``result`` is a :class:`hcid.methods.MethodResult`, ``stages`` the method's
    choosing stages (:attr:`hcid.methods.Method.choice_stages`). Wall times go to
    the log only, so the frontier and stage tables are deterministic; so does
    ``worker`` (``host:pid`` of the process that ran the task).
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
            "worker": [worker],
        },
        schema=tables.IDENTIFY_LOG.arrow,
    )
    return out


def stage_choices_of(table: pa.Table, stage) -> dict[tuple[str, int], StageChoice]:
    """A choosing stage's table (``stage1.parquet``'s columns) as its choice per (model, seed);
    ``stage`` the method's :class:`hcid.methods.StageSpec` (its name and inputs)."""
    i1, i2 = stage.inputs[0], stage.inputs[1]
    return {
        (row["model"], row["seed"]): StageChoice(
            stage=stage.name,
            na=row["na"],
            nb1=row[f"nb_{i1}"],
            nb2=row[f"nb_{i2}"],
            nk1=row[f"nk_{i1}"],
            nk2=row[f"nk_{i2}"],
            v=row["v"],
            n_candidates=row["n_candidates"],
            n_unstable=row["n_unstable"],
            seconds=0.0,
        )
        for row in table.to_pylist()
    }


def write_part(run_dir: Path, model: str, seed: int, method: str, parts: dict[str, pa.Table]) -> None:
    """Store one finished task so an interrupted run can resume from it."""
    if (Path(run_dir) / PARTS).is_symlink():
        clear_parts(run_dir)  # parts go into hcid's own folder, never through a link
    folder = Path(run_dir) / PARTS / method
    for kind, table in parts.items():
        write_part_table(table, folder / f"{model}__{seed}.{kind}{PART_SUFFIX}")


def write_part_table(table: pa.Table, path: Path) -> None:
    """Write one part file (Arrow IPC) atomically."""

    def write(tmp: str) -> None:
        with pa.OSFile(tmp, "wb") as sink, pa.ipc.new_file(sink, table.schema) as writer:
            writer.write_table(table)

    atomic_write(path, write)


def read_part_table(path: Path) -> pa.Table:
    """Read one part file (raises ``pa.ArrowException`` or ``OSError`` if damaged or missing)."""
    with pa.OSFile(str(path)) as source:
        return pa.ipc.open_file(source).read_all()


def read_parts(run_dir: Path, kinds: dict[str, dict[str, Schema]]) -> dict[tuple[str, int, str], dict]:
    """Finished tasks of an interrupted run, keyed by (model, seed, method).

    ``kinds`` gives, per method, the schema of each part a finished task has
    (frontier, log, its choosing stages). A task with a part missing, unreadable,
    off its schema or naming another realization than its file is left out, to
    be recomputed.
    """
    found: dict[tuple[str, int, str], dict[str, pa.Table]] = {}
    root = Path(run_dir) / PARTS
    if not root.is_dir() or root.is_symlink():
        return found
    for path in sorted(root.glob(f"*/*.frontier{PART_SUFFIX}")):
        method = path.parent.name
        if method not in kinds:
            continue
        stem = path.name[: -len(f".frontier{PART_SUFFIX}")]
        model, _, seed_text = stem.rpartition("__")
        if not seed_text.isdigit():
            continue
        seed = int(seed_text)
        parts = {}
        try:
            for kind, schema in kinds[method].items():
                table = read_part_table(path.with_name(f"{stem}.{kind}{PART_SUFFIX}"))
                if schema.problem(table) is not None or table.num_rows == 0:
                    break
                if set(
                    zip(table.column("model").to_pylist(), table.column("seed").to_pylist(), strict=True)
                ) != {(model, seed)}:
                    break
                parts[kind] = table
        except (pa.ArrowException, OSError, ValueError):
            continue  # a part cut off mid-write is simply recomputed
        if len(parts) == len(kinds[method]):
            found[(model, seed, method)] = parts
    return found


def clear_parts(run_dir: Path) -> None:
    """Remove the finished-task parts (a link in place of the folder is removed, not followed)."""
    parts = Path(run_dir) / PARTS
    if parts.is_symlink() or parts.is_file():
        parts.unlink()
    else:
        shutil.rmtree(parts, ignore_errors=True)


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
