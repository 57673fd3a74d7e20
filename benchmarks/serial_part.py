"""The serial part of a study (issue 36): wall time outside the worker pool, measured.

Runs ``hcid run CONFIG`` (default configs/paper.yaml) in a fresh process with ``--jobs 1`` and
``--jobs 2`` into fresh run directories, side by side, and splits each command's wall time
into the time inside the worker pool (:func:`hcid.pipeline.parallel.parallel_map`: the pool at
work, the main process collecting and storing results) and the rest (imports, config,
simulation set-up, writing the tables, the W sweep): that rest does not shrink with more
workers. ``PYTHONPATH=CHECKOUT`` measures another checkout's code the same way. Amdahl's fit of the two walls,
S = 2 T2 - T1, is printed beside it. The machine (CPU, load) is printed first.

usage: python benchmarks/serial_part.py [CONFIG] [--repeat N]
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
            spans.append((kwargs.get("label", "?"), time.perf_counter() - start))
    return parallel_map


# Every module that calls the pool by name (this code's Execution, or an older checkout's stages).
# fit-hc's module only where the code imported it already: importing it here would add
# python-control's import to a run that does not need it.
for name in ("hcid.pipeline.execution", "hcid.pipeline.studies", "hcid.pipeline.fit"):
    try:
        module = sys.modules.get(name) or (name != "hcid.pipeline.fit" and importlib.import_module(name))
    except ImportError:
        continue
    if module and hasattr(module, "parallel_map"):
        module.parallel_map = timed(module.parallel_map)
from hcid.cli import main
sys.argv = ["hcid", "run", sys.argv[1], "--run", sys.argv[2], "--jobs", sys.argv[3], "--quiet"]
try:
    main()
except SystemExit:
    pass
total = time.perf_counter() - t0
print("SPANS " + json.dumps({"total": total, "spans": spans}))
"""


def run(config: str, jobs: int) -> dict:
    import json

    folder = Path(tempfile.mkdtemp(prefix="hcid-serial-"))
    try:
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
        out = subprocess.run(
            [sys.executable, "-c", CHILD, config, str(folder / "run"), str(jobs)],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        ).stdout
        line = next(x for x in out.splitlines() if x.startswith("SPANS "))
        return json.loads(line[6:])
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="configs/paper.yaml")
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    print(f"machine: {_cpu()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    walls = {}
    for _ in range(args.repeat):
        for jobs in (1, 2):
            found = run(args.config, jobs)
            inside = sum(s for _, s in found["spans"])
            walls.setdefault(jobs, []).append(found["total"])
            print(
                f"--jobs {jobs}: wall {found['total']:.1f} s, in the pool {inside:.1f} s "
                f"({', '.join(f'{label} {s:.1f}' for label, s in found['spans'])}), "
                f"outside it {found['total'] - inside:.1f} s"
            )
    t1, t2 = min(walls[1]), min(walls[2])
    print(f"Amdahl from the two walls (fastest of {args.repeat}): serial S = 2 T2 - T1 = {2 * t2 - t1:.1f} s")
    print(f"done {time.strftime('%Y-%m-%d %H:%M')}")


if __name__ == "__main__":
    main()
