"""A measured study's data set: many files, their factors, one record per run (results layer).

``--data`` names files, globs, folders or manifests (:func:`data_files`):

- a data file (CSV, Parquet, MATLAB) is itself;
- a glob (``trials/*.csv``) is every file it matches, sorted by path;
- a folder is every data file directly in it, sorted by name;
- a manifest is a CSV with a ``file`` column (paths relative to the manifest's
  folder) and one column per factor (subject, condition, trial, ...).

Factors come from the manifest and from the config's ``data.pattern``, matched
against each file's name (``{subject}_{condition}_{trial}.csv``). Every file of a
set must give the same factors, have the same columns (CSV headers, Parquet
schemas) and be sampled at the same rate. The runs of a one-file set keep the
file's run ids; the runs of several files are numbered 1, 2, ... in file order,
and ``runs.parquet`` (:func:`runs_table`) keeps each run's file, the file's own
run id and its factors, for every table to be joined with.
"""

from __future__ import annotations

import csv
import fnmatch
import glob
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid.config import DataConfig
from hcid.config.parse import RESERVED_FACTORS, check_pattern
from hcid.errors import ConfigError, DataError
from hcid.io.formats import READERS, csv_layout
from hcid.io.measured import FileAtRate, at_rate, read_file, records_of
from hcid.tables import RUNS

__all__ = [
    "DataFile",
    "DataSet",
    "FoundFiles",
    "data_files",
    "find_files",
    "read_files",
    "read_set",
    "runs_table",
    "set_at",
    "skipped_by_reason",
]

_GLOB = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class DataFile:
    """One file of a data set and its factors (name, value), in the set's factor order."""

    path: Path
    factors: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class DataSet:
    """The runs of a data set at the analysis rate.

    ``records`` by run id (``t``, ``ft``, ``fd``, ``e``, ``u``); ``runs`` one row per
    run: ``file``, ``file_run`` and the factors (:data:`hcid.tables.RUNS`).
    """

    records: dict[int, dict[str, np.ndarray]]
    runs: list[dict[str, object]]
    factors: tuple[str, ...]
    rate: float
    #: Files left out (``read_set(skip=True)``): (path, the one-line reason).
    set_aside: tuple[tuple[str, str], ...] = ()
    #: Files a folder or glob found that are not runs (:func:`find_files`): (path, reason).
    skipped: tuple[tuple[str, str], ...] = ()


def _pattern_regex(pattern: str, lazy: bool = True) -> re.Pattern:
    """The pattern's regex: each factor one or more characters other than ``/``, matched lazily
    or greedily (a name both match alike is read in one way only)."""
    out, pos = [], 0
    for m in re.finditer(r"\{([^{}]*)\}", pattern):
        out.append(re.escape(pattern[pos : m.start()]))
        out.append(f"(?P<{m.group(1)}>[^/]+{'?' if lazy else ''})")
        pos = m.end()
    out.append(re.escape(pattern[pos:]))
    return re.compile("".join(out))


def _tail(path: Path, pattern: str) -> str:
    """The part of ``path`` a pattern or glob with ``/`` is matched against: the file's name and as
    many of its folders as the pattern names (the folders as named, a link not followed); the
    whole absolute path for a glob that starts with ``/``."""
    absolute = Path(os.path.abspath(path))
    if pattern.startswith("/"):
        return absolute.as_posix()
    return "/".join(absolute.parts[-(pattern.count("/") + 1) :])


def _is_manifest(path: Path) -> bool:
    if path.suffix.lower() != ".csv":
        return False
    names, header_row, _ = csv_layout(path)
    return header_row and "file" in names


