"""Measured human-in-the-loop data: read CSV, Parquet, MATLAB or numpy .npz files into records.

Part of the results layer (it reads files). A data file holds one or more runs
of one subject and condition, each with ft, fd, e and u (rad) and either a
time column or a sample rate. Names are mapped by the config's ``data``
section. Every check fails with one line naming the file and what is wrong:
a file above :data:`hcid.io.formats.MAX_FILE_BYTES`, missing columns, unequal lengths, a run
id in two places, a non-uniform or wrong sample rate, NaN, inf or a value
beyond :data:`LARGEST`, a constant signal, or a record too short for the
identification windows.

Every signal read from a file, a data file's or a forcing function's, passes
the same checks (:func:`check_signal`), and only the columns the config names
are read.

Layouts:

How each format's columns are read: :mod:`hcid.io.formats`.

- CSV / Parquet: one row per sample, a column per signal; several runs are
  told apart by the ``run`` column (integers; each run one contiguous block
  of rows, its id kept as the file gives it), else the file is run 1. A CSV
  may start with a UTF-8 byte-order mark and hold ``#`` comment lines.
- MATLAB ``.mat``: one variable per signal, a vector (run 1) or a
  samples x runs matrix (runs 1, 2, ...); the rate as a scalar variable
  (``rate`` mapping) or a time vector (``time`` mapping).
- numpy ``.npz``: one array per signal (1-D or n x 1), runs by a ``run`` array as
  in a CSV, the rate as a time array or a ``rate`` number; ``ref`` may be saved as
  ``ref_``. Never unpickled: an object array is refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid.config import Config, DataConfig
from hcid.errors import DataError, quote
from hcid.io.formats import column_label, csv_layout, read_columns
from hcid.tables import MEASURED, SIGNALS

__all__ = [
    "LARGEST",
    "FileAtRate",
    "FileRuns",
    "check_signal",
    "read_file",
    "read_signal",
    "at_rate",
    "records_of",
    "records_table",
    "samples_needed",
]

#: Largest magnitude a signal may hold: its square, summed over a record and scaled by a loop's gains,
#: must stay far from overflow (1.8e308) in the simulations and least-squares fits.
LARGEST = 1e100
#: A time column's steps may differ from their mean by this share of it (rounded time stamps).
TIME_JITTER = 1e-2


def check_signal(x: np.ndarray, where: str) -> np.ndarray:
    """``x`` as contiguous float64 if every value is finite and at most :data:`LARGEST` in magnitude.

    The one check every signal from a file passes (data columns and forcing functions).

    Raises
    ------
    DataError
        Naming ``where``, the first bad value and its sample.
    """
    if np.iscomplexobj(x):
        raise DataError(f"{where} holds complex values; a signal is real")
    try:
        x = np.ascontiguousarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError(f"{where} must hold numbers, got {type(x).__name__}") from None
    if x.size == 0:
        raise DataError(f"{where} holds no samples")
    bad = ~np.isfinite(x) | (np.abs(x) > LARGEST)
    if bad.any():
        k = int(np.argmax(bad))
        raise DataError(
            f"{where} holds {x[k]:.6g} at sample {k} (values must be finite and at most {LARGEST:g} "
            "in magnitude)"
        )
    return x


def _read_columns(path: Path, data: DataConfig) -> dict[str, np.ndarray]:
    wanted = {
        name: data.columns[name]
        for name in (*SIGNALS, "theta", "time", "run", "rate")
        if name in data.columns
    }
    if data.time_default:
        wanted["time_alt"] = "time"  # default names: 't' or 'time'
    options = {}
    if data.struct is not None:
        options["struct"] = data.struct
    if data.dimensions is not None:
        options["nd"] = True
    return read_columns(path, wanted, **options)


def run_blocks(ids: np.ndarray, where: str, column: str) -> dict[int, slice]:
    """The rows of each run id, in the order of the ids: each run must be one contiguous block.

    Raises
    ------
    DataError
        If there are no rows, an id is not an integer, or a run's rows are split (the same id
        in two places: two trials given one id must not be merged).

    Examples
    --------
    >>> run_blocks(np.array([11.0, 11, 12, 12, 12]), "f", "run")
    {11: slice(0, 2, None), 12: slice(2, 5, None)}
    """
    ids = np.ravel(ids)
    if not ids.size:
        raise DataError(f"{where}: no data rows (column {quote(column)} is empty)")
    if not (np.all(np.isfinite(ids)) and np.all(ids == np.round(ids)) and np.all(np.abs(ids) < 2**53)):
        k = int(np.argmax(~np.isfinite(ids) | (ids != np.round(ids)) | ~(np.abs(ids) < 2**53)))
        raise DataError(f"{where}: {quote(column)} holds {ids[k]:.6g} at row {k}; run ids must be integers")
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    ends = np.r_[starts[1:], ids.size]
    blocks: dict[int, slice] = {}
    for a, b in zip(starts, ends, strict=True):
        run = int(ids[a])
        if run in blocks:
            first = blocks[run]
            raise DataError(
                f"{where}: run {run} appears in two separate blocks of rows ({first.start}-{first.stop - 1} "
                f"and {a}-{b - 1} of column {quote(column)}); give each trial its own run id"
            )
        blocks[run] = slice(int(a), int(b))
    return dict(sorted(blocks.items()))


def read_signal(path: str | Path, column: str, run: int | None = None, run_column: str = "run") -> np.ndarray:
    """One column (or .mat variable) of a data file as a float64 vector, e.g. a recorded forcing function.

    With ``run``, only the rows whose ``run_column`` equals it (CSV, Parquet) or that
    column of a samples x runs matrix (.mat, counted from 1); the file must hold
    that run column (or matrix). Without ``run``, a file of several runs is refused.

    Raises
    ------
    DataError
        If the file is missing, too large or unreadable, lacks the column or the
        run column, or a value fails :func:`check_signal`.
    """
    path = Path(path)
    cols = read_columns(path, {"x": column, "run": run_column})
    if "x" not in cols:
        raise DataError(f"{path}: has no column {quote(column)}")
    x = cols["x"]
    if run is None:
        # A file of several runs is never read as one signal (its runs end to end).
        runs = x.shape[1] if x.ndim == 2 and min(x.shape) > 1 else None
        if runs is None and "run" in cols:
            blocks = run_blocks(cols["run"], str(path), run_column)
            runs = len(blocks) if len(blocks) > 1 else None
        if runs is not None:
            raise DataError(
                f"{path}: {quote(column)} holds {runs} runs (column {quote(run_column)} or a samples x "
                "runs matrix); name the one to use with run"
            )
    else:
        if x.ndim == 2 and min(x.shape) > 1:
            if not 1 <= run <= x.shape[1]:
                raise DataError(f"{path}: {quote(column)} has {x.shape[1]} runs, no run {run}")
            x = x[:, run - 1]
        elif "run" in cols:
            blocks = run_blocks(cols["run"], str(path), run_column)
            if run not in blocks:
                raise DataError(f"{path}: no rows with {run_column} = {run} (runs {_id_list(blocks)})")
            x = x.ravel()[blocks[run]]
        else:
            raise DataError(
                f"{path}: run {run} asked for, but the file has no run column {quote(run_column)} "
                "(name it with run_column, or drop run for a file of one run)"
            )
    x = x.ravel() if x.ndim == 1 or min(x.shape) == 1 else x[:, 0]
    return check_signal(x, f"{path}: column {quote(column)}")


def _id_list(blocks: dict[int, slice]) -> str:
    ids = list(blocks)
    return ", ".join(map(str, ids)) if len(ids) <= 6 else f"{ids[0]}, {ids[1]}, ..., {ids[-1]}"


def _split_dimensions(path: Path, cols: dict[str, np.ndarray], data: DataConfig) -> dict[int, dict]:
    """Runs of N-D arrays whose axes ``data.dimensions`` names (``sample`` and factors), run ids
    1, 2, ... over the factors in C order; each run's factors (1-based indices) under ``_factors``."""
    dims = list(data.dimensions)
    signals_ = {n: v for n, v in cols.items() if n not in ("rate", "time", "time_alt", "run")}
    shapes = {n: v.shape for n, v in signals_.items()}
    for name, shape in shapes.items():
        if len(shape) != len(dims):
            raise DataError(
                f"{path}: {data.columns[name]!r} has shape {shape}, data.dimensions names "
                f"{len(dims)} axes {dims}"
            )
    if len(set(shapes.values())) > 1:
        raise DataError(
            f"{path}: signals of unequal shapes ({', '.join(f'{n} {s}' for n, s in shapes.items())})"
        )
    axis = dims.index("sample")
    factors = [d for d in dims if d != "sample"]
    moved = {n: np.moveaxis(v, axis, 0) for n, v in signals_.items()}
    shape = next(iter(moved.values())).shape[1:]
    out = {}
    for run, index in enumerate(np.ndindex(*shape), start=1):
        rec = {n: v[(slice(None), *index)] for n, v in moved.items()}
        rec.update({n: v for n, v in cols.items() if n not in signals_})
        rec["_factors"] = {f: str(i + 1) for f, i in zip(factors, index, strict=True)}
        out[run] = rec
    return out


