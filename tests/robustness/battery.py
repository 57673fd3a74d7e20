"""Robustness battery: hcid used as a careless or hostile user would (issue 10).

Every case runs the real `hcid` command in a fresh temporary directory, with a
memory limit and a timeout, and is judged handled when either

- it is refused: exit code 2, exactly one line on stderr starting ``hcid: error:``
  and quoting at most a few hundred characters, and the run directory unchanged
  (nothing written, earlier results intact); or
- it is accepted (the input is valid): exit code 0 and the tables it should write.

Usage: python tests/robustness/battery.py [--only SUBSTRING] [--list]
(`make robustness`). Prints one line per case and the totals; exit 1 if any case
was not handled.
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import yaml

ROOT = Path(__file__).resolve().parents[2]
HCID = [str(Path(sys.executable).parent / "hcid")]
MEMORY = 3 << 30  # bytes of address space per case
TIMEOUT = 240.0
BASE = yaml.safe_load((ROOT / "configs" / "ci.yaml").read_text())
BASE["seeds"] = [1]
BASE["timing"]["periods"] = 2
DATA_CONFIG = yaml.safe_load((ROOT / "configs" / "example_data.yaml").read_text())
EXAMPLE_CSV = ROOT / "configs" / "example_data" / "subject_synthetic.csv"


@dataclass
class Case:
    name: str
    # setup(tmp) -> argv (after "hcid"); may write files into tmp.
    setup: Callable[[Path], list[str]]
    expect: str = "either"  # "refused", "accepted" or "either"
    tables: tuple[str, ...] = ()  # files an accepted case must leave in tmp/run
    check: Callable[[Path, subprocess.CompletedProcess], str | None] | None = None
    notes: list[str] = field(default_factory=list)


def _write_config(tmp: Path, data, name: str = "c.yaml") -> Path:
    path = tmp / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
    return path


def _mutated(path: tuple, value, base=None) -> dict:
    data = copy.deepcopy(BASE if base is None else base)
    node = data
    for key in path[:-1]:
        node = node[key]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


_DELETE = object()


def _simulate(data) -> Callable[[Path], list[str]]:
    def setup(tmp: Path) -> list[str]:
        return [
            "simulate",
            str(_write_config(tmp, data)),
            "--run",
            str(tmp / "run"),
            "--quiet",
            "--jobs",
            "1",
        ]

    return setup


def _digest_tree(root: Path) -> str:
    h = hashlib.sha256()
    if not root.exists():
        return "absent"
    for p in sorted(root.rglob("*")):
        if p.name == ".hcid.lock":
            continue  # the lock's holder line changes; its content is not a result
        h.update(str(p.relative_to(root)).encode())
        if p.is_file() and not p.is_symlink():
            h.update(p.read_bytes())
    return h.hexdigest()


def _limit():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))


def run_case(case: Case, keep: bool = False) -> tuple[bool, str, float]:
    tmp = Path(tempfile.mkdtemp(prefix="hcid-battery-"))
    try:
        try:
            argv = case.setup(tmp)
        except Exception as exc:  # noqa: BLE001 (a broken case is reported, not a crash of the battery)
            return False, f"setup failed: {type(exc).__name__}: {str(exc)[:150]}", 0.0
        before = _digest_tree(tmp / "run")
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONWARNINGS="default")
        start = time.perf_counter()
        try:
            proc = subprocess.run(
                [*HCID, *argv], cwd=tmp, capture_output=True, text=True, timeout=TIMEOUT, env=env,
                preexec_fn=_limit, errors="replace",
            )  # fmt: skip
        except subprocess.TimeoutExpired:
            return False, f"timeout after {TIMEOUT:g} s", TIMEOUT
        seconds = time.perf_counter() - start
        err = [line for line in proc.stderr.splitlines() if line.strip()]
        if proc.returncode == 2:
            if case.expect == "accepted":
                return False, f"refused a valid input: {err[:1]}", seconds
            if len(err) != 1 or not err[0].startswith("hcid: error: ") or len(err[0]) > 400:
                return False, f"refusal is not one short line: {len(err)} lines, {err[:2]!r:.300}", seconds
            if _digest_tree(tmp / "run") != before:
                return False, "refused but the run directory changed", seconds
            verdict = "refused: " + err[0][len("hcid: error: ") :][:150]
        elif proc.returncode == 0:
            if case.expect == "refused":
                return False, "accepted an input that must be refused", seconds
            missing = [t for t in case.tables if not (tmp / "run" / t).exists()]
            if missing:
                return False, f"exit 0 but {missing} missing", seconds
            if err and any("Traceback" in line or "Warning" in line for line in err):
                return False, f"exit 0 with stderr noise: {err[:2]!r:.200}", seconds
            verdict = "accepted"
        else:
            tail = err[-1] if err else ""
            return False, f"exit {proc.returncode}: {tail[:200]}", seconds
        if case.check is not None:
            problem = case.check(tmp, proc)
            if problem:
                return False, problem, seconds
        return True, verdict, seconds
    finally:
        if not keep:
            shutil.rmtree(tmp, ignore_errors=True)


# --------------------------------------------------------------------------- config cases

NUMERIC_KEYS = [
    ("models", "FB", "Kpe"), ("models", "FB", "TL"), ("models", "FB", "tau_pe"), ("models", "FF", "Kpt"),
    ("models", "FF", "TI"), ("models", "FF", "tau_pt"), ("loop", "Kc"), ("loop", "wb"), ("loop", "w_nms"),
    ("loop", "zeta_nms"), ("loop", "w_n"), ("loop", "zeta_n"), ("loop", "remnant_ratio"),
    ("signals", "disturbance", "base_period"), ("signals", "disturbance", "time_offset"),
    ("signals", "target", "gain_deg"), ("timing", "sim_rate"), ("timing", "output_rate"),
    ("timing", "run_in"), ("timing", "window"), ("timing", "periods"),
]  # fmt: skip
BAD_VALUES = [("string", "x"), ("negative", -1), ("huge", 1e308), ("null", None), ("bool", True), ("list", [1]),
              ("nan", float("nan")), ("inf", float("inf"))]  # fmt: skip


def config_cases() -> list[Case]:
    cases = []
    for key in NUMERIC_KEYS:
        for label, value in BAD_VALUES:
            cases.append(Case(f"config {'.'.join(key)} = {label}", _simulate(_mutated(key, value)),
                              tables=("simulations.parquet",)))  # fmt: skip
    for section in ("models", "loop", "signals", "timing", "seeds"):
        cases.append(Case(f"config without {section}", _simulate(_mutated((section,), _DELETE)), "refused"))
        cases.append(
            Case(f"config {section} is a string", _simulate(_mutated((section,), "oops")), "refused")
        )
    for path in (("loop",), ("timing",), ("signals", "target"), ("identify", "direct"), ("selection",)):
        data = copy.deepcopy(BASE)
        node = data
        for key in path:
            node = node.setdefault(key, {})
        node["typo_key"] = 1
        cases.append(Case(f"unknown key under {'.'.join(path)}", _simulate(data), "refused"))
    grid_bad = [("na", [0, 3]), ("na", [3, 1]), ("nb1", [0, 100]), ("nk1", [-1, 3]), ("nk2", "x"),
                ("estimation", [0, 10]), ("estimation", [1, 5000]), ("validation", [2048, 2048]),
                ("validation", "all")]  # fmt: skip
    for key, value in grid_bad:
        cases.append(
            Case(
                f"identify.direct.{key} = {value}",
                _simulate(_mutated(("identify", "direct", key), value)),
                "refused",
            )
        )  # noqa: E501
    cases.append(
        Case(
            "identify.direct.na = [1, 30] (valid)",
            _simulate(_mutated(("identify", "direct", "na"), [1, 30])),
            "accepted",
            ("simulations.parquet",),
        )
    )
    cases += [
        Case("identify.direct null", _simulate(_mutated(("identify", "direct"), None)), "refused"),
        Case("identify.stage1 a list", _simulate(_mutated(("identify", "stage1"), [1, 2])), "refused"),
        Case(
            "grid of 4.4e9 candidates",
            _simulate(
                _mutated(
                    ("identify", "direct"),
                    {
                        "na": [1, 30],
                        "nb1": [0, 60],
                        "nb2": [0, 60],
                        "nk1": [0, 200],
                        "nk2": [0, 200],
                        "estimation": [300, 1088],
                        "validation": [1089, 2048],
                    },
                )
            ),
            "refused",
        ),  # fmt: skip
        Case(
            "target_shift not whole samples",
            _simulate(_mutated(("identify", "target_shift"), 1.01)),
            "refused",
        ),
        Case(
            "w_grid max below min",
            _simulate(_mutated(("selection", "w_grid"), {"min": 1, "max": 0.1, "points": 5})),
            "refused",
        ),  # noqa: E501
        Case(
            "w_grid 10^6 points",
            _simulate(_mutated(("selection", "w_grid"), {"min": 1e-4, "max": 1, "points": 10**6})),
            "refused",
        ),  # noqa: E501
        Case("criteria unknown", _simulate(_mutated(("selection", "criteria"), {"xic": {}})), "refused"),
        Case(
            "mbic c negative", _simulate(_mutated(("selection", "criteria"), {"mbic": {"c": -3}})), "refused"
        ),
        Case("target_rate 2", _simulate(_mutated(("selection", "target_rate"), 2)), "refused"),
        Case("seeds empty", _simulate(_mutated(("seeds",), [])), "refused"),
        Case("seeds repeated", _simulate(_mutated(("seeds",), [1, 1])), "refused"),
        Case("seeds 200,000 as a list", _simulate(_mutated(("seeds",), list(range(200_000)))), "refused"),
        Case(
            "seeds first/count 10^6", _simulate(_mutated(("seeds",), {"first": 1, "count": 10**6})), "refused"
        ),
        Case("seeds negative", _simulate(_mutated(("seeds",), [-1])), "refused"),
        Case("Kc 99: unstable loop", _simulate(_mutated(("loop", "Kc"), 99)), "refused"),
        Case("Kpe 60: unstable loop", _simulate(_mutated(("models", "FB", "Kpe"), 60)), "refused"),
        Case(
            "tau_pe 0.245 not whole samples",
            _simulate(_mutated(("models", "FB", "tau_pe"), 0.245)),
            "refused",
        ),
        Case(
            "sim_rate 10 kHz, 100 periods",
            _simulate(
                _mutated(
                    ("timing",),
                    {"sim_rate": 10000, "output_rate": 25, "run_in": 8.09, "window": 81.92, "periods": 100},
                )
            ),
            "refused",
        ),  # fmt: skip
        Case("output_rate not a divisor", _simulate(_mutated(("timing", "output_rate"), 30)), "refused"),
        Case(
            "segments longer than the window",
            _simulate(_mutated(("signals", "target", "segments"), [["c", 100, 0]])),
            "refused",
        ),  # noqa: E501
        Case(
            "segment kind x", _simulate(_mutated(("signals", "target", "segments"), [["x", 3, 0]])), "refused"
        ),
        Case(
            "disturbance amplitude count",
            _simulate(_mutated(("signals", "disturbance", "amplitude"), [0.1])),
            "refused",
        ),  # noqa: E501
        Case("disturbance k zero", _simulate(_mutated(("signals", "disturbance", "k"), [0] * 20)), "refused"),
        Case(
            "model name not an identifier",
            _simulate(_mutated(("models",), {"F B": BASE["models"]["FB"]})),
            "refused",
        ),  # noqa: E501
        Case(
            "model name 2000 characters",
            _simulate(_mutated(("models",), {"FB" * 1000: BASE["models"]["FB"]})),
            "refused",
        ),  # noqa: E501
        Case("name '.'", _simulate(_mutated(("name",), ".")), "refused"),
        Case("name '..'", _simulate(_mutated(("name",), "..")), "refused"),
        Case("name with '/'", _simulate(_mutated(("name",), "a/b")), "refused"),
        Case("name with NUL", _simulate(_mutated(("name",), "a\0b")), "refused"),
        Case("name 500 characters", _simulate(_mutated(("name",), "n" * 500)), "refused"),
        Case(
            "YAML alias bomb (3.7 KB)",
            lambda t: ["simulate", str(_write_config(t, _alias_bomb())), "--run", str(t / "run")],
            "refused",
        ),  # noqa: E501
        Case(
            "duplicate key",
            lambda t: [
                "simulate",
                str(_write_config(t, yaml.safe_dump(BASE) + "seeds: [2]\n")),
                "--run",
                str(t / "run"),
            ],
            "refused",
        ),  # noqa: E501
        Case(
            "nesting 20,000 deep",
            lambda t: [
                "simulate",
                str(_write_config(t, "x: " + "[" * 20000 + "]" * 20000)),
                "--run",
                str(t / "run"),
            ],
            "refused",
        ),  # noqa: E501
        Case(
            "5,000-digit integer",
            lambda t: [
                "simulate",
                str(_write_config(t, "seeds: [" + "9" * 5000 + "]\n")),
                "--run",
                str(t / "run"),
            ],
            "refused",
        ),  # noqa: E501
        Case(
            "non-UTF-8 bytes",
            lambda t: ["simulate", str(_bytes(t, b"name: \xff\xfe\n")), "--run", str(t / "run")],
            "refused",
        ),  # noqa: E501
        Case(
            "binary garbage",
            lambda t: ["simulate", str(_bytes(t, bytes(range(256)) * 40)), "--run", str(t / "run")],
            "refused",
        ),  # noqa: E501
        Case(
            "empty config",
            lambda t: ["simulate", str(_write_config(t, "")), "--run", str(t / "run")],
            "refused",
        ),
        Case(
            "config is a list",
            lambda t: ["simulate", str(_write_config(t, "[1, 2]\n")), "--run", str(t / "run")],
            "refused",
        ),  # noqa: E501
        Case(
            "not YAML",
            lambda t: ["simulate", str(_write_config(t, "models: [unclosed\n")), "--run", str(t / "run")],
            "refused",
        ),  # noqa: E501
        Case(
            "config missing", lambda t: ["simulate", str(t / "none.yaml"), "--run", str(t / "run")], "refused"
        ),
        Case("config is a directory", lambda t: ["simulate", str(t), "--run", str(t / "run")], "refused"),
        Case(
            "config /dev/zero (endless)",
            lambda t: ["simulate", "/dev/zero", "--run", str(t / "run")],
            "refused",
        ),
        Case(
            "config 2 MB",
            lambda t: [
                "simulate",
                str(_write_config(t, "# " + "x" * (2 << 20) + "\n")),
                "--run",
                str(t / "run"),
            ],
            "refused",
        ),  # noqa: E501
        Case(
            "valid config",
            _simulate(BASE),
            "accepted",
            ("simulations.parquet", "config.yaml", "hcid-run.json"),
        ),
        Case("'$' in the name", _simulate(_mutated(("name",), "a$b$c")), "refused"),
    ]
    return cases


def _alias_bomb() -> str:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


def _bytes(tmp: Path, data: bytes) -> Path:
    path = tmp / "c.yaml"
    path.write_bytes(data)
    return path


# --------------------------------------------------------------------------- run directory cases


def _ready_run(tmp: Path, data=None) -> Path:
    """A complete run of the battery's small config in tmp/run (made once, copied)."""
    cache = Path(tempfile.gettempdir()) / "hcid-battery-run"
    if not (cache / "thresholds.parquet").exists():
        shutil.rmtree(cache, ignore_errors=True)
        config = _write_config(Path(tempfile.mkdtemp()), BASE)
        subprocess.run([*HCID, "run", str(config), "--run", str(cache), "--quiet", "--jobs", "1"], check=True,
                       capture_output=True)  # fmt: skip
    shutil.copytree(cache, tmp / "run")
    (tmp / "run" / ".hcid.lock").unlink(missing_ok=True)
    return _write_config(tmp, BASE if data is None else data)


