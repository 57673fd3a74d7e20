"""Data file formats (hcid.io.formats): how the CSV reader hands a file to Arrow, and numpy's
.npz archives, read through hcid.io.measured as every format is."""

import dataclasses
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pytest

from hcid.config.parse import default_data
from hcid.errors import DataError
from hcid.io import formats
from hcid.io.measured import read_file, read_runs

from .conftest import ROOT

SESSIONS = ROOT.parent / "shared" / "data" / "cphs2017-sessions" / "dp"
LOGGED = "20170901-094005_su17v3_fo_r-sos+E_d-sos+O_s49_p0a0_+1"  # a two-input trial of subject dp
RATE = 25.0


def _signals(n: int = 600, seed: int = 7) -> dict[str, np.ndarray]:
    """Random signals t, ft, fd, e, u of ``n`` samples at 25 Hz (full float64 mantissas)."""
    rng = np.random.default_rng(seed)
    return {"t": np.arange(n) / RATE, **{name: rng.standard_normal(n) for name in ("ft", "fd", "e", "u")}}


def _data(**columns):
    """The default data section (ft, fd, e, u, theta, time t or time, run, rate), some names changed."""
    data = default_data()
    return dataclasses.replace(data, columns={**data.columns, **columns})


# A refusal after a CSV was read exits with its code -----------------------------------------

# Reads a CSV that lacks e and theta: the refusal (a DataError) is printed and the process exits 2.
_REFUSE = """
import sys
from hcid.config.parse import default_data
from hcid.errors import HcidError
from hcid.io.measured import read_file
try:
    read_file(sys.argv[1], default_data())
except HcidError as exc:
    print(exc, file=sys.stderr)
    sys.exit(2)
"""


def _no_theta_csv(path: Path) -> Path:
    """A logger's CSV (two ``#`` lines, then a header row) of t, ft, fd and u: no e, no theta."""
    signals = _signals(3000)
    del signals["e"]
    sink = pa.BufferOutputStream()
    pacsv.write_csv(pa.table(signals), sink)
    path.write_bytes(b"# logger v2, 25 Hz\n# subject 01\n" + sink.getvalue().to_pybytes())
    return path


def test_arrow_reads_a_csv_from_memory_it_owns(tmp_path, monkeypatch):
    # The root of an abort at exit (apache/arrow#34314): given a Python object, Arrow's threads may
    # release it after read_csv returns, taking the interpreter lock, and one that asks for it while
    # the interpreter exits aborts the process. So the reader gets an Arrow buffer, filled by Arrow's
    # allocator (a pa.py_buffer of bytes would hold a Python object, and not count there).
    seen = []
    real = pacsv.read_csv
    before = pa.total_allocated_bytes()

    def spy(source, *args, **kwargs):
        native = isinstance(source, pa.NativeFile) and not isinstance(source, pa.PythonFile)
        allocated = native and pa.total_allocated_bytes() - before >= source.size()
        seen.append((type(source).__name__, native, allocated))
        return real(source, *args, **kwargs)

    monkeypatch.setattr(pacsv, "read_csv", spy)
    with pytest.raises(DataError, match="missing columns"):
        read_file(_no_theta_csv(tmp_path / "no_theta.csv"), default_data())
    assert seen == [("BufferReader", True, True)]


def test_a_refusal_after_reading_a_csv_exits_2_every_time(tmp_path):
    # The refusal printed, then exit code 2, in 30 fresh processes, never an abort at exit (signal
    # 6, exit 134). A guard over repetitions, not a reproduction: the abort is a race, rarer in a
    # process this short than in the CLI's; the test above checks its cause.
    path = _no_theta_csv(tmp_path / "no_theta.csv")

    def run(_):
        return subprocess.run(
            [sys.executable, "-c", _REFUSE, str(path)], capture_output=True, text=True, timeout=120
        )

    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(run, range(30)))
    assert [r.returncode for r in results] == [2] * 30, [
        r.stderr[-300:] for r in results if r.returncode != 2
    ]
    refusal = (
        f"{path}: missing columns ['e'] (or a system output 'theta' for e = ft - theta) (mapped in a "
        "config's data.columns, or read_records' columns=)"
    )
    assert all(r.stderr.splitlines() == [refusal] for r in results)