def _manifest(path: Path) -> list[DataFile]:
    """The files a manifest names, with its factor columns."""
    with open(path, newline="", encoding="utf-8-sig") as f:
        rows = [r for r in csv.reader(line for line in f if not line.lstrip().startswith("#")) if any(r)]
    header = [h.strip() for h in rows[0]]
    factors = [h for h in header if h != "file"]
    for name in factors:
        if not name.isidentifier() or name in RESERVED_FACTORS:
            raise DataError(
                f"{path}: factor column {name!r} must be an identifier other than "
                f"{', '.join(RESERVED_FACTORS)}"
            )
    if len(set(header)) != len(header):
        raise DataError(f"{path}: a column appears twice in its header")
    if len(rows) < 2:
        raise DataError(f"{path}: names no file (an empty manifest)")
    out = []
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise DataError(f"{path}: row {number} has {len(row)} fields, its header {len(header)}")
        values = dict(zip(header, (v.strip() for v in row), strict=True))
        for name in factors:
            if not values[name]:
                raise DataError(f"{path}: row {number}: factor {name!r} is empty")
        if not values["file"]:
            raise DataError(f"{path}: row {number}: no file")
        named = path.parent / values["file"]
        if not named.is_file():
            raise DataError(f"{path}: row {number}: {values['file']}: no such file")
        out.append(DataFile(named, tuple((n, values[n]) for n in factors)))
    return out


def _not_data(found: list[Path], skipped: list[tuple[str, str]]) -> list[Path]:
    """The data files of what a folder or glob found; the others listed in ``skipped``."""
    for p in found:
        if p.suffix.lower() not in READERS:
            skipped.append(
                (str(p), f"not a data file ({p.suffix or 'no suffix'}; read: {', '.join(READERS)})")
            )
    return [p for p in found if p.suffix.lower() in READERS]


def _expand(source: str | Path | DataFile, skipped: list[tuple[str, str]]) -> list[DataFile]:
    if isinstance(source, DataFile):  # already expanded (e.g. by set_aside), its factors kept
        return [source]
    text = str(source)
    path = Path(text)
    if _GLOB.search(text) and not path.exists():
        found = _not_data(
            sorted(Path(m) for m in glob.glob(text, recursive=True) if Path(m).is_file()), skipped
        )
        if not found:
            raise DataError(f"{text}: matches no data file ({', '.join(READERS)})")
        return [DataFile(p) for p in found]
    if path.is_dir():
        found = _not_data(sorted(p for p in path.iterdir() if p.is_file()), skipped)
        found = [p for p in found if not _is_manifest(p)]
        if not found:
            raise DataError(f"{path}: holds no data file ({', '.join(READERS)})")
        return [DataFile(p) for p in found]
    if not path.exists():
        raise DataError(f"{path}: no such file or folder")
    if not path.is_file():  # read before anything is written: a pipe would block, a device never end
        raise DataError(f"{path}: not a regular file (a pipe, socket or device); give a data file")
    if _is_manifest(path):
        return _manifest(path)
    return [DataFile(path)]


@dataclass(frozen=True)
class FoundFiles:
    """What ``--data`` names: the data set's files with their factors, in order, and the files a
    folder or glob found that are not runs, each with the one-line reason it was left out."""

    files: list[DataFile]
    skipped: tuple[tuple[str, str], ...] = ()


def _excluded(files: list[DataFile], exclude: Sequence[str], skipped: list) -> list[DataFile]:
    kept = []
    for f in files:
        glob_ = next((g for g in exclude if fnmatch.fnmatchcase(_tail(f.path, g), g)), None)
        if glob_ is None:
            kept.append(f)
        else:
            skipped.append((str(f.path), f"left out by data.exclude {glob_!r}"))
    return kept


def _copies(files: list[DataFile], skipped: list) -> list[DataFile]:
    """One file of each recording: where a folder holds a name in several formats (a logger's
    ``.csv`` beside its ``.npz``), the set's most common format is kept and the others skipped."""
    count: dict[str, int] = {}
    for f in files:
        count[f.path.suffix.lower()] = count.get(f.path.suffix.lower(), 0) + 1
    rank = {suffix: (-n, list(READERS).index(suffix)) for suffix, n in count.items()}
    by_stem: dict[tuple[Path, str], list[DataFile]] = {}
    for f in files:
        by_stem.setdefault((f.path.resolve().parent, f.path.stem), []).append(f)
    copies = set()
    for same in by_stem.values():
        if len(same) > 1:
            kept = min(same, key=lambda f: rank[f.path.suffix.lower()])
            for f in same:
                if f is not kept:
                    copies.add(f.path)
                    skipped.append((str(f.path), f"a copy in another format of {kept.path.name}"))
    return [f for f in files if f.path not in copies]