def _tamper(edit):
    def setup(tmp: Path) -> list[str]:
        config = _ready_run(tmp)
        edit(tmp / "run")
        return ["sweep-w", str(config), "--run", str(tmp / "run")]

    return setup


def _report_after(edit):
    def setup(tmp: Path) -> list[str]:
        _ready_run(tmp)
        edit(tmp / "run")
        return ["report", str(tmp / "run")]

    return setup


def _set_column(name: str, column: str, values):
    def edit(run: Path):
        t = pq.read_table(run / name)
        i = t.column_names.index(column)
        pq.write_table(t.set_column(i, column, pa.array(values(t.num_rows))), run / name)

    return edit


def rundir_cases() -> list[Case]:
    def run_into(where: str):
        return lambda t: ["simulate", str(_write_config(t, BASE)), "--run", where, "--quiet"]

    def foreign(tmp: Path) -> list[str]:
        (tmp / "run").mkdir()
        (tmp / "run" / "thesis.parquet").write_bytes(b"my own data")
        return ["simulate", str(_write_config(tmp, BASE)), "--run", str(tmp / "run"), "--force", "--quiet"]

    def force_keeps_user_files(tmp: Path) -> list[str]:
        config = _ready_run(tmp)
        (tmp / "run" / "notes.parquet").write_bytes(b"mine")  # in an hcid run directory, not hcid's
        return ["simulate", str(_write_config(tmp, _mutated(("seeds",), [2]))), "--run", str(tmp / "run"),
                "--force", "--quiet", "--jobs", "1"] if config else []  # fmt: skip

    def keeps(tmp: Path, proc) -> str | None:
        return (
            None
            if (tmp / "run" / "notes.parquet").read_bytes() == b"mine"
            else "deleted a file hcid did not write"
        )

    def symlinked_parts(tmp: Path) -> list[str]:
        config = _ready_run(tmp)
        outside = tmp / "elsewhere"
        outside.mkdir()
        (tmp / "run" / ".parts").symlink_to(outside)
        return ["identify", str(config), "--run", str(tmp / "run"), "--force", "--quiet", "--jobs", "1"]

    def damaged_parts(tmp: Path) -> list[str]:
        config = _ready_run(tmp)
        for name in ("frontier.parquet", "identify_log.parquet", "stage1.parquet"):
            (tmp / "run" / name).unlink()
        parts = tmp / "run" / ".parts" / "direct"
        parts.mkdir(parents=True)
        (parts / "FB__1.frontier.arrow").write_bytes(b"ARROW1 damaged")
        (parts / "FB__1.log.arrow").write_bytes(b"")
        for kind in ("frontier", "log"):  # readable, but off the part's schema
            path, schema = parts / f"FF__1.{kind}.arrow", pa.schema([("x", pa.int64())])
            with pa.OSFile(str(path), "wb") as sink, pa.ipc.new_file(sink, schema) as writer:
                writer.write_table(pa.table({"x": [1]}))
        (parts / "junk__x.frontier.arrow").write_bytes(b"")
        return ["identify", str(config), "--run", str(tmp / "run"), "--quiet", "--jobs", "1"]

    def complete_rerun(tmp: Path) -> list[str]:
        config = _ready_run(tmp)
        return ["run", str(config), "--run", str(tmp / "run"), "--quiet", "--jobs", "1"]

    def edited_config_yaml(tmp: Path) -> list[str]:
        _ready_run(tmp)
        path = tmp / "run" / "config.yaml"
        path.write_text(path.read_text().replace("seeds:\n- 1\n", "seeds:\n- 7\n", 1))
        return ["report", str(tmp / "run")]

    def run_config_non_utf8(tmp: Path) -> list[str]:
        config = _ready_run(tmp)
        (tmp / "run" / "config.yaml").write_bytes(b"\xff\xfe")
        return ["sweep-w", str(config), "--run", str(tmp / "run")]

    return [
        Case("--run /", run_into("/"), "refused"),
        Case("--run .", run_into("."), "refused"),
        Case("--run ..", run_into(".."), "refused"),
        Case(
            "--run is a file",
            lambda t: (
                t.joinpath("f").write_text("x"),
                ["simulate", str(_write_config(t, BASE)), "--run", str(t / "f")],
            )[1],
            "refused",
        ),  # noqa: E501
        Case("--run a foreign non-empty directory, --force", foreign, "refused"),
        Case(
            "simulate --force keeps a user's file",
            force_keeps_user_files,
            "accepted",
            ("simulations.parquet",),
            keeps,
        ),  # noqa: E501
        Case(
            "symlinked .parts",
            symlinked_parts,
            "accepted",
            ("frontier.parquet",),
            lambda t, p: None if not any((t / "elsewhere").iterdir()) else "wrote through the symlink",
        ),  # fmt: skip
        Case("damaged .parts files", damaged_parts, "accepted", ("frontier.parquet",)),
        Case("run on a complete directory", complete_rerun, "accepted", ("thresholds.parquet",)),
        Case("hand-edited config.yaml (seeds)", edited_config_yaml, "refused"),
        Case("run config.yaml not UTF-8", run_config_non_utf8, "refused"),
        Case(
            "frontier v NaN",
            _tamper(_set_column("frontier.parquet", "v", lambda n: [float("nan")] * n)),
            "refused",
        ),  # noqa: E501
        Case(
            "frontier v strings",
            _tamper(_set_column("frontier.parquet", "v", lambda n: ["1"] * n)),
            "refused",
        ),
        Case(
            "frontier unknown model",
            _tamper(_set_column("frontier.parquet", "model", lambda n: ["ZZ"] * n)),
            "refused",
        ),  # noqa: E501
        Case(
            "frontier unknown method",
            _tamper(_set_column("frontier.parquet", "method", lambda n: ["magic"] * n)),
            "refused",
        ),  # noqa: E501
        Case(
            "frontier seed 99",
            _tamper(_set_column("frontier.parquet", "seed", lambda n: [99] * n)),
            "refused",
        ),
        Case("frontier missing", _tamper(lambda r: (r / "frontier.parquet").unlink()), "refused"),
        Case("frontier corrupt", _tamper(lambda r: (r / "frontier.parquet").write_bytes(b"x")), "refused"),
        Case(
            "report: thresholds v strings",
            _report_after(_set_column("thresholds.parquet", "w_fp", lambda n: ["a"] * n)),
            "refused",
        ),  # noqa: E501
        Case(
            "report: selection unknown model",
            _report_after(_set_column("selection.parquet", "model", lambda n: ["ZZ"] * n)),
            "refused",
        ),  # noqa: E501
        Case("report: missing run directory", lambda t: ["report", str(t / "nope")], "refused"),
        Case(
            "sweep-w: missing run directory",
            lambda t: ["sweep-w", str(_write_config(t, BASE)), "--run", str(t / "run")],
            "refused",
        ),  # noqa: E501
        Case(
            "--backend foo",
            lambda t: ["identify", str(_write_config(t, BASE)), "--run", str(t / "run"), "--backend", "foo"],
            "refused",
        ),  # noqa: E501
        Case(
            "--scheduler foo://x",
            lambda t: [
                "identify",
                str(_write_config(t, BASE)),
                "--run",
                str(t / "run"),
                "--backend",
                "dask",
                "--scheduler",
                "foo://x",
                "--worker-timeout",
                "5",
            ],
            "refused",
        ),  # noqa: E501
        Case(
            "--scheduler tcp://127.0.0.1:1 (nothing there)",
            lambda t: [
                "identify",
                str(_write_config(t, BASE)),
                "--run",
                str(t / "run"),
                "--backend",
                "dask",
                "--scheduler",
                "tcp://127.0.0.1:1",
                "--worker-timeout",
                "5",
            ],
            "refused",
        ),  # noqa: E501
        Case(
            "--method magic",
            lambda t: ["identify", str(_write_config(t, BASE)), "--run", str(t / "run"), "--method", "magic"],
            "refused",
        ),  # noqa: E501
        Case("report.md escapes the run path", _escaping_case, "accepted", ("report/report.md",), _escaped),
    ]