def _split_runs(
    path: Path, cols: dict[str, np.ndarray], data: DataConfig
) -> dict[int, dict[str, np.ndarray]]:
    """The file's runs by their ids: the run column's values, or 1, 2, ... for a matrix's columns."""
    if data.dimensions is not None:
        return _split_dimensions(path, cols, data)
    lengths = {name: v.shape[0] for name, v in cols.items() if name != "rate" and v.ndim >= 1}
    if len(set(lengths.values())) > 1:
        described = ", ".join(f"{data.columns[n]} {n_}" for n, n_ in lengths.items())
        raise DataError(f"{path}: signals of unequal length ({described})")
    if any(v.ndim == 2 and v.shape[1] > 1 for v in cols.values()):
        widths = {
            v.shape[1] if v.ndim == 2 else 1 for n, v in cols.items() if n not in ("rate", "run", "time")
        }
        if len(widths) > 1:
            raise DataError(f"{path}: signals hold different numbers of runs ({sorted(widths)})")
        n_runs = widths.pop()
        return {
            r + 1: {n: (v[:, r] if v.ndim == 2 and v.shape[1] > 1 else v.ravel()) for n, v in cols.items()}
            for r in range(n_runs)
        }
    flat = {n: v.ravel() for n, v in cols.items()}
    if "run" not in flat:
        return {1: flat}
    blocks = run_blocks(flat.pop("run"), str(path), data.columns["run"])
    return {run: {n: v if n == "rate" else v[rows] for n, v in flat.items()} for run, rows in blocks.items()}


