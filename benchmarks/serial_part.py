"""The serial part of a study (issue 36) or of ``hcid analyse`` (issue 47): wall time outside the
worker pool, measured.

Runs ``hcid run CONFIG`` (default configs/paper.yaml) in a fresh process with ``--jobs 1`` and
``--jobs 2`` into fresh run directories, side by side, and splits each command's wall time
into the time inside the worker pool (:func:`hcid.pipeline.parallel.parallel_map`: the pool at
work, the main process collecting and storing results) and the rest (imports, config,
simulation set-up, writing the tables, the W sweep): that rest does not shrink with more
workers. ``PYTHONPATH=CHECKOUT`` measures another checkout's code the same way. Amdahl's fit of the two walls,
S = 2 T2 - T1, is printed beside it. The machine (CPU, load) is printed first.

``--analyse DATA`` runs ``hcid analyse CONFIG --data DATA`` instead (with ``--twins``,
``--max-fb-twins`` and ``--by`` passed on) and names where the serial part lies: per phase of
:func:`hcid.pipeline.analyse.analyse_study` (identify, fit runs, twins, line statistics and more
FB twins, fit selected, tables, and the data's reading and the report around them) its wall
time, the time inside the pool and the rest.

usage: python benchmarks/serial_part.py [CONFIG] [--repeat N] [--analyse DATA [--twins N]
       [--max-fb-twins N] [--by F]] [--smoke]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from cold_start import _cpu  # the machine, named as every benchmark names it

CHILD = r"""
import importlib, json, sys, time
t0 = time.perf_counter()
spans = []


def timed(original):
    def parallel_map(func, tasks, **kwargs):
        start = time.perf_counter()
        try:
            yield from original(func, tasks, **kwargs)
        finally:
            spans.append((kwargs.get("label", "?"), time.perf_counter() - start, start))
    return parallel_map


# Every module that calls the pool by name (this code's Execution, or an older checkout's stages).
# fit-hc's module only where the code imported it already: importing it here would add
# python-control's import to a run that does not need it.
# (hcid.pipeline.fit: an older checkout's name of fit_hc.)
fit_modules = ("hcid.pipeline.fit_hc", "hcid.pipeline.fit")
for name in ("hcid.pipeline.execution", "hcid.pipeline.studies", *fit_modules):
    try:
        module = sys.modules.get(name) or (name not in fit_modules and importlib.import_module(name))
    except ImportError:
        continue
    if module and hasattr(module, "parallel_map"):
        module.parallel_map = timed(module.parallel_map)
phases = []
if sys.argv[4] == "analyse":  # each phase of analyse_study, timed from the outside
    import hcid.pipeline.analyse as analyse

    def phase(name, original):
        def timed_phase(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                phases.append((name, start, time.perf_counter()))
        return timed_phase

    # An older checkout's names too (_twins, _more_fb_twins: before analyse_twins.py).
    for name, function in (("identify", "identify_study"), ("fit runs", "_fit_runs"), ("twins", "make_twins"),
                           ("twins", "_twins"), ("line statistics", "run_statistics"),
                           ("more FB twins", "more_fb_twins"), ("more FB twins", "_more_fb_twins"),
                           ("fit selected", "_select_and_fit"), ("tables", "write_tables"),
                           ("tables", "build_tables"), ("tables", "write_analysis")):
        if hasattr(analyse, function):
            setattr(analyse, function, phase(name, getattr(analyse, function)))
    analyse.read_study = phase("read the data", analyse.read_study)
    import hcid.report

    hcid.report.build_report = phase("report", hcid.report.build_report)
from hcid.cli import main
command = ["run", sys.argv[1]] if sys.argv[4] == "run" else ["analyse", sys.argv[1], *json.loads(sys.argv[5])]
sys.argv = ["hcid", *command, "--run", sys.argv[2], "--jobs", sys.argv[3], "--quiet"]
try:
    main()
except SystemExit:
    pass
total = time.perf_counter() - t0
print("SPANS " + json.dumps({"total": total, "spans": spans, "phases": phases}))
"""


def run(config: str, jobs: int, analyse: list[str] | None = None) -> dict:
    import json

    folder = Path(tempfile.mkdtemp(prefix="hcid-serial-"))
    try:
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
        kind = ["run"] if analyse is None else ["analyse", json.dumps(analyse)]
        out = subprocess.run(
            [sys.executable, "-c", CHILD, config, str(folder / "run"), str(jobs), *kind],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        ).stdout
        line = next(x for x in out.splitlines() if x.startswith("SPANS "))
        return json.loads(line[6:])
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def phase_lines(found: dict) -> list[str]:
    """Per phase: its wall, the pool's time within it and the rest (the serial part)."""
    lines, merged = [], []
    for name, start, stop in found["phases"]:  # one span from a phase's first function to its last
        if merged and merged[-1][0] == name:  # (tables: build_tables, then write_analysis)
            merged[-1][2] = stop
        else:
            merged.append([name, start, stop])
    for name, start, stop in merged:
        inside = sum(
            min(stop, s0 + span) - max(start, s0)
            for _, span, s0 in found["spans"]
            if s0 < stop and s0 + span > start
        )
        wall = stop - start
        lines.append(
            f"    {name}: wall {wall:.1f} s, in the pool {inside:.1f} s, outside {wall - inside:.1f} s"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="configs/paper.yaml")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument(
        "--analyse", metavar="DATA", help="hcid analyse CONFIG --data DATA instead of hcid run"
    )
    parser.add_argument("--twins", type=int, default=None)
    parser.add_argument("--max-fb-twins", type=int, default=None)
    parser.add_argument("--by", default=None)
    parser.add_argument(
        "--smoke", action="store_true", help="hcid analyse of 4 lab-example runs, 4 + 8 twins"
    )
    args = parser.parse_args()
    if args.smoke:
        folder = Path(tempfile.mkdtemp(prefix="hcid-serial-data-"))
        root = Path(__file__).resolve().parents[1]
        for f in sorted((root / "configs" / "lab_example").glob("S1_*_trial[12].csv")):
            shutil.copy(f, folder)
        config = str(root / "configs" / "lab_example.yaml")
        args.config, args.analyse, args.twins, args.max_fb_twins = config, str(folder), 4, 8
    analyse = None
    if args.analyse:
        analyse = ["--data", args.analyse]
        for flag, value in (
            ("--twins", args.twins),
            ("--max-fb-twins", args.max_fb_twins),
            ("--by", args.by),
        ):
            analyse += [flag, str(value)] if value is not None else []
    print(f"machine: {_cpu()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    walls = {}
    for _ in range(args.repeat):
        for jobs in (1, 2):
            found = run(args.config, jobs, analyse)
            inside = sum(s for _, s, _ in found["spans"])
            walls.setdefault(jobs, []).append(found["total"])
            labels = {}
            for label, span, _ in found["spans"]:
                labels[label] = labels.get(label, 0.0) + span
            print(
                f"--jobs {jobs}: wall {found['total']:.1f} s, in the pool {inside:.1f} s "
                f"({', '.join(f'{label} {s:.1f}' for label, s in labels.items())}), "
                f"outside it {found['total'] - inside:.1f} s"
            )
            print("\n".join(phase_lines(found)))
    t1, t2 = min(walls[1]), min(walls[2])
    print(f"Amdahl from the two walls (fastest of {args.repeat}): serial S = 2 T2 - T1 = {2 * t2 - t1:.1f} s")
    print(f"done {time.strftime('%Y-%m-%d %H:%M')}")


if __name__ == "__main__":
    main()