def _escaping_case(tmp: Path) -> list[str]:
    _ready_run(tmp)
    target = tmp / "<b>run</b>"
    shutil.move(tmp / "run", target)
    (tmp / "run").symlink_to(target)
    return ["report", str(target)]


def _escaped(tmp: Path, proc) -> str | None:
    text = (tmp / "<b>run</b>" / "report" / "report.md").read_text()
    return (
        None if "<b>run</b>" not in text and "&lt;b&gt;run&lt;/b&gt;" in text else "report.md is not escaped"
    )


# --------------------------------------------------------------------------- data cases


def _data_config(tmp: Path, **changes) -> Path:
    data = copy.deepcopy(DATA_CONFIG)
    data.update(changes)
    return _write_config(tmp, data, "d.yaml")


def _csv_case(damage):
    def setup(tmp: Path) -> list[str]:
        table = pa.csv.read_csv(EXAMPLE_CSV)
        path = damage(tmp, table)
        return ["identify", str(_data_config(tmp)), "--run", str(tmp / "run"), "--data", str(path), "--quiet",
                "--jobs", "1"]  # fmt: skip

    return setup


def _with(column: str, edit):
    def damage(tmp: Path, table: pa.Table) -> Path:
        cols = {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}
        cols[column] = edit(np.array(cols[column], dtype=object if column == "run" else float))
        path = tmp / "data.csv"
        pa.csv.write_csv(pa.table(cols), path)
        return path

    return damage