#: Largest up or down factor of a resampling: ratios of rates beyond it are refused.
MAX_RESAMPLING_FACTOR = 100


def resampling_factors(rate_in: float, rate_out: float) -> tuple[int, int]:
    """``(up, down)`` with ``rate_out = rate_in * up / down`` (to 1e-6, as a time column's
    uniformity is checked), both at most 100.

    Raises
    ------
    DataError
        If no such small integers exist (the ratio cannot be done exactly).

    Examples
    --------
    >>> resampling_factors(60.0, 20.0), resampling_factors(100.0, 25.0), resampling_factors(60.0, 25.0)
    ((1, 3), (1, 4), (5, 12))
    """
    from fractions import Fraction

    ratio = Fraction(rate_out / rate_in).limit_denominator(MAX_RESAMPLING_FACTOR)
    up, down = ratio.numerator, ratio.denominator
    if up > MAX_RESAMPLING_FACTOR or abs(rate_in * up / down - rate_out) > 1e-6 * rate_out:
        raise DataError(
            f"cannot resample {rate_in:.10g} Hz to {rate_out:g} Hz exactly: the ratio is not "
            f"p/q with p, q <= {MAX_RESAMPLING_FACTOR}"
        )
    return up, down


def resample(x: np.ndarray, up: int, down: int) -> np.ndarray:
    """Resample by ``up/down`` with ``scipy.signal.resample_poly``: zero phase, anti-aliased.

    The polyphase FIR is a Kaiser-windowed sinc (beta 5, cut-off at the lower of the two
    Nyquist frequencies), linear phase with its delay removed; the signal is taken
    as 0 outside the record, so the first and last ``10 max(up, down)`` input samples
    are affected by the record's ends.
    """
    from scipy import signal as sps

    if up == down:
        return x
    return sps.resample_poly(x, up, down)


