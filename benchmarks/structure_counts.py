"""How the code passes results between the steps of ``hcid analyse`` (issue 48), counted.

Two kinds of count, printed as one table:

- **Measured on a run** of ``hcid analyse CONFIG --data DATA`` in this process (``--jobs 1``:
  every step in this process, where the counters see it): the Parquet and Arrow tables the
  command reads back after writing them itself (a path read after this process wrote it; the
  byte comparison of an unchanged table before a write is not a read; a run log read to append
  its line is counted apart, and so is the report's reading of the tables after the analysis),
  and how often a YAML file is read and a config parsed (``read_yaml``, ``describe_config``:
  the study's, and each twins folder's config built from it).
- **Read from the source** with ``ast`` (``hcid/pipeline``, ``hcid/api.py``, ``hcid/report``):
  positional accesses into results (a subscript by an integer or a bool literal: ``x[0]``,
  ``fits[True]``; arrays' own indexing is among them, so the count is an upper bound and its
  change is the figure), and functions taking a bag of phase state (both a ``study`` and a
  ``found`` parameter).

usage: python benchmarks/structure_counts.py [CONFIG DATA] [--twins N] [--max-fb-twins N]
       (default: configs/lab_example.yaml on two subjects' first two trials, 4 twins, 12 FB)
"""

from __future__ import annotations

import argparse
import ast
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("hcid/pipeline", "hcid/api.py", "hcid/report")


def static_counts(root: Path = ROOT) -> dict[str, int]:
    """Positional subscripts and ``(study, found)`` functions in :data:`SOURCES`."""
    positional = bags = 0
    for source in SOURCES:
        base = root / source
        for path in [base] if base.is_file() else sorted(base.rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
                    value = node.slice.value
                    positional += isinstance(value, bool | int)
                elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    names = {a.arg for a in node.args.args + node.args.kwonlyargs}
                    bags += {"study", "found"} <= names
    return {"positional accesses (x[0], x[True])": positional, "functions taking (study, found)": bags}


def run_counts(config: str, data: list[str], twins: int, most_fb: int) -> dict[str, int]:
    """Run ``hcid analyse`` here, with the readers and writers counted."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    import hcid.report
    from hcid.assembly import resolve
    from hcid.cli import app
    from hcid.config import parse
    from hcid.io import results

    written: set[str] = set()
    counts = {
        "tables read back by the analysis": 0,
        "run logs read to append a line": 0,
        "tables read back by its report": 0,
        "YAML files read": 0,
        "configs parsed": 0,
    }
    read_back: list[str] = []
    phase = ["analysis"]
    yamls: list[str] = []

    def counted_write(original):
        def write(table, where, *args, **kwargs):
            written.add(str(Path(str(where))).removesuffix(".tmp"))
            return original(table, where, *args, **kwargs)

        return write

    def counted_read(original, counter=None):
        def read(where, *args, **kwargs):
            key = str(Path(str(where)))
            if key in written and phase[0] == "analysis" and Path(key).name == "run_log.parquet":
                counts["run logs read to append a line"] += 1
            elif key in written:
                counts[f"tables read back by {'its report' if phase[0] == 'report' else 'the analysis'}"] += 1
                read_back.append(f"{Path(key).name} ({phase[0]})")
            return original(where, *args, **kwargs)

        return read

    def counted(original, name):
        def call(*args, **kwargs):
            counts[name] += 1
            if name == "YAML files read":
                yamls.append(Path(str(args[0])).name)
            return original(*args, **kwargs)

        return call

    def reporting(original):
        def call(*args, **kwargs):
            phase[0] = "report"
            return original(*args, **kwargs)

        return call

    def atomic(original):
        def write(path, writer, *args, **kwargs):
            written.add(str(Path(path)))
            return original(path, writer, *args, **kwargs)

        return write

    results.atomic_write = atomic(results.atomic_write)
    pq.read_table = counted_read(pq.read_table)
    original_ipc = results.read_part_table
    results.read_part_table = counted_read(original_ipc)
    resolve.read_yaml = counted(resolve.read_yaml, "YAML files read")
    parse.describe_config = counted(parse.describe_config, "configs parsed")
    resolve.describe_config = parse.describe_config
    hcid.report.build_report = reporting(hcid.report.build_report)
    del pa

    run = Path(tempfile.mkdtemp(prefix="hcid-counts-")) / "run"
    args = ["analyse", config, "--run", str(run), "--twins", str(twins), "--max-fb-twins", str(most_fb)]
    args += ["--jobs", "1", "--quiet"]
    for d in data:
        args += ["--data", d]
    try:
        app(args, standalone_mode=False)
    finally:
        shutil.rmtree(run.parent, ignore_errors=True)
    from collections import Counter

    print("read back:", ", ".join(f"{k} x{n}" for k, n in sorted(Counter(read_back).items())) or "none")
    print("YAML read:", ", ".join(yamls))
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="configs/lab_example.yaml")
    parser.add_argument("data", nargs="*")
    parser.add_argument("--twins", type=int, default=4)
    parser.add_argument("--max-fb-twins", type=int, default=12)
    args = parser.parse_args()
    data = args.data
    slice_dir = None
    if not data:  # two subjects' first two trials of the lab example
        slice_dir = Path(tempfile.mkdtemp(prefix="hcid-slice-"))
        for f in sorted((ROOT / "configs/lab_example").glob("S[12]_*_trial[12].csv")):
            shutil.copy(f, slice_dir)
        data = [str(slice_dir)]
    counts = static_counts()
    try:
        counts |= run_counts(args.config, data, args.twins, args.max_fb_twins)
    finally:
        if slice_dir is not None:
            shutil.rmtree(slice_dir, ignore_errors=True)
    width = max(map(len, counts))
    for name, n in counts.items():
        print(f"{name:<{width}}  {n}")


if __name__ == "__main__":
    sys.exit(main())
