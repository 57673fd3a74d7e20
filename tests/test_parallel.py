"""The local worker pool: forked workers give loky's tables, stop with their parent, keep no lock."""

import fcntl
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from hcid import pipeline
from hcid.errors import HcidError
from hcid.pipeline import parallel, rundir

from .conftest import CI_CONFIG

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="workers are forked on Linux only")


def _nap(seconds: float) -> int:
    time.sleep(seconds)
    return os.getpid()


def _die(_: int) -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _forking(monkeypatch, fork: bool) -> list:
    """Force the fork (or loky) path; the returned list counts the forked pools started."""
    started = []
    real = parallel._forked_stream

    def spy(*args):
        started.append(1)
        return real(*args)

    monkeypatch.setattr(parallel, "_can_fork", lambda: fork)
    monkeypatch.setattr(parallel, "_forked_stream", spy)
    return started


@pytest.mark.parametrize("fork", [True, False], ids=["forked", "loky"])
def test_local_pool_gives_the_in_process_tables(fork, tmp_path, monkeypatch, ci_config):
    # The same tasks in this process (jobs 1) and on two workers, forked or loky's:
    # byte-identical tables (every task is deterministic in its inputs).
    runs = {}
    for jobs in (1, 2):
        started = _forking(monkeypatch, fork)
        runs[jobs] = tmp_path / f"jobs{jobs}"
        pipeline.run_study(ci_config, runs[jobs], jobs=jobs, show_progress=False)
        assert len(started) == (2 if fork and jobs == 2 else 0)  # simulate and identify
    for name in ("simulations", "frontier", "stage1", "selection", "thresholds"):
        assert (runs[1] / f"{name}.parquet").read_bytes() == (runs[2] / f"{name}.parquet").read_bytes()


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")  # a zombie has ended


def _wait_gone(pids, seconds: float = 10.0) -> list[int]:
    deadline = time.monotonic() + seconds
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [p for p in pids if _alive(p)]


def test_stopping_early_kills_the_forked_workers(monkeypatch):
    # The first task returns at once, the others would sleep a minute: leaving the loop
    # (an error or Ctrl-C in the caller) must end the workers, not wait for their tasks.
    _forking(monkeypatch, True)
    before = {p.pid for p in multiprocessing.active_children()}  # e.g. loky's idle workers
    stream = parallel.parallel_map(
        _nap, [(0.0,), (60.0,), (60.0,), (60.0,)], jobs=2, label="t", show_progress=False
    )
    worker = next(stream)
    children = [p.pid for p in multiprocessing.active_children() if p.pid not in before]
    assert worker in children and len(children) == 2
    start = time.monotonic()
    stream.close()  # what a KeyboardInterrupt in the caller's loop does
    assert _wait_gone(children) == [] and time.monotonic() - start < 10


def test_a_dead_worker_is_one_error_line(monkeypatch):
    _forking(monkeypatch, True)
    with pytest.raises(
        HcidError, match=r"^a worker process died .*; 0 of 2 tasks are kept; rerun to resume$"
    ):
        list(parallel.parallel_map(_die, [(1,), (2,)], jobs=2, label="t", show_progress=False))


def test_forked_workers_keep_no_copy_of_the_run_lock(tmp_path):
    # A forked child that outlives its parent's command must not hold the run directory.
    run = tmp_path / "run"
    ready, started = os.pipe()  # closed with the test process
    with rundir.using(run):
        (run / "kept.txt").write_text("so that the directory is kept")
        child = os.fork()
        if child == 0:  # pragma: no cover (the child, once fork's hooks have run in it)
            os.write(started, b"1")
            time.sleep(5)
            os._exit(0)
        os.read(ready, 1)
    try:
        with open(run / rundir.LOCK, "a+") as handle:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)  # raises if the child holds it
    finally:
        os.kill(child, signal.SIGKILL)
        os.waitpid(child, 0)


def _children(pid: int) -> list[int]:
    return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def test_forked_workers_die_with_a_killed_parent(tmp_path):
    # `hcid identify --jobs 2` killed with -9 mid-run: its workers end with it and the run
    # directory is free. The paper's grids (SPEC 3: ~1.4 s a task on one core, 12 tasks)
    # keep the workers busy well past the first part.
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["identify"] = {"target_shift": raw["identify"]["target_shift"]}
    config = tmp_path / "ci_paper_grids.yaml"
    config.write_text(yaml.safe_dump(raw))
    run = tmp_path / "run"
    hcid = str(Path(sys.executable).parent / "hcid")
    subprocess.run(
        [hcid, "simulate", str(config), "--run", str(run), "--quiet"], check=True, capture_output=True
    )
    proc = subprocess.Popen([hcid, "identify", str(config), "--run", str(run), "--jobs", "2", "--quiet"])
    try:
        deadline = time.monotonic() + 240
        while not list((run / ".parts").glob("*/*.log.arrow")) and time.monotonic() < deadline:
            time.sleep(0.1)
        workers = _children(proc.pid)
        assert len(workers) == 2
    finally:
        proc.kill()
        proc.wait()
    assert _wait_gone(workers) == []
    with open(run / rundir.LOCK, "a+") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    shutil.rmtree(run)