# numpy .npz archives ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "save",
    [
        pytest.param(lambda path, s: np.savez(path, **s), id="arrays by name"),
        pytest.param(lambda path, s: np.savez(path, **{f"{n}_": v for n, v in s.items()}), id="ref_ names"),
        pytest.param(
            lambda path, s: np.savez_compressed(path, **{n: v.reshape(-1, 1) for n, v in s.items()}),
            id="n x 1, compressed",
        ),
    ],
)
def test_an_npz_gives_the_numbers_of_the_same_data_as_csv(tmp_path, save):
    # The same arrays as CSV (float64 round-trips exactly through its shortest text) and as .npz:
    # read_runs gives the same records, bit for bit, and both equal the arrays written.
    signals = _signals()
    pacsv.write_csv(pa.table(signals), tmp_path / "d.csv")
    save(tmp_path / "d.npz", signals)
    from_csv, rate_csv = read_runs(tmp_path / "d.csv", default_data())
    from_npz, rate_npz = read_runs(tmp_path / "d.npz", default_data())
    assert rate_npz == rate_csv == pytest.approx(RATE)
    assert list(from_npz) == list(from_csv) == [1]
    for name in ("t", "ft", "fd", "e", "u"):
        np.testing.assert_array_equal(from_npz[1][name], from_csv[1][name])
    for name in ("ft", "fd", "e", "u"):
        np.testing.assert_array_equal(from_npz[1][name], signals[name])


def test_an_npz_with_a_run_array_and_a_rate_number(tmp_path):
    # Two runs told apart by a run array, the rate a number (a 0-D array): the runs' records are
    # the rows of each run, as a CSV with a run column and a rate column gives them.
    signals = _signals(1200)
    del signals["t"]
    run = np.repeat([4, 9], 600)
    np.savez(tmp_path / "d.npz", **signals, run=run, rate=np.float64(RATE))
    pacsv.write_csv(pa.table({**signals, "run": run, "rate": np.full(1200, RATE)}), tmp_path / "d.csv")
    from_npz, rate = read_runs(tmp_path / "d.npz", default_data())
    from_csv, _ = read_runs(tmp_path / "d.csv", default_data())
    assert rate == RATE
    assert list(from_npz) == list(from_csv) == [4, 9]
    for run_id, rows in ((4, slice(0, 600)), (9, slice(600, 1200))):
        np.testing.assert_array_equal(from_npz[run_id]["u"], signals["u"][rows])
        np.testing.assert_array_equal(from_npz[run_id]["t"], from_csv[run_id]["t"])


