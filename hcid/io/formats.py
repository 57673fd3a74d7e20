"""Data file formats: the named columns of a CSV, Parquet, MATLAB or numpy ``.npz`` file, and
nothing else (results layer; :mod:`hcid.io.measured` turns them into checked records).

- Every file is checked against :data:`MAX_FILE_BYTES` (``stat()``) before it is read.
- CSV: a UTF-8 byte-order mark, ``#`` comment lines and blank lines are dropped block by
  block; the column names are the header row's or, without one, the last ``#`` line's
  (:func:`csv_layout`); a column may be given by position (1 for the first); only the
  named columns are parsed (pyarrow).
- Parquet: only the named columns are read.
- MATLAB: v5/v7 by scipy, v7.3 (HDF5) by h5py; a struct's fields and N-D arrays.
- numpy ``.npz``: ``np.load(allow_pickle=False)`` only (an object array is refused, never
  unpickled); a name answers to its array or, without one, to the name with a trailing
  underscore (``ref_``); 1-D or n x 1 arrays (:func:`_read_npz`).

Add a format to :data:`READERS`.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid.errors import DataError, quote

__all__ = ["MAX_FILE_BYTES", "READERS", "column_label", "csv_layout", "read_columns"]

#: Largest data file (bytes) hcid reads, checked before reading: 1 GiB, about 20 million rows
#: of a CSV with seven columns, or an hour of six signals at 1 kHz in binary.
MAX_FILE_BYTES = 1 << 30

_BOM = b"\xef\xbb\xbf"
_BLANK_LINE = re.compile(rb"(?:^|\n)[ \t\r]*\n")
_BLOCK = 1 << 20


def _check_size(path: Path) -> None:
    try:
        if not path.is_file():
            kind = "not a regular file (a pipe, socket or device)" if path.exists() else "missing"
            raise DataError(f"{path}: {kind}")
        size = path.stat().st_size
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    if size > MAX_FILE_BYTES:
        raise DataError(
            f"{path}: {size:,} bytes, above the {MAX_FILE_BYTES:,}-byte limit on a data file "
            "(split it into several files)"
        )


def _table_columns(
    table: pa.Table, path: Path, wanted: dict[str, str], labels: dict[str, str | int] | None = None
) -> dict[str, np.ndarray]:
    """The ``wanted`` columns of ``table`` as float64; ``labels`` name them in messages."""
    out = {}
    for name, column in wanted.items():
        if column in table.column_names:
            try:
                out[name] = table.column(column).to_numpy(zero_copy_only=False).astype(np.float64)
            except (pa.ArrowException, ValueError, TypeError) as exc:
                given = (labels or wanted)[name]
                label = f"column {given}" if isinstance(given, int) else f"column {quote(given)}"
                raise DataError(f"{path}: {label} is not numeric") from exc
    return out


def _by_name(path: Path, wanted: dict[str, str | int]) -> None:
    """Columns by position are a CSV's: refused for the other formats."""
    positions = [c for c in wanted.values() if isinstance(c, int)]
    if positions:
        raise DataError(
            f"{path}: columns by position (e.g. {positions[0]}) are for CSV files; name the columns"
        )


def _is_comment(line: bytes) -> bool:
    return line.lstrip().startswith(b"#")


def _uncommented(path: Path) -> pa.Buffer:
    """A CSV file's bytes without a leading UTF-8 byte-order mark and without ``#`` comment or
    blank lines, in memory that Arrow owns.

    Read block by block, so a file is never held twice in memory. Arrow's CSV reader is handed
    this buffer, never a Python object (a file object, or ``pa.py_buffer`` of bytes): Arrow's
    threads may release what they were given after ``read_csv`` returns, releasing a Python
    object takes the interpreter lock, and a thread that asks for it while the interpreter exits
    aborts the process (``terminate called without an active exception``, apache/arrow#34314)
    where a refusal should exit with code 2.
    """
    sink = pa.BufferOutputStream()
    tail = b""
    with open(path, "rb") as f:
        first = True
        while True:
            block = f.read(_BLOCK)
            if first:
                block, first = block.removeprefix(_BOM), False
            if block:
                block = tail + block
                cut = block.rfind(b"\n") + 1
                whole, tail = block[:cut], block[cut:]
            else:
                whole, tail = tail, b""
            if b"#" in whole or _BLANK_LINE.search(whole):
                whole = b"".join(
                    line for line in whole.splitlines(keepends=True) if line.strip() and not _is_comment(line)
                )
            sink.write(whole)
            if not block:
                return sink.getvalue()


