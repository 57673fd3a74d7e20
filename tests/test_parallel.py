"""The local worker pool: forked workers give loky's tables, stop with their parent, keep no lock."""

import contextlib
import fcntl
import multiprocessing
import os
import select
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from hcid import pipeline
from hcid.errors import HcidError
from hcid.pipeline import Execution, parallel, rundir

from .conftest import CI_CONFIG, ROOT

HCID = str(Path(sys.executable).parent / "hcid")
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
        pipeline.run_study(ci_config, runs[jobs], execution=Execution(jobs, progress=False))
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


def test_stopping_early_leaves_no_pool_thread_running(monkeypatch):
    # The pool's manager thread is joined when the loop is left: one still running at
    # Python's exit raced its hook on Python 3.11 (an OSError traceback after Ctrl-C, seen in CI).
    _forking(monkeypatch, True)
    before = set(threading.enumerate())
    stream = parallel.parallel_map(_nap, [(0.0,), (60.0,), (60.0,)], jobs=2, label="t", show_progress=False)
    next(stream)
    assert set(threading.enumerate()) - before  # the manager thread runs while the pool does
    stream.close()
    assert set(threading.enumerate()) - before == set()


@pytest.mark.parametrize("fork", [True, False], ids=["forked", "loky"])
def test_a_dead_worker_is_one_error_line(fork, monkeypatch):
    _forking(monkeypatch, fork)
    with pytest.raises(
        HcidError,
        match=r"^a worker process died .* with 0 of 2 tasks finished; rerun \(identify and fit-hc resume",
    ):
        list(parallel.parallel_map(_die, [(1,), (2,)], jobs=2, label="t", show_progress=False))


def test_forked_workers_keep_no_copy_of_the_run_lock(tmp_path):
    # A forked child that outlives its parent's command must not hold the run directory.
    run = tmp_path / "run"
    ready, started = os.pipe()
    with rundir.using(run):
        (run / "kept.txt").write_text("so that the directory is kept")
        child = os.fork()
        if child == 0:  # pragma: no cover (the child, once fork's hooks have run in it)
            os.write(started, b"1")
            time.sleep(5)
            os._exit(0)
        # A child that died before writing would block os.read forever: wait at most 60 s.
        assert select.select([ready], [], [], 60)[0], "the forked child never started"
        os.read(ready, 1)
    try:
        _run_dir_is_free(run)  # the parent has released it; the child must not hold it
    finally:
        os.kill(child, signal.SIGKILL)
        os.waitpid(child, 0)
        os.close(ready)
        os.close(started)


def _children(pid: int) -> list[int]:
    return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """configs/ci.yaml with the paper's grids (SPEC 3) and 8 seeds, simulated; a copy per test.
    32 tasks of about 0.3 to 0.5 s each on one core (make bench), so the workers are busy for
    seconds past the first part."""
    base = tmp_path_factory.mktemp("busy")
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["identify"] = {"target_shift": raw["identify"]["target_shift"]}
    raw["seeds"] = list(range(1, 9))
    config = base / "ci_paper_grids.yaml"
    config.write_text(yaml.safe_dump(raw))
    subprocess.run([HCID, "simulate", str(config), "--run", str(base / "run"), "--quiet"], check=True)
    return config, base / "run"


def _identify_mid_run(simulated, tmp_path):
    """`hcid identify --jobs 2` in a session of its own, once its first part is written."""
    config, simulations = simulated
    run = tmp_path / "run"
    shutil.copytree(simulations, run)
    proc = subprocess.Popen(
        [HCID, "identify", str(config), "--run", str(run), "--jobs", "2", "--quiet"],
        start_new_session=True,
        # Ctrl-C as in a terminal: a test run from a background shell (`make test &`) inherits
        # SIGINT ignored, and so would hcid (seen: exit 0 where 130 was expected).
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 240
    while not list((run / ".parts").glob("*/*.log.arrow")) and time.monotonic() < deadline:
        time.sleep(0.05)
    return proc, _children(proc.pid), run


def _run_dir_is_free(run: Path) -> None:
    with open(run / rundir.LOCK, "a+") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)  # raises if anyone holds it