def _mat(**variables):
    def damage(tmp: Path, table: pa.Table) -> Path:
        import scipy.io

        path = tmp / "data.mat"
        scipy.io.savemat(path, variables)
        return path

    return damage


def data_cases() -> list[Case]:
    import pyarrow.csv  # noqa: F401

    mapping = DATA_CONFIG.get("data", {}).get("columns", {})
    sig = {k: mapping.get(k, k) for k in ("ft", "fd", "e", "u")}
    time_col = mapping.get("time", "t")
    n = 2048

    def put(i, value):
        def edit(x):
            x = x.copy()
            x[i] = value
            return x

        return edit

    cases = []
    for name, column in sig.items():
        cases += [
            Case(f"data {name}: NaN", _csv_case(_with(column, put(100, np.nan))), "refused"),
            Case(f"data {name}: inf", _csv_case(_with(column, put(100, np.inf))), "refused"),
            Case(f"data {name}: 1e308", _csv_case(_with(column, put(100, 1e308))), "refused"),
            Case(
                f"data {name}: column missing",
                _csv_case(lambda t, tab, c=column: _drop(t, tab, c)),
                "refused",
            ),
        ]
    rng = np.random.default_rng(0)
    good = {k: rng.standard_normal((n, 2)) * 0.01 for k in ("ft", "fd", "e", "u")}
    cases += [
        Case("data time not uniform", _csv_case(_with(time_col, put(500, 999.0))), "refused"),
        Case("data all zero", _csv_case(lambda t, tab: _zeros(t, tab)), "refused"),
        Case("data empty file", _csv_case(lambda t, tab: _raw(t, b"", "csv")), "refused"),
        Case("data header only", _csv_case(lambda t, tab: _raw(t, b"t,ft,fd,e,u\n", "csv")), "refused"),
        Case(
            "data strings", _csv_case(lambda t, tab: _raw(t, b"t,ft,fd,e,u\n0,a,b,c,d\n", "csv")), "refused"
        ),
        Case("data binary .csv", _csv_case(lambda t, tab: _raw(t, bytes(range(256)) * 10, "csv")), "refused"),
        Case("data corrupt .parquet", _csv_case(lambda t, tab: _raw(t, b"PAR1xxxx", "parquet")), "refused"),
        Case("data corrupt .mat", _csv_case(lambda t, tab: _raw(t, b"MATLAB garbage", "mat")), "refused"),
        Case("data unknown suffix", _csv_case(lambda t, tab: _raw(t, b"x", "txt")), "refused"),
        Case(
            "data missing file",
            lambda t: [
                "identify",
                str(_data_config(t)),
                "--run",
                str(t / "run"),
                "--data",
                str(t / "none.csv"),
            ],
            "refused",
        ),  # noqa: E501
        Case("data too short", _csv_case(lambda t, tab: _head(t, tab, 500)), "refused"),
        Case(
            "mat 3-D samples x runs x 1",
            _csv_case(_mat(**{sig[k]: v[:, :, None] for k, v in good.items()}, rate=25.0)),
            "accepted",
            ("frontier.parquet",),  # noqa: E501
            lambda t, p: (
                None
                if set(pq.read_table(t / "run" / "frontier.parquet").column("seed").to_pylist()) == {1, 2}
                else "runs not split"
            ),
        ),  # noqa: E501
        Case(
            "mat 3-D with 3 non-singleton dims",
            _csv_case(_mat(**{sig[k]: np.zeros((n, 2, 2)) + 0.01 for k in good}, rate=25.0)),
            "refused",
        ),  # noqa: E501
        Case(
            "mat complex values",
            _csv_case(_mat(**{sig[k]: v[:, 0] * (1 + 1j) for k, v in good.items()}, rate=25.0)),
            "refused",
        ),  # noqa: E501
        Case(
            "mat empty rate",
            _csv_case(_mat(**{sig[k]: v[:, 0] for k, v in good.items()}, rate=np.array([]))),
            "refused",
        ),  # noqa: E501
        Case(
            "mat wrong rate",
            _csv_case(_mat(**{sig[k]: v[:, 0] for k, v in good.items()}, rate=100.0)),
            "refused",
        ),
        Case(
            "mat different run counts",
            _csv_case(_mat(**{sig[k]: (v if k != "u" else v[:, :1]) for k, v in good.items()}, rate=25.0)),
            "refused",
        ),  # noqa: E501
        Case(
            "mat string variable",
            _csv_case(_mat(**{sig[k]: ("abc" if k == "e" else v[:, 0]) for k, v in good.items()}, rate=25.0)),
            "refused",
        ),  # noqa: E501
        Case(
            "data valid example",
            _csv_case(lambda t, tab: EXAMPLE_CSV),
            "accepted",
            ("frontier.parquet", "measured.parquet"),
        ),  # noqa: E501
    ]
    return cases