def _fields(line: str, path: Path) -> list[str]:
    try:
        return [f.strip() for f in next(csv.reader([line]), [])]
    except csv.Error as exc:
        raise DataError(f"{path}: cannot read its header line ({exc})") from exc


def _numeric(fields: list[str]) -> bool:
    try:
        [float(f) for f in fields]
    except ValueError:
        return False
    return bool(fields)


def csv_layout(path: str | Path) -> tuple[list[str], bool, int]:
    """``(names, header_row, width)`` of a CSV file.

    ``names``: the header row's fields, or, when the first row is numbers (no header row),
    those of the last ``#`` comment line above it if it names at least two columns
    (a logger's layout), else none. ``width``: fields in the first row of numbers, which
    may exceed the names (a file with one column more than its header names).
    """
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(1 << 16).removeprefix(_BOM)
    comment = None
    rows = []
    for raw in head.decode("utf-8", errors="replace").splitlines():
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if not rows:
                comment = line.lstrip("#").strip()
            continue
        rows.append(line)
        if len(rows) == 2:
            break
    if not rows:
        return [], False, 0
    first = _fields(rows[0], path)
    if not _numeric(first):
        width = len(_fields(rows[1], path)) if len(rows) > 1 else len(first)
        return first, True, max(width, len(first))
    names = _fields(comment, path) if comment else []
    if len(names) < 2 or _numeric(names):
        names = []
    return names, False, len(first)


def column_label(column: str | int) -> str:
    """A column as messages name it: its name, or ``column 4`` for a position."""
    return f"column {column}" if isinstance(column, int) else column


def _read_csv(path: Path, wanted: dict[str, str | int]) -> dict[str, np.ndarray]:
    import pyarrow.csv as pacsv

    names, header_row, width = csv_layout(path)
    index = {}
    for key, column in wanted.items():
        if isinstance(column, int):
            if 1 <= column <= width:
                index[key] = column
        elif column in names:
            index[key] = names.index(column) + 1
    if not index:
        return {}
    generated = [f"_c{i}" for i in range(1, width + 1)]
    table = pacsv.read_csv(
        pa.BufferReader(_uncommented(path)),
        read_options=pacsv.ReadOptions(column_names=generated, skip_rows=1 if header_row else 0),
        convert_options=pacsv.ConvertOptions(
            include_columns=sorted({generated[i - 1] for i in index.values()})
        ),
    )
    return _table_columns(table, path, {key: generated[i - 1] for key, i in index.items()}, wanted)


def _read_parquet(path: Path, wanted: dict[str, str | int]) -> dict[str, np.ndarray]:
    import pyarrow.parquet as pq

    _by_name(path, wanted)
    names = pq.read_schema(path).names
    include = sorted({c for c in wanted.values() if c in names})
    return _table_columns(pq.read_table(path, columns=include), path, wanted) if include else {}


def _read_mat(
    path: Path, wanted: dict[str, str | int], struct: str | None = None, nd: bool = False
) -> dict[str, np.ndarray]:
    """The wanted variables of a MATLAB file (or the fields of its ``struct`` variable).

    v5/v7 files by scipy, v7.3 files (HDF5) by h5py. Without ``nd`` a variable must be a
    vector or a samples x runs matrix; with it, any number of dimensions (named by
    ``data.dimensions``).
    """
    import scipy.io

    _by_name(path, wanted)
    names = [struct] if struct is not None else sorted(set(wanted.values()))
    try:
        mat = scipy.io.loadmat(path, variable_names=names)
    except NotImplementedError:  # scipy's reader stops at MATLAB v7.3, an HDF5 file
        mat = _read_mat73(path, names, struct)
    except Exception as exc:  # noqa: BLE001 (a damaged file makes scipy's reader raise almost anything)
        raise DataError(f"{path}: not a readable MATLAB file ({str(exc).splitlines()[0][:80]})") from exc
    else:
        if struct is not None:
            if struct not in mat:
                raise DataError(f"{path}: has no variable {struct!r} (data.struct)")
            record = mat[struct]
            if record.dtype.names is None or record.size != 1:
                raise DataError(f"{path}: {struct!r} is not a MATLAB struct (data.struct)")
            mat = {field: record[field].flat[0] for field in record.dtype.names}
    return _mat_values(path, mat, wanted, nd)


