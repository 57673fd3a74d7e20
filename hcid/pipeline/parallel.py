"""Run tasks on local worker processes or a dask.distributed cluster, with a progress bar.

Results come back in task order whatever the number of workers; every task is
deterministic in its inputs, so the tables are identical for any ``jobs`` or
backend.

The local backend (named ``loky``, for the pool it uses where forking is not
safe) forks its workers from this process on Linux when only this thread runs
Python and numba's thread pool has not started (:func:`_can_fork`). They then
start with every module and compiled kernel already loaded: about 3 s a
command on this machine that loky's fresh interpreters spend importing scipy,
python-control and numba. Elsewhere it uses joblib's loky pool.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from hcid.errors import HcidError

__all__ = ["BACKENDS", "check_backend", "check_scheduler", "compile_before_fork", "labelled", "parallel_map"]

BACKENDS = ("loky", "dask")

#: What every progress bar started inside :func:`labelled` says first (whose work it is).
_LABEL = contextvars.ContextVar("hcid_progress_label", default="")


@contextlib.contextmanager
def labelled(prefix: str):
    """Progress bars started inside say ``prefix`` before their own label (e.g. the twins of
    one group: ``twins condition=pursuit: identify``)."""
    token = _LABEL.set(_LABEL.get() + prefix)
    try:
        yield
    finally:
        _LABEL.reset(token)


def check_backend(backend: str, scheduler: str | None = None) -> None:
    """One-line error for an unknown ``--backend``, or a scheduler given to a backend without one."""
    if backend not in BACKENDS:
        raise HcidError(f"backend (--backend): must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if scheduler is not None and backend != "dask":
        raise HcidError(f"scheduler (--scheduler): only with backend dask (got {backend}); drop one of them")


def parallel_map(
    func: Callable[..., Any],
    tasks: Sequence[tuple],
    *,
    jobs: int,
    label: str,
    show_progress: bool = True,
    backend: str = "loky",
    scheduler: str | None = None,
    worker_timeout: float = 60.0,
) -> Iterable[Any]:
    """Yield ``func(*task)`` for every task, in task order, on ``jobs`` workers.

    A progress bar on stderr counts finished tasks; ``jobs = 1`` with loky runs
    in-process. ``backend = 'dask'`` submits the tasks to a dask.distributed
    scheduler at ``scheduler`` (``tcp://host:port``), or to a local cluster of
    ``jobs`` single-threaded worker processes when ``scheduler`` is None; the
    tasks always run on the cluster's workers, never in this process. A cluster
    without workers for ``worker_timeout`` seconds (none joined, or all lost)
    ends the run with one line, and so does a local worker that dies; the
    caller keeps the finished tasks if it can (identify and fit-hc do).

    A library caller that leaves the loop early should close the generator
    (``contextlib.closing``): that stops the workers; an abandoned one lets
    them finish every task first.
    """
    check_backend(backend)
    if not tasks:
        return
    finished = 0
    with contextlib.ExitStack() as stack:
        try:
            if backend == "dask":
                stream = _dask_stream(func, tasks, jobs, scheduler, worker_timeout, stack)
            else:
                stream = _local_stream(func, tasks, jobs, stack)
            advance = _progress_bar(stack, _LABEL.get() + label, len(tasks)) if show_progress else None
            for result in stream:
                if advance is not None:
                    advance()
                finished += 1
                yield result
        except BrokenProcessPool:  # loky's TerminatedWorkerError is one too
            raise HcidError(
                f"a worker process died (killed, or out of memory?) with {finished} of {len(tasks)} "
                "tasks finished; rerun (identify and fit-hc resume from the finished ones)"
            ) from None


def _progress_bar(stack: contextlib.ExitStack, label: str, total: int) -> Callable[[], None]:
    """A rich progress bar on stderr, open until ``stack`` closes; returns its advance step.
    (rich is imported here: a quiet run does without its 0.1 s import.)"""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

    progress = stack.enter_context(
        Progress(
            "[progress.description]{task.description}",
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
        )
    )
    bar = progress.add_task(label, total=total)
    return lambda: progress.advance(bar)


_compiled = False


def compile_before_fork() -> None:
    """The identification engine's kernels compiled, or loaded from numba's cache, in this
    process before it forks its workers, so that they start with them instead of each
    compiling its own. The two parts of :data:`hcid.arx.engine.KERNEL_PARTS` compile at once:
    the ``rest`` in a forked child that writes them to the cache (a worker's safeguards: it
    leaves Ctrl-C to this process and dies with it), the ``vector`` steps here; then this
    process loads the child's from the cache (on a warm cache both only load). Where forking
    is not safe (:func:`_can_fork`) or fails, one part after the other, here. Once per process.
    """
    global _compiled
    from hcid.arx.engine import KERNEL_PARTS
    from hcid.arx.engine import compile_kernels as compile_part

    if _compiled:
        return
    vector, rest = KERNEL_PARTS
    child = _fork_compiler(compile_part, rest) if _can_fork() else 0
    try:
        compile_part(vector)
    except BaseException:
        if child:
            os.kill(child, signal.SIGKILL)
        raise
    finally:
        if child:
            os.waitpid(child, 0)  # its part is in the cache now (or, if it failed, compiled below)
    compile_part(rest)
    _compiled = True


def _fork_compiler(compile_part: Callable[[str], None], part: str) -> int:
    """A forked child that compiles ``part`` and exits without any cleanup; its pid, or 0 if
    the fork failed (the caller then compiles it itself)."""
    parent = os.getpid()
    sys.stdout.flush()
    sys.stderr.flush()
    with _ctrl_c_deferred(), warnings.catch_warnings():
        warnings.filterwarnings("ignore", r"This process .* is multi-threaded", DeprecationWarning)
        try:
            child = os.fork()
        except OSError:
            return 0
        if child == 0:  # the child never leaves this block (a Ctrl-C deferred here is dropped)
            code = 1
            try:
                _forked_worker_start(parent)
                compile_part(part)
                code = 0
            finally:
                os._exit(code)
    return child


def _local_stream(func, tasks, jobs, stack: contextlib.ExitStack) -> Iterator:
    if jobs == 1:
        return (func(*task) for task in tasks)
    if _can_fork():
        return _forked_stream(func, tasks, jobs, stack)
    from joblib import Parallel, delayed, parallel_config

    # loky's fresh workers: BLAS and OpenMP single-threaded, as forked ones inherit it.
    with parallel_config(backend="loky", inner_max_num_threads=1):
        return Parallel(n_jobs=jobs, return_as="generator")(delayed(func)(*task) for task in tasks)


def _can_fork() -> bool:
    """Whether forking this process is safe: Linux, called from the main thread with no other
    Python thread running, and numba's thread pool (OpenMP, TBB or workqueue) not started.

    A Python thread other than the forking one could hold a lock the child then
    waits for forever; a forked child cannot use a started numba thread pool,
    which only library calls with ``threads > 1`` start (studies run
    ``threads = 1``). Threads of C libraries (pyarrow's pool, jemalloc's
    background thread) are running too: those libraries reset their state in a
    forked child themselves.
    """
    if sys.platform != "linux" or threading.active_count() > 1:
        return False
    if threading.current_thread() is not threading.main_thread():
        return False  # signal handlers are the main thread's; PDEATHSIG fires when the forking thread ends
    numba = sys.modules.get("numba")
    if numba is not None:
        try:
            numba.threading_layer()
            return False  # a parallel kernel (threads > 1) has run in this process
        except ValueError:
            pass  # not started
    return True


def _forked_stream(func, tasks, jobs, stack: contextlib.ExitStack) -> Iterator:
    """Every task submitted at once to ``jobs`` forked workers; results in task order.

    CPython forks every worker of a fork-context pool at the first submit, so
    here, before the progress bar starts its thread. If the caller stops early
    (an error, Ctrl-C) the workers are killed at once, their running tasks
    abandoned (loky does the same).
    """
    import concurrent.futures
    import multiprocessing

    pool = concurrent.futures.ProcessPoolExecutor(
        min(jobs, len(tasks)),
        mp_context=multiprocessing.get_context("fork"),
        initializer=_forked_worker_start,
        initargs=(os.getpid(),),
    )
    futures: list = []
    stack.callback(_stop_pool, pool, futures, len(tasks))  # first: a failed fork stops the others
    with _ctrl_c_deferred(), warnings.catch_warnings():
        # Python 3.12+ warns that C libraries' threads run at the fork (see _can_fork).
        warnings.filterwarnings("ignore", r"This process .* is multi-threaded", DeprecationWarning)
        futures.extend(pool.submit(func, *task) for task in tasks)
    return (future.result() for future in futures)


@contextlib.contextmanager
def _ctrl_c_deferred():
    """Ctrl-C during the forks is raised in this process after them, and swallowed in a child.

    Otherwise a SIGINT inside fork() lands in an at-fork hook (which drops it)
    or in a child before its initializer ignores SIGINT, where the
    KeyboardInterrupt unwinds the parent's stack as cloned (the worker dies).
    A handler installed outside Python cannot be put back, so is left alone.
    """
    previous = signal.getsignal(signal.SIGINT)
    if previous is None:
        yield
        return
    received = []
    signal.signal(signal.SIGINT, lambda *_: received.append(1))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        signal.raise_signal(signal.SIGINT)


def _stop_pool(pool, futures, n_tasks: int) -> None:
    """Stop the pool, killing its workers first unless every task has finished.

    Always waits for the pool's manager thread, which ends as soon as it sees the killed workers
    (or the end of a result one of them was sending): left running, it can close its wake-up pipe
    while Python's exit hook writes to it (Python 3.11's race, fixed in 3.12), which printed an
    OSError traceback after a Ctrl-C.
    """
    finished = len(futures) == n_tasks and all(f.done() and not f.cancelled() for f in futures)
    if not finished:
        # ProcessPoolExecutor.kill_workers() arrives in Python 3.14; until then, its processes.
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.kill()
        # A worker killed while sending a result leaves the manager thread reading the rest of it;
        # with this process's copy of the pipe's write end closed too, it reads an end instead.
        writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
        if writer is not None:
            writer.close()
    pool.shutdown(wait=True, cancel_futures=True)


def _forked_worker_start(parent: int) -> None:
    """A forked worker leaves Ctrl-C to its parent, and dies with it (even by kill -9)."""
    import ctypes

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    pr_set_pdeathsig = 1
    # Refused only under a seccomp filter: the worker then works, but outlives a parent killed -9.
    ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL)
    if os.getppid() != parent:  # the parent died before prctl
        os._exit(1)


def check_scheduler(backend: str, scheduler: str | None, timeout: float = 60.0) -> None:
    """Refuse, before any work, a dask scheduler that cannot be reached or has no worker."""
    check_backend(backend, scheduler)
    if backend == "dask" and scheduler is not None:
        with contextlib.ExitStack() as stack:
            _client(scheduler, 1, timeout, stack)


def _client(scheduler: str | None, jobs: int, timeout: float, stack: contextlib.ExitStack):
    import logging

    # A lost worker makes distributed log tracebacks of its own; hcid reports the loss in one line.
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:
        raise HcidError("--backend dask: needs dask.distributed (pip install 'hcid[dask]')") from exc
    for name in [*logging.root.manager.loggerDict, "asyncio"]:
        if name.split(".")[0] in ("asyncio", "distributed", "tornado"):
            logging.getLogger(name).setLevel(logging.CRITICAL)
    if scheduler is None:
        cluster = stack.enter_context(
            LocalCluster(
                n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None, host="127.0.0.1"
            )
        )
        return stack.enter_context(Client(cluster))
    try:
        client = stack.enter_context(Client(scheduler, timeout=f"{min(timeout, 20.0):g}s"))
    except Exception as exc:  # noqa: BLE001 (OSError, ValueError, TypeError, TimeoutError by address)
        reason = str(exc).splitlines()[0][:80] if str(exc) else type(exc).__name__
        raise HcidError(f"scheduler (--scheduler): cannot use {scheduler[:80]!r} ({reason})") from None
    try:
        client.wait_for_workers(1, timeout=timeout)
    except Exception:  # noqa: BLE001 (dask raises TimeoutError of asyncio or builtins)
        raise HcidError(f"--scheduler {scheduler[:80]}: no worker joined within {timeout:g} s") from None
    return client


def _dask_stream(func, tasks, jobs, scheduler, timeout: float, stack: contextlib.ExitStack) -> Iterator:
    from dask.distributed import wait

    client = _client(scheduler, jobs, timeout, stack)
    futures = [client.submit(func, *task, pure=False) for task in tasks]
    stack.callback(client.cancel, futures)
    order = {f.key: i for i, f in enumerate(futures)}
    finished: dict[int, Any] = {}
    remaining = set(futures)
    following = 0
    no_workers_since = None
    while following < len(futures):
        if remaining:
            try:
                done, _ = wait(list(remaining), timeout=2.0, return_when="FIRST_COMPLETED")
            except Exception:  # noqa: BLE001 (a timeout of this poll: nothing finished)
                done = set()
            for future in done:
                # Fetch now: a result left on a worker is lost with it. A task's own error is
                # raised; a result whose worker died meanwhile is waited for again.
                try:
                    finished[order[future.key]] = future.result(timeout=timeout)
                    remaining.discard(future)
                except TimeoutError:
                    done = set()
            if not done:
                n_workers = len(client.nthreads())  # asks the scheduler now (scheduler_info is cached)
                now = time.monotonic()
                if n_workers:
                    no_workers_since = None
                elif no_workers_since is None:
                    no_workers_since = now
                elif now - no_workers_since > timeout:
                    raise HcidError(
                        f"dask: no worker for {timeout:g} s (all lost?); {following} of "
                        f"{len(futures)} tasks are kept; rerun to resume"
                    )
        while following in finished:
            yield finished.pop(following)
            following += 1
