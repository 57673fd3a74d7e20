"""Run tasks on a joblib pool (local processes) or a dask.distributed cluster, with a progress bar.

Results come back in task order whatever the number of workers; every task is
deterministic in its inputs, so the tables are identical for any ``jobs`` or
backend.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

from hcid.errors import HcidError

__all__ = ["BACKENDS", "check_backend", "parallel_map"]

BACKENDS = ("loky", "dask")


def check_backend(backend: str) -> None:
    """One-line error for an unknown ``--backend``, before any work starts."""
    if backend not in BACKENDS:
        raise HcidError(f"--backend: must be one of {', '.join(BACKENDS)}, got {backend!r}")


def parallel_map(
    func: Callable[..., Any],
    tasks: Sequence[tuple],
    *,
    jobs: int,
    label: str,
    show_progress: bool = True,
    backend: str = "loky",
    scheduler: str | None = None,
) -> Iterable[Any]:
    """Yield ``func(*task)`` for every task, in task order, on ``jobs`` workers.

    A progress bar on stderr counts finished tasks; ``jobs = 1`` runs
    in-process. ``backend = 'dask'`` sends the tasks to a dask.distributed
    scheduler at ``scheduler`` (``tcp://host:port``), or to a local cluster of
    ``jobs`` single-threaded worker processes when ``scheduler`` is None.
    """
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    check_backend(backend)
    if not tasks:
        return
    with contextlib.ExitStack() as stack:
        stream = _stream(func, tasks, jobs, backend, scheduler, stack)
        progress = stack.enter_context(
            Progress(
                "[progress.description]{task.description}",
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
                disable=not show_progress,
            )
        )
        bar = progress.add_task(label, total=len(tasks))
        for result in stream:
            progress.advance(bar)
            yield result


def _stream(func, tasks, jobs, backend, scheduler, stack: contextlib.ExitStack) -> Iterator:
    from joblib import Parallel, delayed, parallel_config

    if backend == "loky" and jobs == 1:
        return (func(*task) for task in tasks)
    if backend == "dask":
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:
            raise HcidError("--backend dask: needs dask.distributed (pip install 'hcid[dask]')") from exc
        if scheduler:
            try:
                client = stack.enter_context(Client(scheduler, timeout="20s"))
            except OSError as exc:
                raise HcidError(f"--scheduler: cannot reach {scheduler} ({exc})") from exc
        else:
            cluster = stack.enter_context(
                LocalCluster(
                    n_workers=jobs,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    host="127.0.0.1",
                )
            )
            client = stack.enter_context(Client(cluster))
        del client
        stack.enter_context(parallel_config(backend="dask"))
    return Parallel(n_jobs=jobs, backend=None if backend == "dask" else backend, return_as="generator")(
        delayed(func)(*task) for task in tasks
    )