def _read_mat73(path: Path, names: list[str], struct: str | None) -> dict[str, np.ndarray]:
    """The named variables (or ``struct``'s fields) of a MATLAB v7.3 file, in MATLAB's shape.

    MATLAB writes arrays column-major, so HDF5 shows their dimensions reversed: transposed back.
    """
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if struct is not None:
                if struct not in f:
                    raise DataError(f"{path}: has no variable {struct!r} (data.struct)")
                group = f[struct]
                if not isinstance(group, h5py.Group):
                    raise DataError(f"{path}: {struct!r} is not a MATLAB struct (data.struct)")
                items = {k: group[k] for k in group}
            else:
                items = {k: f[k] for k in names if k in f}
            out = {}
            for name, item in items.items():
                if not isinstance(item, h5py.Dataset):
                    raise DataError(
                        f"{path}: variable {name!r} is not an array (structs inside are not read)"
                    )
                if item.dtype.names is not None:  # MATLAB's complex: a compound of real and imag
                    raise DataError(f"{path}: variable {name!r} holds complex values; give the real signal")
                if item.dtype.kind not in "fiub":
                    raise DataError(f"{path}: variable {name!r} is not numeric (cells are not read)")
                out[name] = np.asarray(item[()], dtype=np.float64).T
            return out
    except DataError:
        raise
    except Exception as exc:  # noqa: BLE001 (h5py raises OSError, KeyError, ... on damaged files)
        raise DataError(f"{path}: not a readable MATLAB v7.3 file ({str(exc).splitlines()[0][:80]})") from exc


def _mat_values(path: Path, mat: dict, wanted: dict[str, str | int], nd: bool) -> dict[str, np.ndarray]:
    out = {}
    for name, var in wanted.items():
        if var not in mat:
            continue
        raw = mat[var]
        if np.iscomplexobj(raw):
            raise DataError(f"{path}: variable {var!r} holds complex values; give the real signal")
        try:
            value = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{path}: variable {var!r} is not numeric") from exc
        if nd and name not in ("rate", "time", "time_alt", "run"):
            out[name] = value
            continue
        # MATLAB stores vectors as 1 x n or n x 1 matrices, and may add singleton dimensions.
        value = value.reshape([d for d in value.shape if d != 1] or [value.size])
        if value.ndim > 2:
            raise DataError(
                f"{path}: variable {var!r} has shape {np.shape(raw)}: more than two non-singleton "
                "dimensions (name them with data.dimensions, e.g. [sample, trial, subject])"
            )
        out[name] = value
    return out


_ZIP = (b"PK\x03\x04", b"PK\x05\x06")  # how a zip archive starts (an empty one: its end record)
#: Readers of a .npy header by its format version; np.savez writes 1.0, or 2.0 for a header past 64 KiB.
_NPY_HEADERS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}