class _Runs:
    """Unpickling this runs code: it creates the file ``marker``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def test_an_object_array_is_refused_never_unpickled(tmp_path):
    marker = tmp_path / "unpickled"
    signals = _signals()
    signals["ft"] = np.array([_Runs(marker)] * signals["ft"].size, dtype=object)
    path = tmp_path / "d.npz"
    np.savez(path, **{f"{n}_": v for n, v in signals.items()})
    with pytest.raises(DataError) as refused:
        read_file(path, default_data())
    assert str(refused.value) == (
        f"{path}: array 'ft_' is a pickled object array; hcid never unpickles a file "
        "(save it as a numeric array)"
    )
    assert not marker.exists()


def _damaged(path: Path, damage: str) -> None:
    """An .npz that is not one, or whose ``u`` is not a column of numbers."""
    signals = _signals()
    if damage == "text":
        path.write_bytes(b"t,ft,fd,e,u\n")
    elif damage == "npy":  # one array, as np.save writes it
        with open(path, "wb") as f:
            np.save(f, signals["u"])
    elif damage == "truncated":  # its zip directory, at the end, cut off
        np.savez(path, **signals)
        path.write_bytes(path.read_bytes()[:5000])
    else:
        u = {
            "matrix": np.stack([signals["u"], signals["u"]], axis=1),
            "strings": signals["u"].astype(str),
            "complex": signals["u"] + 1j,
        }[damage]
        np.savez(path, **{**signals, "u": u})


@pytest.mark.parametrize(
    "damage, message",
    [
        ("text", "not a .npz archive of named arrays (not a zip archive;"),
        ("npy", "not a .npz archive of named arrays (a single .npy array;"),
        ("truncated", "not a readable .npz archive (File is not a zip file)"),
        ("matrix", "array 'u' has shape (600, 2); a column is a 1-D array or an n x 1 one"),
        ("strings", "array 'u' is not numeric (<U"),
        ("complex", "array 'u' holds complex values; give the real signal"),
    ],
)
def test_a_damaged_or_unusable_npz_is_refused_in_one_line(tmp_path, damage, message):
    path = tmp_path / "d.npz"
    _damaged(path, damage)
    with pytest.raises(DataError) as refused:
        read_file(path, default_data())
    assert str(refused.value).startswith(f"{path}: ")
    assert message in str(refused.value)
    assert len(str(refused.value).splitlines()) == 1


def test_npz_columns_by_position_are_refused(tmp_path):
    path = tmp_path / "d.npz"
    np.savez(path, **_signals())
    with pytest.raises(
        DataError, match=r"columns by position \(e.g. 3\) are for CSV files; name the columns"
    ):
        read_file(path, _data(u=3))


def test_the_arrays_an_npz_unpacks_to_are_held_to_the_size_limit(tmp_path, monkeypatch):
    # A compressed archive is small on disk: the limit holds for the arrays it unpacks to, t, ft,
    # fd, e and u here: 600 float64 each and np.savez's 128-byte .npy header, 5 * 4928 bytes.
    path = tmp_path / "d.npz"
    np.savez_compressed(
        path, t=np.arange(600) / RATE, **{name: np.zeros(600) for name in ("ft", "fd", "e", "u")}
    )
    assert path.stat().st_size < 5 * 4928 - 1  # below the limit on disk
    monkeypatch.setattr(formats, "MAX_FILE_BYTES", 5 * 4928 - 1)
    with pytest.raises(DataError, match="its arrays unpack to 24,640 bytes, above the 24,639-byte limit"):
        read_file(path, default_data())
    monkeypatch.setattr(formats, "MAX_FILE_BYTES", 5 * 4928)
    assert list(read_file(path, default_data()).runs) == [1]


@pytest.mark.skipif(not SESSIONS.is_dir(), reason=f"no session recordings at {SESSIONS}")
def test_the_loggers_npz_copies(tmp_path):
    # The lab's logger saved each trial twice (SESSIONS' README): as CSV and as .npz whose ref_ and
    # dis_ are pickled object arrays. Those are refused by name; the numeric arrays equal the CSV's
    # columns exactly (the CSV's 19 significant digits round-trip float64).
    columns = {"time": "time", "ft": "ref", "fd": "dis", "u": "inp", "theta": "state"}
    npz = SESSIONS / f"{LOGGED}.npz"
    with pytest.raises(DataError) as refused:
        read_file(npz, _data(**columns))
    assert str(refused.value) == (
        f"{npz}: array 'ref_' is a pickled object array; hcid never unpickles a file "
        "(save it as a numeric array)"
    )
    wanted = {"time": "time", "u": "inp", "realtime": "realtime"}
    from_npz = formats.read_columns(npz, wanted)
    from_csv = formats.read_columns(npz.with_suffix(".csv"), wanted)
    assert from_npz.keys() == from_csv.keys() == wanted.keys()
    for name in wanted:
        np.testing.assert_array_equal(from_npz[name], from_csv[name])
    state = formats.read_columns(npz, {"theta": "state"})["theta"]  # state_ is n x 1
    assert state.shape == from_npz["time"].shape