def _drop(tmp: Path, table: pa.Table, column: str) -> Path:
    path = tmp / "data.csv"
    pa.csv.write_csv(table.drop_columns([column]), path)
    return path


def _zeros(tmp: Path, table: pa.Table) -> Path:
    cols = {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}
    mapping = DATA_CONFIG["data"]["columns"]
    for c in cols:
        if c not in (mapping.get("time", "t"), mapping.get("run", "run")):
            cols[c] = np.zeros(len(cols[c]))
    path = tmp / "data.csv"
    pa.csv.write_csv(pa.table(cols), path)
    return path


def _head(tmp: Path, table: pa.Table, n: int) -> Path:
    path = tmp / "data.csv"
    pa.csv.write_csv(table.slice(0, n), path)
    return path


def _raw(tmp: Path, data: bytes, suffix: str) -> Path:
    path = tmp / f"data.{suffix}"
    path.write_bytes(data)
    return path


# --------------------------------------------------------------------------- issue 24: silent wrong answers


def _example_runs() -> dict[int, dict[str, np.ndarray]]:
    """The example CSV's trials as arrays, by trial."""
    import pyarrow.csv as pacsv

    table = pacsv.read_csv(EXAMPLE_CSV).to_pydict()
    trials = np.asarray(table["trial"])
    return {
        int(k): {c: np.asarray(v, dtype=float)[trials == k] for c, v in table.items()}
        for k in np.unique(trials)
    }