def test_forked_workers_die_with_a_killed_parent(simulated, tmp_path):
    # kill -9 of hcid mid-run: its workers end with it and the run directory is free.
    proc, workers, run = _identify_mid_run(simulated, tmp_path)
    try:
        assert len(workers) == 2
        proc.kill()
        proc.communicate(timeout=60)  # workers that outlived it would hold its pipes: fail, not hang
        assert _wait_gone(workers) == []
        _run_dir_is_free(run)
    finally:
        for pid in workers:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_ctrl_c_stops_the_run_and_its_workers(simulated, tmp_path):
    # Ctrl-C in a terminal signals the whole process group: hcid stops (exit 130, as Python
    # does, nothing on stderr), the workers with it, and the run directory is free.
    proc, workers, run = _identify_mid_run(simulated, tmp_path)
    try:
        assert len(workers) == 2
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert (proc.returncode, err) == (130, "")
        assert _wait_gone(workers) == []
        _run_dir_is_free(run)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)


def test_a_failed_fork_stops_the_workers_already_forked(monkeypatch):
    # The second fork fails (EAGAIN: too many processes). The first worker, forked before
    # the pool started its manager thread, would wait for tasks forever (and the
    # interpreter's exit for it) unless the pool is stopped.
    _forking(monkeypatch, True)
    real_fork = os.fork
    forks = []

    def fork():
        forks.append(1)
        if len(forks) == 2:
            raise BlockingIOError(11, "Resource temporarily unavailable")
        return real_fork()

    monkeypatch.setattr(os, "fork", fork)
    before = {p.pid for p in multiprocessing.active_children()}
    with pytest.raises(BlockingIOError):
        list(parallel.parallel_map(_nap, [(0.0,)] * 4, jobs=2, label="t", show_progress=False))
    monkeypatch.undo()
    assert len(forks) == 2
    assert _wait_gone([p.pid for p in multiprocessing.active_children() if p.pid not in before]) == []


def _interrupt_self(_: int) -> bool:
    ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.2)  # time for a handler to run
    return ignored


def test_forked_workers_leave_ctrl_c_to_hcid(monkeypatch):
    # The parent stops its workers on Ctrl-C; a worker's own KeyboardInterrupt would only
    # race it (and print a traceback when it lands between tasks). A worker ignores SIGINT
    # (its initializer): not interrupted, the task returns.
    _forking(monkeypatch, True)
    out = list(parallel.parallel_map(_interrupt_self, [(1,), (2,)], jobs=2, label="t", show_progress=False))
    assert out == [True, True]


def test_ctrl_c_inside_a_fork_does_not_kill_the_new_worker(monkeypatch):
    # A SIGINT landing in a child before its initializer runs is swallowed there (the
    # handler the forks inherit) instead of killing the child; the parent saw none.
    _forking(monkeypatch, True)
    real_fork = os.fork

    def fork():
        pid = real_fork()
        if pid == 0:
            signal.raise_signal(signal.SIGINT)
        return pid

    monkeypatch.setattr(os, "fork", fork)
    out = list(parallel.parallel_map(_nap, [(0.0,)] * 4, jobs=2, label="t", show_progress=False))
    assert len(out) == 4