def samples_needed(config: Config) -> int:
    """Samples a run must hold after its lead-in: the end of the last identification window."""
    return max(max(s.validation.last, s.estimation.last) for _, s in config.identify.stages)


def read_runs(
    path: str | Path, data: DataConfig, rate: float | None = None, need: int = 1
) -> tuple[dict[int, dict[str, np.ndarray]], float]:
    """Read and check a measured-data file; one record per run, keyed by the file's run id.

    Parameters
    ----------
    path : str or Path
        A CSV, Parquet, MATLAB or .npz file (:data:`hcid.io.formats.READERS`).
    data : DataConfig
        Column names (by default ``t`` or ``time``, ``ft``, ``fd``, ``e``, ``u``,
        ``run``; without an ``e`` column, ``e = ft - theta`` from the system output)
        and the lead-in (s) skipped at the start of every run.
    rate : float, optional
        Analysis rate (Hz). A run at a higher rate is resampled once to it
        (:func:`resample`, zero phase) before the lead-in is skipped. Default: the
        first run's own rate.
    need : int
        Samples each run must hold after the lead-in (the identification windows);
        no signal may be constant over them (over the whole run when ``need`` is 1).

    Returns
    -------
    records : dict of int to dict of ndarray
        Per run: ``t`` (s, from 0 after the lead-in), ``ft``, ``fd``, ``e``, ``u`` (rad).
    rate : float
        The analysis rate (Hz): ``rate``, or the first run's own.

    Raises
    ------
    DataError
        One line naming the file and the problem.
    """
    file = at_rate(read_file(path, data), data, rate)
    return records_of(file, data, need), file.rate


@dataclass(frozen=True)
class FileRuns:
    """One measured file as read, once (:func:`read_file`): per run id its checked columns at
    the file's own rate (the signals, and ``time`` or ``rate``) and the factors its position in
    N-D arrays gives (``data.dimensions``, else none). :func:`at_rate` takes them to an
    analysis rate."""

    path: Path
    runs: dict[int, dict[str, np.ndarray]]
    factors: dict[int, dict[str, object]]


@dataclass(frozen=True)
class FileAtRate:
    """A file's runs at an analysis ``rate``, before the lead-in (:func:`at_rate`): per run id
    its signals, and ``{"rate": its own sample rate (Hz), "factors": its factors}``.
    :func:`records_of` cuts the lead-in and checks the length."""

    path: Path
    signals: dict[int, dict[str, np.ndarray]]
    natives: dict[int, dict]
    rate: float


def read_file(path: str | Path, data: DataConfig) -> FileRuns:
    """Read a measured-data file and check its signals (finite, not too large); no rate yet.

    Raises
    ------
    DataError
        One line naming the file and the problem.
    """
    path = Path(path)
    cols = _named_signals(path, _read_columns(path, data), data)
    runs, factors = {}, {}
    for run_id, run in _split_runs(path, cols, data).items():
        factors[run_id] = run.pop("_factors", {})
        where = f"{path}: run {run_id}"
        for name in (*SIGNALS, "time"):
            if name in run:
                run[name] = check_signal(run[name], f"{where}: {column_label(data.columns[name])}")
        runs[run_id] = run
    if not runs:
        raise DataError(f"{path}: holds no samples")
    return FileRuns(path, runs, factors)