def _runs_csv(tmp: Path, ids: list[int], *, rate: bool) -> Path:
    """The example's trials written with the given run ids, with a rate column or the time column."""
    runs = list(_example_runs().values())
    cols: dict[str, list] = {}
    for run_id, run in zip(ids, (runs * 2)[: len(ids)], strict=True):
        n = run["time_s"].size
        block = {"trial": np.full(n, run_id)}
        block.update({"rate": np.full(n, 25.0)} if rate else {"time_s": run["time_s"]})
        block.update({c: run[c] for c in ("target", "disturbance", "error", "stick")})
        for c, v in block.items():
            cols.setdefault(c, []).append(v)
    path = tmp / "runs.csv"
    pa.csv.write_csv(pa.table({c: np.concatenate(v) for c, v in cols.items()}), path)
    return path


def _rate_data_config(tmp: Path) -> Path:
    data = copy.deepcopy(DATA_CONFIG)
    data["data"]["columns"] = {"rate": "rate", "ft": "target", "fd": "disturbance", "e": "error", "u": "stick",
                               "run": "trial"}  # fmt: skip
    return _write_config(tmp, data, "d.yaml")


def _identify_file(make, config=_data_config) -> Callable[[Path], list[str]]:
    def setup(tmp: Path) -> list[str]:
        path = make(tmp)
        return ["identify", str(config(tmp)), "--run", str(tmp / "run"), "--data", str(path), "--quiet",
                "--jobs", "1", "--method", "direct"]  # fmt: skip

    return setup


def _seeds_are(expected: set[int]):
    def check(tmp: Path, proc) -> str | None:
        seeds = set(pq.read_table(tmp / "run" / "frontier.parquet").column("seed").to_pylist())
        return None if seeds == expected else f"run ids {sorted(seeds)}, expected {sorted(expected)}"

    return check


def _forcing_file(tmp: Path, values: np.ndarray, **spec) -> dict:
    """BASE with a disturbance of kind file: column fd of dist.csv at the analysis rate."""
    path = tmp / "dist.csv"
    pa.csv.write_csv(pa.table({"fd": values}), path)
    data = copy.deepcopy(BASE)
    data["signals"]["disturbance"] = {"kind": "file", "path": str(path), "column": "fd", "rate": 25.0, **spec}
    return data


def _multisine_values(n: int = 2048) -> np.ndarray:
    ms = BASE["signals"]["disturbance"]
    t = np.arange(n) / 25.0
    wm = 2 * np.pi / ms["base_period"]
    return sum(
        a * np.sin(k * wm * t + p) for k, a, p in zip(ms["k"], ms["amplitude"], ms["phase"], strict=True)
    )


def _simulate_with(make) -> Callable[[Path], list[str]]:
    def setup(tmp: Path) -> list[str]:
        return _simulate(make(tmp))(tmp)

    return setup


def _sparse_csv(tmp: Path, size: int, header: bytes = b"") -> Path:
    path = tmp / "big.csv"
    with open(path, "wb") as f:
        f.write(header)
        f.truncate(size)
    return path


def _user_report_kept(tmp: Path, proc) -> str | None:
    mine = tmp / "run" / "report.md"
    return None if mine.read_text() == "my own notes\n" else "the user's report.md was changed"


def _report_into(prepare) -> Callable[[Path], list[str]]:
    def setup(tmp: Path) -> list[str]:
        _ready_run(tmp)
        shutil.move(tmp / "run", tmp / "study")
        out = prepare(tmp)
        return ["report", str(tmp / "study"), "--out", str(out)]

    return setup


def _lock_untouched(tmp: Path, proc) -> str | None:
    lock = tmp / "run" / ".hcid.lock"
    if not lock.is_file() or lock.read_text() != "hcid pid 1 (earlier)" or lock.stat().st_mtime_ns != 10**18:
        return "the refused command rewrote .hcid.lock"
    return None


def _refused_keeps_lock(tmp: Path) -> list[str]:
    _ready_run(tmp)
    lock = tmp / "run" / ".hcid.lock"
    lock.write_text("hcid pid 1 (earlier)")
    os.utime(lock, ns=(10**18, 10**18))
    other = _write_config(tmp, _mutated(("seeds",), [2]), "other.yaml")
    return ["identify", str(other), "--run", str(tmp / "run"), "--quiet"]


def _bom_csv(tmp: Path) -> Path:
    text = EXAMPLE_CSV.read_bytes()
    path = tmp / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf# logger v2\n# subject 01\n" + text)
    return path


