"""Two commands on one run directory at once (issue 10): one proceeds, one is refused, tables intact.

Usage: python tests/robustness/concurrency.py [--trials 10]. For each trial and each of
`identify` and `run`, two processes start together on one directory (with the
simulations in place); exactly one must exit 0 and the other exit 2 with one line
naming the holder, and the tables must equal those of an uninterrupted run.
Then dask on loopback with 2 workers: the identify log must show both workers.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyarrow.parquet as pq
import yaml

ROOT = Path(__file__).resolve().parents[2]
HCID = str(Path(sys.executable).parent / "hcid")
TABLES = ("frontier", "stage1", "selection", "breakpoints", "thresholds")


def _content(run: Path) -> dict:
    """The tables' bytes (hcid's writes are deterministic; Table.equals would call NaN unequal)."""
    return {t: (run / f"{t}.parquet").read_bytes() for t in TABLES if (run / f"{t}.parquet").exists()}


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--trials", type=int, default=10)
    args = parser.parse_args()
    base = Path(tempfile.mkdtemp(prefix="hcid-concurrency-"))
    raw = yaml.safe_load((ROOT / "configs" / "ci.yaml").read_text())
    config = base / "ci.yaml"
    config.write_text(yaml.safe_dump(raw))
    reference = base / "reference"
    subprocess.run(
        [HCID, "run", str(config), "--run", str(reference), "--quiet"], check=True, capture_output=True
    )
    expected = _content(reference)
    failures = 0
    for command in ("identify", "run"):
        for trial in range(1, args.trials + 1):
            run = base / f"{command}{trial}"
            run.mkdir()
            for name in ("simulations.parquet", "simulation_summary.parquet", "config.yaml", "hcid-run.json"):
                shutil.copy(reference / name, run / name)
            argv = [HCID, command, str(config), "--run", str(run), "--quiet"]
            procs = [
                subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                for _ in range(2)
            ]
            outs = [p.communicate(timeout=600) for p in procs]
            codes = sorted(p.returncode for p in procs)
            refused = [o[1].strip() for p, o in zip(procs, outs, strict=True) if p.returncode == 2]
            one_line = all(len(r.splitlines()) == 1 and "in use by hcid pid" in r for r in refused)
            if command == "identify":  # identify alone leaves the sweep to a later command
                subprocess.run(
                    [HCID, "sweep-w", str(config), "--run", str(run)], check=True, capture_output=True
                )
            same = _content(run) == expected
            ok = codes == [0, 2] and one_line and same
            failures += not ok
            print(f"{command:<8} trial {trial:2d}: exit codes {codes}, refusal one line naming the holder: "
                  f"{one_line}, tables equal an uninterrupted run's: {same} -> {'ok' if ok else 'FAIL'}", flush=True)  # fmt: skip
    # dask on loopback, two single-threaded workers
    from dask.distributed import LocalCluster

    run = base / "dask"
    run.mkdir()
    for name in ("simulations.parquet", "simulation_summary.parquet", "config.yaml", "hcid-run.json"):
        shutil.copy(reference / name, run / name)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      host="127.0.0.1") as cluster:  # fmt: skip
        start = time.perf_counter()
        subprocess.run([HCID, "identify", str(config), "--run", str(run), "--backend", "dask", "--scheduler",
                        cluster.scheduler_address, "--quiet"], check=True, capture_output=True)  # fmt: skip
        seconds = time.perf_counter() - start
    workers = pq.read_table(run / "identify_log.parquet").column("worker").to_pylist()
    counts = {w: workers.count(w) for w in sorted(set(workers))}
    same = (run / "frontier.parquet").read_bytes() == expected["frontier"]
    dask_ok = len(counts) == 2 and same
    failures += not dask_ok
    print(f"dask loopback, 2 workers: tasks per worker {counts}, frontier equal: {same}, {seconds:.0f} s "
          f"-> {'ok' if dask_ok else 'FAIL'}")  # fmt: skip
    shutil.rmtree(base, ignore_errors=True)
    print(f"{failures} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