def _read_npz(path: Path, wanted: dict[str, str | int]) -> dict[str, np.ndarray]:
    """The wanted arrays of a numpy ``.npz`` archive, each a column.

    Read by ``np.load(allow_pickle=False)`` only: an object array (a pickled Python object,
    which could run code when loaded) is refused, never unpickled. A name answers to the
    array of that name or, where there is none, to the name with a trailing underscore
    (``ref`` to ``ref_``, as a logger's ``np.savez(**signals)`` leaves them). A column is a
    1-D array or an n x 1 one; ``rate`` may also be a number (a 0-D array). The arrays read
    may unpack to at most :data:`MAX_FILE_BYTES` together (a compressed archive is small on disk).
    """
    _by_name(path, wanted)
    with open(path, "rb") as f:
        start = f.read(6)
    if not start.startswith(_ZIP):
        what = "a single .npy array" if start == b"\x93NUMPY" else "not a zip archive"
        raise DataError(f"{path}: not a .npz archive of named arrays ({what}; np.savez writes one)")
    try:
        npz = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 (a damaged archive makes zipfile raise almost anything)
        raise DataError(f"{path}: not a readable .npz archive ({str(exc).splitlines()[0][:80]})") from exc
    with npz:
        members = {}
        for key, name in wanted.items():
            member = next((m for m in (name, f"{name}_") if m in npz.files), None)
            if member is not None:
                members[key] = member
        unpacked = sum(_npz_entry(path, npz, m).file_size for m in set(members.values()))
        if unpacked > MAX_FILE_BYTES:
            raise DataError(
                f"{path}: its arrays unpack to {unpacked:,} bytes, above the {MAX_FILE_BYTES:,}-byte "
                "limit on a data file (split it into several files)"
            )
        return {key: _npz_column(path, npz, member, key == "rate") for key, member in members.items()}


def _npz_entry(path: Path, npz, member: str):
    """The archive's entry (``zipfile.ZipInfo``) of an array: ``member.npy``, as np.savez names it."""
    try:
        return npz.zip.getinfo(f"{member}.npy")
    except KeyError:
        raise DataError(
            f"{path}: {member!r} is not a numpy array (a file of another kind in the archive)"
        ) from None


def _npz_column(path: Path, npz, member: str, scalar: bool) -> np.ndarray:
    """One array of an archive as a float64 column, its header checked before its data are read."""
    label = f"array {member!r}"
    try:
        with npz.zip.open(_npz_entry(path, npz, member)) as f:
            read_header = _NPY_HEADERS.get(np.lib.format.read_magic(f))
            dtype = read_header(f)[2] if read_header is not None else None
        if dtype is not None and dtype.hasobject:
            raise DataError(
                f"{path}: {label} is a pickled object array; hcid never unpickles a file "
                "(save it as a numeric array)"
            )
        value = npz[member]  # np.load's allow_pickle=False holds here too
    except DataError:
        raise
    except Exception as exc:  # noqa: BLE001 (a damaged entry makes zipfile or numpy raise almost anything)
        raise DataError(f"{path}: {label} cannot be read ({str(exc).splitlines()[0][:80]})") from exc
    if np.iscomplexobj(value):
        raise DataError(f"{path}: {label} holds complex values; give the real signal")
    if value.dtype.kind not in "fiub":
        raise DataError(f"{path}: {label} is not numeric ({value.dtype})")
    if value.ndim == 2 and value.shape[1] == 1:
        value = value[:, 0]
    if scalar and value.ndim == 0:
        value = value.reshape(1)
    if value.ndim != 1:
        raise DataError(
            f"{path}: {label} has shape {value.shape}; a column is a 1-D array or an n x 1 one "
            "(several runs: a run array beside the signals, not a matrix)"
        )
    return np.asarray(value, dtype=np.float64)


#: Data formats by file suffix: ``reader(path, wanted) -> {signal: array}``, where ``wanted``
#: maps ft, fd, e, u, time, run and rate to the file's names. Add a format here; the order
#: decides which of a recording's copies in several formats a data set keeps on a tie
#: (:mod:`hcid.io.datasets`: the first).
READERS = {
    ".csv": _read_csv,
    ".parquet": _read_parquet,
    ".pq": _read_parquet,
    ".mat": _read_mat,
    ".npz": _read_npz,
}


def read_columns(path: Path, wanted: dict[str, str | int], **options) -> dict[str, np.ndarray]:
    """The ``wanted`` columns of a data file that it holds, after the size check.

    ``options`` (``struct``, ``nd``) are the MATLAB reader's; other formats take none.
    """
    _check_size(path)
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise DataError(
            f"{path}: unknown data format {quote(path.suffix.lower())} (use {', '.join(READERS)})"
        )
    if options and reader is not _read_mat:
        raise DataError(f"{path}: data.struct and data.dimensions are for MATLAB files")
    try:
        return reader(path, wanted, **options)
    except DataError:
        raise
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read ({str(exc).splitlines()[0][:160]})") from exc