def skipped_by_reason(skipped: Sequence[tuple[str, str]]) -> dict[str, list[str]]:
    """The files :func:`find_files` skipped, grouped by their reason without its detail (``not a
    data file``, ``left out by data.exclude '<glob>'``, ``a copy in another format``), in order.

    >>> skipped_by_reason([("a.ini", "not a data file (.ini; read: .csv)"),
    ...                    ("b.npz", "a copy in another format of b.csv")])
    {'not a data file': ['a.ini'], 'a copy in another format': ['b.npz']}
    """
    out: dict[str, list[str]] = {}
    for path, why in skipped:
        out.setdefault(why.split(" (")[0].split(" of ")[0], []).append(path)
    return out


def data_files(sources: Sequence[str | Path], pattern: str | None = None) -> list[DataFile]:
    """The files of a data set with their factors, in order (:func:`find_files` without
    exclusions; the files it skips are left out)."""
    return find_files(sources, pattern).files


def find_files(
    sources: Sequence[str | Path], pattern: str | None = None, exclude: Sequence[str] = ()
) -> FoundFiles:
    """The files of a data set with their factors, in order, and those left out.

    A folder or glob may find files that are not runs; each is left out and listed with its
    reason (:attr:`FoundFiles.skipped`): a file that is not of a data format (a stray
    ``desktop.ini``), one an ``exclude`` glob matches (a logger's reset segments), or a copy of a
    recording in another format beside it (the set's most common format kept). ``pattern`` gives
    each kept file's factors from its name, and, where it holds ``/``, from the folders the file
    sits in (``{subject}/{trial}.csv``).

    Raises
    ------
    DataError
        One line: a source that is missing or matches nothing, a file named twice, a
        file whose name does not match ``pattern``, a factor given twice with two
        values, or files that do not all give the same factors.
    """
    if isinstance(sources, str | Path):
        sources = [sources]
    if not sources:
        raise DataError("data (--data): no data given")
    skipped: list[tuple[str, str]] = []
    files = [f for source in sources for f in _expand(source, skipped)]
    seen: dict[Path, Path] = {}
    for f in files:
        key = f.path.resolve()
        if key in seen:
            raise DataError(f"{f.path}: named twice in the data set")
        seen[key] = f.path
    files = _copies(_excluded(files, exclude, skipped), skipped)
    if not files:
        raise DataError(
            f"data (--data): every file it names is left out ({len(skipped)}: e.g. {skipped[0][0]}: "
            f"{skipped[0][1]})"
        )
    if pattern is not None:
        try:
            check_pattern(pattern, "data.pattern")
        except ConfigError as exc:
            raise DataError(str(exc)) from None
        regex, greedy = _pattern_regex(pattern), _pattern_regex(pattern, lazy=False)
        named = []
        for f in files:
            name = _tail(f.path, pattern)
            m = regex.fullmatch(name)
            if m is None:
                where = "its name" if "/" not in pattern else f"{name!r}"
                raise DataError(
                    f"{f.path}: {where} does not match data.pattern {pattern!r} (files that are not "
                    "runs: data.exclude)"
                )
            if greedy.fullmatch(name).groupdict() != m.groupdict():
                raise DataError(
                    f"{f.path}: its name matches data.pattern {pattern!r} in more than one way (e.g. "
                    f"{m.groupdict()} or {greedy.fullmatch(name).groupdict()}); make the pattern's "
                    "separators occur in no factor value, or leave files that are not runs out "
                    "(data.exclude)"
                )
            given = dict(f.factors)
            for name, value in m.groupdict().items():
                if name in given and given[name] != value:
                    raise DataError(
                        f"{f.path}: factor {name!r} is {given[name]!r} in the manifest and {value!r} "
                        "in its name"
                    )
                given[name] = value
            named.append(DataFile(f.path, tuple(given.items())))
        files = named
    names = [tuple(n for n, _ in f.factors) for f in files]
    for f, n in zip(files, names, strict=True):
        if set(n) != set(names[0]):
            missing = sorted(set(names[0]) ^ set(n))
            raise DataError(f"{f.path}: factors {n} differ from the set's {names[0]} (missing {missing})")
    return FoundFiles(files, tuple(skipped))


