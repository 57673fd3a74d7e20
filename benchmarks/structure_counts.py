"""How the code passes results between the steps of ``hcid analyse`` (issue 48), counted.

Two kinds of count, printed as one table:

- **Measured on a run** of ``hcid analyse CONFIG --data DATA`` in this process (``--jobs 1``:
  every step in this process, where the counters see it): the Parquet and Arrow tables the
  command reads back after writing them itself (a path read after this process wrote it; the
  byte comparison of an unchanged table before a write is not a read; a run log read to append
  its line is counted apart, and so is the report's reading of the tables after the analysis),
  how often the study's config file is read, how often a run directory's ``config.yaml`` is read
  (is the folder the same study? the run directory's and each twins folder's), and how often a
  config is parsed (``describe_config``: the study's, and each twins folder's config built from it).
- **Read from the source** with ``ast`` (``hcid/pipeline``, ``hcid/api.py``, ``hcid/report``):
  positional accesses into results (a subscript by an integer or a bool literal: ``x[0]``,
  ``fits[True]``; arrays' own indexing is among them, so the count is an upper bound and its
  change is the figure), and functions taking a bag of phase state (both a ``study`` and a
  ``found`` parameter).

usage: python benchmarks/structure_counts.py [CONFIG DATA] [--twins N] [--max-fb-twins N]
       (default: configs/lab_example.yaml on two subjects' first two trials, 4 twins, 12 FB;
       ``PYTHONPATH=CHECKOUT`` counts another checkout's code, an older one's too)
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


def static_counts(root: Path | None = None) -> dict[str, int]:
    """Positional subscripts and ``(study, found)`` functions in :data:`SOURCES` of ``root`` (default:
    the checkout whose ``hcid`` is imported, ``PYTHONPATH``'s where given)."""
    if root is None:
        import hcid

        root = Path(hcid.__file__).resolve().parents[1]
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


def _patch_everywhere(name: str, wrap) -> None:
    """Replace the function ``name`` of hcid's modules wherever a module holds it (a module that
    imported it by name holds its own reference), by ``wrap(original)``."""
    import sys

    originals = {}
    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("hcid") and callable(getattr(module, name, None)):
            original = getattr(module, name)
            if original not in originals:
                originals[original] = wrap(original)
            setattr(module, name, originals[original])


def run_counts(config: str, data: list[str], twins: int, most_fb: int) -> dict[str, int]:
    """Run ``hcid analyse`` here, as a user would (no ``--run``: the default run directory, in a
    temporary working folder), with the readers and writers counted."""
    import contextlib
    import importlib
    import os
    from collections import Counter

    import pyarrow.parquet as pq

    import hcid.report
    from hcid.cli import app
    from hcid.io import results

    for name in ("hcid.assembly.resolve", "hcid.io.resolve", "hcid.report.run", "hcid.pipeline.twins"):
        with contextlib.suppress(ImportError):  # this checkout's, or an older one's modules
            importlib.import_module(name)

    study_file = Path(config).resolve()
    written: set[str] = set()
    counts = {
        "tables read back by the analysis": 0,
        "run logs read to append a line": 0,
        "tables read back by its report": 0,
        "study config file reads": 0,
        "run directories' config.yaml reads": 0,
        "configs parsed": 0,
    }
    read_back: list[str] = []
    phase = ["analysis"]
    yamls: list[str] = []

    def counted_read(original):
        def read(where, *args, **kwargs):
            key = str(Path(str(where)))
            if key in written and phase[0] == "analysis" and Path(key).name == "run_log.parquet":
                counts["run logs read to append a line"] += 1
            elif key in written:
                counts[f"tables read back by {'its report' if phase[0] == 'report' else 'the analysis'}"] += 1
                read_back.append(f"{Path(key).name} ({phase[0]})")
            return original(where, *args, **kwargs)

        return read

    def counted(name):
        def wrap(original):
            def call(*args, **kwargs):
                if name == "YAML":
                    file = Path(str(args[0]))
                    study = file.resolve() == study_file
                    counts["study config file reads" if study else "run directories' config.yaml reads"] += 1
                    yamls.append(f"{file.name} ({phase[0]})")
                else:
                    counts[name] += 1
                return original(*args, **kwargs)

            return call

        return wrap

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

    _patch_everywhere("atomic_write", atomic)
    pq.read_table = counted_read(pq.read_table)
    _patch_everywhere("read_part_table", counted_read)
    _patch_everywhere("read_yaml", counted("YAML"))
    _patch_everywhere("describe_config", counted("configs parsed"))
    hcid.report.build_report = reporting(hcid.report.build_report)
    del results

    here = Path.cwd()
    work = Path(tempfile.mkdtemp(prefix="hcid-counts-"))
    args = ["analyse", str(Path(config).resolve()), "--twins", str(twins), "--max-fb-twins", str(most_fb)]
    args += ["--jobs", "1", "--quiet"]
    for d in data:
        args += ["--data", str(Path(d).resolve())]
    os.chdir(work)  # the default run directory, runs/<name>, lands here
    try:
        app(args, standalone_mode=False)
    finally:
        os.chdir(here)
        shutil.rmtree(work, ignore_errors=True)
    print("read back:", ", ".join(f"{k} x{n}" for k, n in sorted(Counter(read_back).items())) or "none")
    print("YAML read:", ", ".join(f"{k} x{n}" for k, n in sorted(Counter(yamls).items())))
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="configs/lab_example.yaml")
    parser.add_argument("data", nargs="*")
    parser.add_argument("--twins", type=int, default=4)
    parser.add_argument("--max-fb-twins", type=int, default=12)
    parser.add_argument("--smoke", action="store_true", help="the default run (already small); for make test")
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