def _in_a_fresh_process(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return out.stdout.split()


_HALF_SENT = """
import gc, multiprocessing.queues, os, struct, tempfile, time
from hcid.pipeline import parallel

SENT = os.path.join(tempfile.mkdtemp(), "sent")

def task(kind):
    if kind == "quick":
        return 0
    # Half a result on the pool's result pipe: a worker killed while sending a large one.
    queue = next(o for o in gc.get_objects() if isinstance(o, multiprocessing.queues.SimpleQueue))
    os.write(queue._writer.fileno(), struct.pack("!i", 1_000_000) + b"x" * 10)
    open(SENT, "w").close()
    time.sleep(60)

tasks = [("quick",), ("half",), ("quick",)]
stream = parallel.parallel_map(task, tasks, jobs=2, label="t", show_progress=False)
next(stream)
while not os.path.exists(SENT):  # the half result is on the pipe (the suite's timeout bounds this)
    time.sleep(0.01)
time.sleep(0.2)  # and the manager thread reading the rest of it
stream.close()
print("closed")
"""


def test_stopping_early_with_a_result_half_sent_does_not_hang():
    # A reviewer's case: a worker killed while sending a large result left the pool's manager
    # thread waiting for its rest, and the join of _stop_pool for ever (in a process of its own,
    # so that a hang fails this test by its timeout instead of stopping the suite).
    out = subprocess.run([sys.executable, "-c", _HALF_SENT], capture_output=True, text=True, timeout=60)
    assert (out.returncode, out.stdout.split(), out.stderr) == (0, ["closed"], "")


def test_can_fork_only_when_no_other_thread_runs():
    # In a process of its own (this one may have threads of earlier tests, loky's among them).
    code = (
        "import threading\n"
        "from hcid.pipeline import parallel\n"
        "before = parallel._can_fork()\n"
        "stop = threading.Event()\n"
        "other = threading.Thread(target=stop.wait)\n"
        "other.start()\n"
        "during = parallel._can_fork()\n"
        "stop.set()\n"
        "other.join()\n"
        "print(before, during, parallel._can_fork())\n"
    )
    assert _in_a_fresh_process(code) == ["True", "False", "True"]


def test_can_fork_not_once_numba_threads_started():
    # numba's thread pool, once started, stays for the process.
    code = (
        "from numba import njit, prange\n"
        "from hcid.pipeline import parallel\n"
        "before = parallel._can_fork()\n"
        "@njit(parallel=True)\n"
        "def total(n):\n"
        "    s = 0.0\n"
        "    for i in prange(n):\n"
        "        s += i\n"
        "    return s\n"
        "total(100)\n"
        "print(before, parallel._can_fork())\n"
    )
    assert _in_a_fresh_process(code) == ["True", "False"]


def _blas_threads(_: int) -> list[int]:
    from threadpoolctl import threadpool_info

    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


def _blas_around_a_run(jobs: int) -> tuple[list[int], list[list[int]], list[int]]:
    """BLAS threads in this process before and after ``Execution(jobs).run`` under a caller's
    limit of 2, and in the worker of each of its 4 tasks."""
    from threadpoolctl import threadpool_info, threadpool_limits

    with threadpool_limits(2, user_api="blas"):  # a caller's BLAS with two threads
        before = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
        found = Execution(jobs, progress=False).run(_blas_threads, [(i,) for i in range(4)], "t")
        after = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
    return before, found, after


@pytest.mark.parametrize("jobs, fork", [(1, True), (2, True), (2, False)])
def test_execution_runs_blas_single_threaded_and_puts_it_back(jobs, fork, monkeypatch):
    # Issue 36: the pinning lives in Execution, for a library caller as for the CLI, in forked
    # workers and in loky's fresh ones (as if on a machine of 8 CPUs, where loky would give each
    # of 2 workers 4 threads). Source: threadpoolctl's count of each loaded BLAS's threads, in
    # the worker that ran the task.
    import json

    import joblib._parallel_backends

    if jobs > 1 and fork:
        # Forked workers in a process of its own, where forking is safe (this one may run the
        # threads of pytest-xdist or of earlier tests, and would then use loky's instead).
        code = (
            "import json\n"
            "from hcid.pipeline import parallel\n"
            "from tests.test_parallel import _blas_around_a_run\n"
            "assert parallel._can_fork()\n"
            f"print(json.dumps(_blas_around_a_run({jobs})))\n"
        )
        out = subprocess.run(
            [sys.executable, "-c", code], cwd=ROOT, check=True, capture_output=True, text=True
        )
        before, found, after = json.loads(out.stdout)
    else:
        monkeypatch.setattr(parallel, "_can_fork", lambda: fork)
        if not fork:
            monkeypatch.setattr(joblib._parallel_backends, "cpu_count", lambda *a, **k: 8)
            for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
                monkeypatch.delenv(name, raising=False)  # make test sets them; a library caller may not
        before, found, after = _blas_around_a_run(jobs)
    assert before and set(before) == {2}
    assert all(counts and set(counts) == {1} for counts in found)
    assert after == before