def at_rate(file: FileRuns, data: DataConfig, rate: float | None = None) -> FileAtRate:
    """A file's runs resampled once to the analysis ``rate`` (default: the first run's own;
    :func:`resample`, zero phase); a run slower than it is refused."""
    given = rate is not None
    signals, natives = {}, {}
    for run_id, run in file.runs.items():
        where = f"{file.path}: run {run_id}"
        found = _run_rate(where, run, data, rate)
        if rate is None:
            rate = found
        natives[run_id] = {"rate": float(found), "factors": file.factors[run_id]}
        signals[run_id] = _at_rate(where, {name: run[name] for name in SIGNALS}, found, rate, given)
    return FileAtRate(file.path, signals, natives, float(rate))


def records_of(
    file: FileAtRate, data: DataConfig, need: int = 1, single_input: bool = False
) -> dict[int, dict[str, np.ndarray]]:
    """Each run's record after ``data.lead_in``, holding at least ``need`` samples, no signal
    constant over them (:func:`read_runs`); with ``single_input``, one of ft and fd may be (a
    disturbance-only or target-only trial, SPEC 12)."""
    return {
        run_id: _after_lead_in(f"{file.path}: run {run_id}", signals_, file.rate, data, need, single_input)
        for run_id, signals_ in file.signals.items()
    }


def _named_signals(path: Path, cols: dict[str, np.ndarray], data: DataConfig) -> dict[str, np.ndarray]:
    """The file's columns under hcid's names, ``e = ft - theta`` derived; every signal and a time or rate."""
    if "time" not in cols and "time_alt" in cols:
        cols["time"] = cols.pop("time_alt")
    cols.pop("time_alt", None)
    if "e" not in cols and "theta" in cols and "ft" in cols:
        if cols["theta"].shape != cols["ft"].shape:
            raise DataError(
                f"{path}: signals of unequal length ({data.columns['theta']}, {data.columns['ft']})"
            )
        cols["e"] = cols["ft"] - cols["theta"]  # e = ft - theta
    cols.pop("theta", None)
    absent = [n for n in SIGNALS if n not in cols]
    if absent:
        missing = [column_label(data.columns[n]) for n in absent]
        theta = column_label(data.columns["theta"])
        hint = f" (or a system output '{theta}' for e = ft - theta)" if "e" in absent else ""
        wanted = [data.columns[n] for n in (*absent, "theta") if n in data.columns]
        if any(isinstance(c, int) for c in wanted) and path.suffix.lower() in (".csv", ".txt"):
            hint += f"; the file has {csv_layout(path)[2]} columns"
        raise DataError(
            f"{path}: missing columns {missing}{hint} (mapped in a config's data.columns, or "
            "read_records' columns=)"
        )
    if "time" not in cols and "rate" not in cols:
        raise DataError(
            f"{path}: needs a time column '{data.columns['time']}' or a rate '{data.columns['rate']}'"
        )
    return cols


def time_rate(time: np.ndarray, where: str, default: float | None = None) -> float:
    """The sample rate (Hz) of a uniformly sampled, increasing time vector (s); ``default`` for a
    single sample.

    A logger's time stamps are rounded (to 1 us, say: 6e-5 of a 60 Hz step): each step may
    differ from the mean by :data:`TIME_JITTER` of it, a dropped or doubled sample may not.

    Raises
    ------
    DataError
        Naming ``where`` and the first step that is off, or a time that does not increase.
    """
    steps = np.diff(time)
    mean = (time[-1] - time[0]) / steps.size if steps.size else 0.0
    off = np.abs(steps - mean) > TIME_JITTER * abs(mean) + 1e-9
    if steps.size and off.any():
        k = int(np.argmax(off))
        raise DataError(
            f"{where}: time is not uniformly sampled (step {steps[k]:.6g} s at sample "
            f"{k + 1}, mean step {mean:.6g} s)"
        )
    if steps.size and steps[0] <= 0:
        raise DataError(f"{where}: time does not increase (step {steps[0]:.6g} s)")
    if not steps.size and default is None:
        raise DataError(f"{where}: one sample only; a run needs at least two to have a sample rate")
    return steps.size / (time[-1] - time[0]) if steps.size else default