def _lead_in_config(tmp: Path) -> Path:
    data = copy.deepcopy(DATA_CONFIG)
    data["data"]["lead_in"] = 200.0
    return _write_config(tmp, data, "d.yaml")


def _improper_plant(tmp: Path) -> list[str]:
    data = copy.deepcopy(BASE)
    del data["loop"]["Kc"], data["loop"]["wb"]
    data["loop"]["plant"] = {
        "kind": "tf",
        "num": [1.0],
        "den": [1.0, 2.3456789, 3.456789, 4.567891, 5.678912, 6.789123, 0.0],
    }
    return _simulate(data)(tmp)


def _short_quote(tmp: Path, proc) -> str | None:
    line = proc.stderr.strip()
    return None if "is improper" not in line or len(line) < 400 else f"message of {len(line)} characters"


def silent_answer_cases() -> list[Case]:
    data_only = {"name": "donly", "data": {"analysis_rate": 25.0, "window": 81.92,
                 "columns": {"run": "trial", "time": "time_s", "ft": "target", "fd": "disturbance", "e": "error",
                             "u": "stick"}}}  # fmt: skip

    def fit_hc_data_only(tmp: Path) -> list[str]:
        config = _write_config(tmp, data_only, "d.yaml")
        subprocess.run([*HCID, "identify", str(config), "--run", str(tmp / "run"), "--data", str(EXAMPLE_CSV),
                        "--quiet", "--jobs", "1", "--method", "direct"], check=True, capture_output=True)  # fmt: skip
        subprocess.run(
            [*HCID, "sweep-w", str(config), "--run", str(tmp / "run")], check=True, capture_output=True
        )
        return ["fit-hc", str(config), "--run", str(tmp / "run"), "--quiet", "--jobs", "1"]

    zero_fd = copy.deepcopy(BASE)
    zero_fd["signals"]["disturbance"]["amplitude"] = [0.0] * len(zero_fd["signals"]["disturbance"]["k"])
    nyquist = copy.deepcopy(BASE)
    nyquist["fit_hc"] = {"band": [0.1, 100.0]}
    return [
        # 1. a forcing file's run asked for, the run column absent
        Case("forcing file run 2 without its run column",
             _simulate_with(lambda t: _forcing_file(t, _multisine_values(), run=2)), "refused"),
        Case("forcing file run 1 without its run column",
             _simulate_with(lambda t: _forcing_file(t, _multisine_values(), run=1)), "refused"),
        # 2. a repeated run id: never merged
        Case("data run id in two blocks, rate column", _identify_file(lambda t: _runs_csv(t, [1, 2, 1], rate=True),
             _rate_data_config), "refused"),
        Case("data run id in two blocks, time column", _identify_file(lambda t: _runs_csv(t, [1, 2, 1], rate=False)),
             "refused"),
        Case("data run ids 11..13 kept", _identify_file(lambda t: _runs_csv(t, [11, 12, 13], rate=True),
             _rate_data_config), "accepted", ("frontier.parquet",), _seeds_are({11, 12, 13})),
        # 3. report output folders follow the run directory's rules
        Case("report --out a folder with a user's report.md",
             _report_into(_user_folder), "refused", check=_user_report_kept),
        Case("report --out /", _report_into(lambda t: Path("/")), "refused"),
        Case("report --out the working directory", _report_into(lambda t: t), "refused"),
        Case("report --out a file", _report_into(_user_file), "refused"),
        Case("report --out a new folder", _report_into(lambda t: t / "run"), "accepted", ("report.html",)),
        # 4. fit-hc on a data-only config
        Case("fit-hc on a data-only config", fit_hc_data_only, "refused"),
        # 5. big files refused before reading
        Case("data 2 GB sparse csv", _identify_file(lambda t: _sparse_csv(t, 2 << 30)), "refused"),
        Case("data 2 GB csv with a header",
             _identify_file(lambda t: _sparse_csv(t, 2 << 30, b"trial,time_s,target,disturbance,error,stick\n")),
             "refused"),
        Case("forcing file of 2 GB",
             _simulate_with(lambda t: (_sparse_csv(t, 2 << 30), _big_forcing(t))[1]), "refused"),
        # 6. a byte-order mark before '#' comment lines
        Case("data csv with BOM and # comments", _identify_file(_bom_csv), "accepted", ("frontier.parquet",),
             _seeds_are({1, 2, 3})),
        # 7. forcing-file values beyond the data bound
        Case("forcing file value 1e150", _simulate_with(lambda t: _forcing_file(t, _scaled(1e150))), "refused"),
        Case("forcing file value 1e200", _simulate_with(lambda t: _forcing_file(t, _scaled(1e200))), "refused"),
        # 8. an all-zero disturbance
        Case("multisine disturbance all amplitudes 0", _simulate(zero_fd), "refused"),
        Case("forcing file disturbance all zeros", _simulate_with(lambda t: _forcing_file(t, np.zeros(2048))),
             "refused"),
        Case("data fd column all zeros", _csv_case(_with("disturbance", lambda x: np.zeros_like(x))), "refused"),
        # smaller ones
        Case("cli --w abc", lambda t: ["fit-hc", str(_ready_run(t)), "--run", str(t / "run"), "--w", "abc"],
             "refused"),
        Case("cli --jobs 0", lambda t: ["simulate", str(_write_config(t, BASE)), "--run", str(t / "run"),
             "--jobs", "0"], "refused"),
        Case("cli --scheduler with --backend loky",
             lambda t: ["identify", str(_write_config(t, BASE)), "--run", str(t / "run"), "--backend", "loky",
                        "--scheduler", "tcp://127.0.0.1:1"], "refused"),
        Case("improper plant message quoted short", _improper_plant, "refused", check=_short_quote),
        Case("fit_hc.band above Nyquist", _simulate(nyquist), "refused"),
        Case("data lead-in longer than the record", _identify_file(lambda t: EXAMPLE_CSV, _lead_in_config),
             "refused", check=lambda t, p: p.stderr if re.search(r" -\d+ samples", p.stderr) else None),
        Case("refused command leaves .hcid.lock", _refused_keeps_lock, "refused", check=_lock_untouched),
        # review of the change
        Case("--run a folder holding only the user's config.yaml", _users_config_folder, "refused"),
        Case("forcing file of several trials without run", _simulate_with(_two_trials), "refused"),
        # issue 26: the estimator and its standard errors
        Case("fit-hc --target ml", lambda t: ["fit-hc", str(_ready_run(t)), "--run", str(t / "run"), "--target",
             "ml", "--quiet"], "refused"),
        Case("fit_hc.covariance hac", lambda t: _fit_hc_with(t, {"covariance": "hac"}), "refused"),
        Case("fit_hc.lag -1", lambda t: _fit_hc_with(t, {"lag": -1}), "refused"),
        Case("fit_hc.lag 1e9", lambda t: _fit_hc_with(t, {"lag": 1e9}), "refused"),
        # issue 27: a lab's data set and hcid analyse
        Case("analyse a glob matching nothing", lambda t: _analyse(t, [str(t / "*.csv")]), "refused"),
        Case("analyse a manifest naming a missing file", lambda t: _analyse(t, [_manifest_missing(t)]), "refused"),
        Case("analyse --by a factor the set lacks", lambda t: _analyse(t, [_lab_slice(t)], "--by", "session"),
             "refused"),
        Case("analyse a file whose name the pattern misses",
             lambda t: _analyse(t, [_lab_slice(t, extra="trial1_S1.csv")]), "refused"),
        Case("fit-hc --target closed_loop", lambda t: ["fit-hc", str(_ready_run(t)), "--run", str(t / "run"),
             "--target", "closed_loop", "--quiet", "--jobs", "1"], "accepted",
             ("hc_parameters.parquet", "hc_loop.parquet", "remnant_spectrum.parquet")),
    ]  # fmt: skip


