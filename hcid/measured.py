"""Measured human-in-the-loop data: read CSV, Parquet or MATLAB files into records.

Part of the results layer (it reads files). A data file holds one or more runs
of one subject and condition, each with ft, fd, e and u (rad) and either a
time column or a sample rate. Names are mapped by the config's ``data``
section. Every check fails with one line naming the file and what is wrong:
missing columns, unequal lengths, a non-uniform or wrong sample rate, NaN or
inf, or a record too short for the identification windows.

Layouts:

- CSV / Parquet: one row per sample, a column per signal; several runs are
  told apart by the ``run`` column (integers), else the file is one run.
- MATLAB ``.mat``: one variable per signal, a vector (one run) or a
  samples x runs matrix; the rate as a scalar variable (``rate`` mapping) or
  a time vector (``time`` mapping).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid.config import Config, DataConfig
from hcid.errors import DataError
from hcid.tables import MEASURED, SIGNALS

__all__ = ["READERS", "load_data", "read_signal", "records_table"]

#: Largest magnitude a signal may hold: its square must not overflow in the least-squares fits.
_LARGEST = 1e150


def _table_columns(table: pa.Table, path: Path, wanted: dict[str, str]) -> dict[str, np.ndarray]:
    out = {}
    for name, column in wanted.items():
        if column in table.column_names:
            try:
                out[name] = table.column(column).to_numpy(zero_copy_only=False).astype(np.float64)
            except (pa.ArrowException, ValueError) as exc:
                raise DataError(f"{path}: column {column!r} is not numeric") from exc
    return out


def _read_csv(path: Path, wanted: dict[str, str]) -> dict[str, np.ndarray]:
    import io

    import pyarrow.csv as pacsv

    # Loggers write a header of '#' comment lines: skipped, as are comment lines further down.
    with open(path, "rb") as f:
        lines = [line for line in f if not line.lstrip().startswith(b"#")]
    return _table_columns(pacsv.read_csv(io.BytesIO(b"".join(lines))), path, wanted)


def _read_parquet(path: Path, wanted: dict[str, str]) -> dict[str, np.ndarray]:
    import pyarrow.parquet as pq

    return _table_columns(pq.read_table(path), path, wanted)


def _read_mat(path: Path, wanted: dict[str, str]) -> dict[str, np.ndarray]:
    import scipy.io

    try:
        mat = scipy.io.loadmat(path)
    except Exception as exc:  # noqa: BLE001 (a damaged file makes scipy's reader raise almost anything)
        raise DataError(f"{path}: not a readable MATLAB file ({str(exc).splitlines()[0][:80]})") from exc
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
        # MATLAB stores vectors as 1 x n or n x 1 matrices, and may add singleton dimensions.
        value = value.reshape([d for d in value.shape if d != 1] or [value.size])
        if value.ndim > 2:
            raise DataError(
                f"{path}: variable {var!r} has shape {mat[var].shape}: more than two non-singleton "
                "dimensions (use a vector or a samples x runs matrix)"
            )
        out[name] = value
    return out


#: Data formats by file suffix: ``reader(path, wanted) -> {signal: array}``, where ``wanted``
#: maps ft, fd, e, u, time, run and rate to the file's names. Add a format here.
READERS = {".csv": _read_csv, ".parquet": _read_parquet, ".pq": _read_parquet, ".mat": _read_mat}


def _read_columns(path: Path, data: DataConfig) -> dict[str, np.ndarray]:
    suffix = path.suffix.lower()
    wanted = {
        name: data.columns[name]
        for name in (*SIGNALS, "theta", "time", "run", "rate")
        if name in data.columns
    }
    if data.time_default:
        wanted["time_alt"] = "time"  # default names: 't' or 'time'
    reader = READERS.get(suffix)
    if reader is None:
        raise DataError(f"{path}: unknown data format {suffix!r} (use {', '.join(READERS)})")
    try:
        return reader(path, wanted)
    except DataError:
        raise
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read ({str(exc).splitlines()[0]})") from exc


def read_signal(path: str | Path, column: str, run: int | None = None, run_column: str = "run") -> np.ndarray:
    """One column (or .mat variable) of a data file as a float64 vector, e.g. a recorded forcing function.

    With ``run``, only the rows whose ``run_column`` equals it (CSV, Parquet) or that
    column of a samples x runs matrix (.mat, counted from 1).

    Raises
    ------
    DataError
        If the file is missing or unreadable, lacks the column, or the values are not finite.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: missing")
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise DataError(f"{path}: unknown data format {path.suffix.lower()!r} (use {', '.join(READERS)})")
    wanted = {"x": column} if run is None else {"x": column, "run": run_column}
    try:
        cols = reader(path, wanted)
    except DataError:
        raise
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read ({str(exc).splitlines()[0]})") from exc
    if "x" not in cols:
        raise DataError(f"{path}: has no column {column!r}")
    x = cols["x"]
    if run is not None:
        if x.ndim == 2:
            if not 1 <= run <= x.shape[1]:
                raise DataError(f"{path}: {column!r} has {x.shape[1]} runs, no run {run}")
            x = x[:, run - 1]
        elif "run" in cols:
            rows = cols["run"].ravel() == run
            if not rows.any():
                raise DataError(f"{path}: no rows with {run_column} = {run}")
            x = x.ravel()[rows]
    x = np.ascontiguousarray(x.ravel() if x.ndim == 1 or min(x.shape) == 1 else x[:, 0], dtype=np.float64)
    if x.size == 0 or not np.all(np.isfinite(x)):
        raise DataError(f"{path}: column {column!r} is empty or holds NaN or inf")
    return x