def _columns(path: Path) -> tuple[str, ...] | None:
    """The file's column names, to compare across a set (None for a MATLAB file)."""
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return tuple(csv_layout(path)[0]) or None
    if suffix in (".parquet", ".pq"):
        import pyarrow.parquet as pq

        try:
            return tuple(pq.read_schema(path).names)
        except (pa.ArrowException, OSError) as exc:
            raise DataError(f"{path}: cannot read ({str(exc).splitlines()[0][:160]})") from exc
    return None


def read_files(
    files: Sequence[DataFile],
    data: DataConfig,
    rate: float | Callable[[float], float] | None = None,
    skip: bool = False,
) -> tuple[list[tuple[DataFile, FileAtRate, tuple[str, ...] | None]], list[tuple[str, str]]]:
    """Every file of a set read once (:func:`hcid.io.measured.read_file`) and taken at once to
    the analysis ``rate`` (:func:`hcid.io.measured.at_rate`; None: the first run's own; a
    function: of the first run's own rate), so that only one file is held at its own rate:
    ``([(file, its runs at the rate, its columns)], set aside)``. With ``skip``, a file that
    cannot be read or resampled is set aside with its one-line reason instead of refused.

    Raises
    ------
    DataError
        One line: a file's own problem (named), files of different formats, or an empty set.
    """
    if not files:
        raise DataError("data (--data): the data set holds no file")
    suffixes = {f.path.suffix.lower().replace(".pq", ".parquet") for f in files}
    if len(suffixes) > 1:
        raise DataError(f"the data set mixes formats ({', '.join(sorted(suffixes))}): give one kind of file")
    read, aside = [], []
    first = None  # the first file read: (columns, path), to name what differs in one that is not
    for f in files:
        try:
            columns = _columns(f.path)
            try:
                file_runs = read_file(f.path, data)
            except DataError:
                if first is not None and columns != first[0]:
                    raise _columns_differ(f, columns, first) from None
                raise
            first = first or (columns, f.path)
            if callable(rate):  # the first readable file's own rate decides
                rate = rate(at_rate(file_runs, data).rate)
            file = at_rate(file_runs, data, rate)
        except DataError as exc:
            if not skip:
                raise
            aside.append((str(f.path), str(exc)))
            continue
        rate = file.rate
        read.append((f, file, columns))
    if not read:
        raise DataError(f"no file of the data set can be read (the first: {aside[0][1]})")
    return read, aside