LAB = ROOT / "configs" / "lab_example"


def _lab_slice(tmp: Path, extra: str | None = None) -> Path:
    """Two files of the example lab study (and one more under another name)."""
    folder = tmp / "lab"
    folder.mkdir(exist_ok=True)
    for name in ("S1_pursuit_trial1.csv", "S1_compensatory_trial1.csv"):
        shutil.copy(LAB / name, folder / name)
    if extra is not None:
        shutil.copy(LAB / "S1_pursuit_trial1.csv", folder / extra)
    return folder


def _manifest_missing(tmp: Path) -> Path:
    path = tmp / "manifest.csv"
    path.write_text("file,subject\nS9_pursuit_trial1.csv,S9\n")
    return path


def _analyse(tmp: Path, data: list, *extra: str) -> list[str]:
    args = ["analyse", str(ROOT / "configs" / "lab_example.yaml"), "--run", str(tmp / "run"), "--quiet",
            "--twins", "2", "--jobs", "1"]  # fmt: skip
    for d in data:
        args += ["--data", str(d)]
    return [*args, *extra]


def _fit_hc_with(tmp: Path, fit_hc: dict) -> list[str]:
    data = copy.deepcopy(BASE)
    data["fit_hc"] = fit_hc
    return ["fit-hc", str(_ready_run(tmp, data)), "--run", str(tmp / "run"), "--quiet", "--jobs", "1"]


def _user_folder(tmp: Path) -> Path:
    (tmp / "run").mkdir()
    (tmp / "run" / "report.md").write_text("my own notes\n")
    return tmp / "run"


def _user_file(tmp: Path) -> Path:
    (tmp / "run").mkdir()
    (tmp / "run" / "f.txt").write_text("x")
    return tmp / "run" / "f.txt"


def _users_config_folder(tmp: Path) -> list[str]:
    (tmp / "run").mkdir()
    (tmp / "run" / "config.yaml").write_text("# my own config, with my comments\n" + yaml.safe_dump(BASE))
    return ["simulate", str(tmp / "run" / "config.yaml"), "--run", str(tmp / "run"), "--quiet", "--jobs", "1"]


def _two_trials(tmp: Path) -> dict:
    values = _multisine_values()
    path = tmp / "trials.csv"
    pa.csv.write_csv(pa.table({"fd": np.concatenate([values, values]), "run": [1] * 2048 + [2] * 2048}), path)
    data = _forcing_file(tmp, values)
    data["signals"]["disturbance"]["path"] = str(path)
    return data


def _scaled(peak: float) -> np.ndarray:
    x = _multisine_values()
    return x / np.max(np.abs(x)) * peak


def _big_forcing(tmp: Path) -> dict:
    data = _forcing_file(tmp, _multisine_values())
    data["signals"]["disturbance"]["path"] = str(tmp / "big.csv")
    return data


def all_cases() -> list[Case]:
    return config_cases() + rundir_cases() + data_cases() + silent_answer_cases()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="")
    parser.add_argument("--list", action="store_true")
    parser.add_argument("--keep", action="store_true")
    parser.add_argument("--start", type=int, default=1, help="first case number (to resume a long battery)")
    args = parser.parse_args()
    cases = [c for c in all_cases() if args.only in c.name]
    if args.list:
        for c in cases:
            print(c.name)
        print(f"{len(cases)} cases")
        return 0
    ok = refused = accepted = 0
    failures = []
    start = time.perf_counter()
    for i, case in enumerate(cases, 1):
        if i < args.start:
            continue
        handled, verdict, seconds = run_case(case, args.keep)
        ok += handled
        refused += handled and verdict.startswith("refused")
        accepted += handled and verdict == "accepted"
        mark = "ok  " if handled else "FAIL"
        print(f"{i:4d} {mark} {seconds:6.1f} s  {case.name:<48.48} {verdict[:110]}", flush=True)
        if not handled:
            failures.append(case.name)
    ran = len(cases) - args.start + 1
    print(
        f"\n{ok} of {ran} cases handled ({refused} refused in one line, {accepted} accepted); "
        f"{len(failures)} not handled; {time.perf_counter() - start:.0f} s"
    )
    for name in failures:
        print(f"  not handled: {name}")
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