def _split_runs(path: Path, cols: dict[str, np.ndarray], data: DataConfig) -> list[dict[str, np.ndarray]]:
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
        return [
            {n: (v[:, r] if v.ndim == 2 and v.shape[1] > 1 else v.ravel()) for n, v in cols.items()}
            for r in range(n_runs)
        ]
    flat = {n: v.ravel() for n, v in cols.items()}
    if "run" not in flat:
        return [flat]
    runs = flat.pop("run")
    out = []
    for value in np.unique(runs):
        rows = runs == value
        out.append({n: v if n == "rate" else v[rows] for n, v in flat.items()})
    return out


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


def load_data(path: str | Path, config: Config) -> dict[int, dict[str, np.ndarray]]:
    """Read and check a measured-data file; one record per run, keyed by run number (1, 2, ...).

    Each record holds ``t`` (s, from 0 after the lead-in), ``ft``, ``fd``, ``e``, ``u``
    (rad) at the analysis rate ``config.timing.output_rate``. Column names are the
    config's ``data.columns`` (by default ``t`` or ``time``, ``ft``, ``fd``, ``e``,
    ``u``, ``run``); without an ``e`` column, ``e = ft - theta`` from the system
    output. A run at another rate is resampled once to the analysis rate
    (:func:`resample`, zero phase); then ``data.lead_in`` s are skipped.

    Raises
    ------
    DataError
        One line naming the file and the problem.
    """
    from hcid.config.parse import default_data

    path = Path(path)
    data = config.data if config.data is not None else default_data()
    if not path.is_file():
        raise DataError(f"{path}: missing")
    cols = _read_columns(path, data)
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
    missing = [data.columns[n] for n in SIGNALS if n not in cols]
    if missing:
        hint = (
            f" (or a system output '{data.columns['theta']}' for e = ft - theta)"
            if "e" in missing[-1:]
            else ""
        )
        raise DataError(f"{path}: missing columns {missing}{hint} (mapped in the config's data.columns)")
    if "time" not in cols and "rate" not in cols:
        raise DataError(
            f"{path}: needs a time column '{data.columns['time']}' or a rate '{data.columns['rate']}'"
        )
    rate = config.timing.output_rate
    need = max(max(s.validation.last, s.estimation.last) for _, s in config.identify.stages)
    skip = round(data.lead_in * rate)
    records = {}
    for i, run in enumerate(_split_runs(path, cols, data), start=1):
        where = f"{path}: run {i}"
        for name in (*SIGNALS, "time"):
            if name in run:
                bad = ~np.isfinite(run[name]) | (np.abs(run[name]) > _LARGEST)
                if bad.any():
                    k = int(np.argmax(bad))
                    label = data.columns[name] if name != "e" or "e" in data.columns else "e"
                    raise DataError(
                        f"{where}: {label} holds {run[name][k]:.6g} at sample {k} "
                        f"(values must be finite and at most {_LARGEST:g} in magnitude)"
                    )
        if "time" in run:
            steps = np.diff(run["time"])
            if steps.size and not np.allclose(steps, steps[0], rtol=1e-6, atol=1e-9):
                k = int(np.argmax(np.abs(steps - steps[0]) > 1e-6 * abs(steps[0]) + 1e-9))
                raise DataError(
                    f"{where}: time is not uniformly sampled (step {steps[k]:.6g} s at sample "
                    f"{k + 1}, first step {steps[0]:.6g} s)"
                )
            if steps.size and steps[0] <= 0:
                raise DataError(f"{where}: time does not increase (step {steps[0]:.6g} s)")
            found = steps.size / (run["time"][-1] - run["time"][0]) if steps.size else rate
        else:
            rates = np.ravel(run["rate"])
            if rates.size == 0 or not np.isfinite(rates[0]) or rates[0] <= 0:
                raise DataError(
                    f"{where}: the rate {data.columns['rate']!r} is empty or not a positive number"
                )
            found = float(rates[0])
        signals_ = {name: run[name] for name in SIGNALS}
        if not np.isclose(found, rate, rtol=1e-6):
            if found < rate:
                raise DataError(
                    f"{where}: sample rate {found:.6g} Hz, below the config's analysis rate "
                    f"(timing.output_rate) {rate:g} Hz; set that to the data's rate or lower"
                )
            try:
                up, down = resampling_factors(found, rate)
            except DataError as exc:
                raise DataError(f"{where}: {exc}") from None
            signals_ = {name: resample(x, up, down) for name, x in signals_.items()}
        n = signals_["ft"].size - skip
        if n < need:
            raise DataError(
                f"{where}: {n} samples at {rate:g} Hz"
                + (f" after the {data.lead_in:g} s lead-in" if skip else "")
                + f", the identification windows need {need}"
            )
        signals_ = {name: np.ascontiguousarray(x[skip:]) for name, x in signals_.items()}
        for name in ("e", "u"):
            if not np.any(signals_[name][:need]):
                raise DataError(f"{where}: {data.columns[name]} is zero over the identification windows")
        records[i] = {"t": np.arange(n) / rate, **signals_}
    if not records:
        raise DataError(f"{path}: holds no samples")
    return records


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