def set_at(
    read: Sequence[tuple[DataFile, FileAtRate, tuple[str, ...] | None]],
    data: DataConfig,
    need: int = 1,
    skip: bool = False,
    aside: Sequence[tuple[str, str]] = (),
    order: Sequence[str] = (),
    skipped: Sequence[tuple[str, str]] = (),
    single_input: bool = False,
) -> DataSet:
    """The files :func:`read_files` read, as a data set: every run after ``data.lead_in``,
    holding ``need`` samples, each file with the columns of the set's first kept file and all
    runs at one own rate. With ``skip``, a file that fails is set aside with its reason, beside
    those ``aside`` already holds, all listed in the files' ``order`` (their paths); ``skipped``
    (:attr:`FoundFiles.skipped`) is kept with the set; ``single_input`` lets a run's ft or fd be
    constant (:func:`hcid.io.measured.records_of`)."""
    records: dict[int, dict[str, np.ndarray]] = {}
    runs: list[dict[str, object]] = []
    aside = list(aside)
    native = first = None  # the first kept file's first run's (rate, path, run id); (columns, path)
    several = len(read) > 1 or data.dimensions is not None
    kept = []
    for f, file, columns in read:
        try:
            if first is not None and columns != first[0]:
                raise _columns_differ(f, columns, first)
            file_records = records_of(file, data, need, single_input)
            native = _same_rate(f, file.natives, native)
        except DataError as exc:
            if not skip:
                raise
            aside.append((str(f.path), str(exc)))
            continue
        first = first or (columns, f.path)
        kept.append(f)
        for file_run, record in file_records.items():
            run = len(records) + 1 if several else file_run
            records[run] = record
            runs.append(
                {
                    "run": run,
                    "file": str(f.path),
                    "file_run": int(file_run),
                    **dict(f.factors),
                    **file.natives[file_run]["factors"],
                }
            )
    position = {path: i for i, path in enumerate(order)}
    aside.sort(key=lambda item: position.get(item[0], len(position)))
    if not records:
        raise DataError(f"no file of the data set can be read (the first: {aside[0][1]})")
    factors = tuple(n for n, _ in kept[0].factors) + tuple(
        d for d in (data.dimensions or ()) if d != "sample"
    )
    # Files by their path under the set's common folder: the same whatever the set was given as.
    root = Path(os.path.commonpath([str(f.path.resolve().parent) for f in kept]))
    names = {str(f.path): f.path.resolve().relative_to(root).as_posix() for f in kept}
    for r in runs:
        r["file"] = names[r["file"]]
    return DataSet(records, runs, factors, float(read[0][1].rate), tuple(aside), tuple(skipped))


def read_set(
    files: Sequence[DataFile], data: DataConfig, rate: float | None = None, need: int = 1, skip: bool = False
) -> DataSet:
    """Read and check every file of a set once (:func:`read_files`, then :func:`set_at`). With
    ``skip``, a file whose reading or checks fail (its own problem, or columns or a sample rate
    that differ from the set's first kept file) is left out with its reason
    (``DataSet.set_aside``, in the files' order) instead.

    Raises
    ------
    DataError
        One line: a file's own problem (named), files of different formats,
        columns or sample rates (the first that differs named against the first
        file), or an empty set.
    """
    read, aside = read_files(files, data, rate, skip)
    return set_at(read, data, need, skip, aside, [str(f.path) for f in files])


def _columns_differ(f: DataFile, columns, first) -> DataError:
    mine, theirs = list(columns or []), list(first[0] or [])
    return DataError(f"{f.path}: columns {mine} differ from {first[1].name}'s {theirs}")


def _same_rate(f: DataFile, natives: dict, native):
    """A file's runs checked against the set's first run's native rate (``native``: its rate,
    path and run id, or None before it); returns that first run's."""
    for file_run, info in natives.items():
        found = info["rate"]
        if native is None:
            native = (found, f.path, file_run)
        elif not np.isclose(found, native[0], rtol=1e-6):
            raise DataError(
                f"{f.path}: run {file_run} is sampled at {found:.6g} Hz, {native[1].name} at "
                f"{native[0]:.6g} Hz: a set's files share one rate"
            )
    return native


def runs_table(name: str, data_set: DataSet) -> pa.Table:
    """``runs.parquet``: model (the data name), seed (the run id), file, file_run, then a string
    column per factor."""
    columns = {
        "model": pa.array([name] * len(data_set.runs), pa.string()),
        "seed": pa.array([r["run"] for r in data_set.runs], pa.int64()),
        "file": pa.array([r["file"] for r in data_set.runs], pa.string()),
        "file_run": pa.array([r["file_run"] for r in data_set.runs], pa.int64()),
    }
    for factor in data_set.factors:
        columns[factor] = pa.array([str(r[factor]) for r in data_set.runs], pa.string())
    table = pa.table(columns)
    assert RUNS.problem(table) is None
    return table