def _run_rate(where: str, run: dict[str, np.ndarray], data: DataConfig, default: float | None) -> float:
    """A run's sample rate (Hz): from its uniformly sampled time column, else its rate column."""
    if "time" in run:
        return time_rate(run["time"], where, default)
    rates = np.ravel(run["rate"])
    if rates.size == 0 or not np.isfinite(rates[0]) or rates[0] <= 0:
        raise DataError(f"{where}: the rate {data.columns['rate']!r} is empty or not a positive number")
    return float(rates[0])


def _at_rate(
    where: str, signals_: dict[str, np.ndarray], found: float, rate: float, given: bool
) -> dict[str, np.ndarray]:
    """The signals resampled from ``found`` to ``rate`` Hz (unchanged when they agree to 1e-6)."""
    if np.isclose(found, rate, rtol=1e-6):
        return signals_
    if found < rate:
        which = "the config's analysis rate (timing.output_rate)" if given else "the first run's rate"
        raise DataError(
            f"{where}: sample rate {found:.6g} Hz, below {which} {rate:g} Hz; "
            "set that to the data's rate or lower"
        )
    try:
        up, down = resampling_factors(found, rate)
    except DataError as exc:
        raise DataError(f"{where}: {exc}") from None
    return {name: resample(x, up, down) for name, x in signals_.items()}


def _after_lead_in(
    where: str,
    signals_: dict[str, np.ndarray],
    rate: float,
    data: DataConfig,
    need: int,
    single_input: bool = False,
) -> dict[str, np.ndarray]:
    """The record after the lead-in, long enough and with no signal constant over ``need`` samples."""
    total = signals_["ft"].size
    skip = round(data.lead_in * rate)
    if total - skip < need:
        lead = f", {total - skip} after the {data.lead_in:g} s lead-in" if skip and total > skip else ""
        if skip >= total:
            lead = f", none after the {data.lead_in:g} s lead-in"
        raise DataError(
            f"{where}: {total} samples at {rate:g} Hz{lead}, the identification windows (data.window, "
            f"or identify's estimation and validation rows) need {need}"
        )
    n = total - skip
    signals_ = {name: np.ascontiguousarray(x[skip:]) for name, x in signals_.items()}
    constant = [name for name in SIGNALS if np.ptp(signals_[name][: need if need > 1 else n]) == 0]
    forcing = [name for name in constant if name in ("ft", "fd")]
    if single_input and len(forcing) == 1:  # one input absent: a single-input trial
        constant.remove(forcing[0])
    for name in constant:
        window = signals_[name][: need if need > 1 else n]
        if np.ptp(window) == 0:
            raise DataError(
                f"{where}: {data.columns.get(name, name)} is constant ({window[0]:.6g}) over the "
                "identification windows"
            )
    return {"t": np.arange(n) / rate, **signals_}


def records_table(name: str, records: dict[int, dict[str, np.ndarray]]) -> pa.Table:
    """The imported runs as a table: model (the data name), seed (the run), k, t, ft, fd, e, u."""
    parts = {c: [] for c in ("model", "seed", "k", "t", *SIGNALS)}
    for run, rec in records.items():
        n = rec["ft"].size
        parts["model"].append(np.full(n, name, dtype=object))
        parts["seed"].append(np.full(n, run, dtype=np.int64))
        parts["k"].append(np.arange(n, dtype=np.int64))
        for c in ("t", *SIGNALS):
            parts[c].append(rec[c])
    return pa.Table.from_pydict({c: np.concatenate(v) for c, v in parts.items()}, schema=MEASURED.arrow)
