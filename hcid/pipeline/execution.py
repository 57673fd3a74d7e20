"""How work runs: one :class:`Execution` for every command and pipeline function.

It holds the worker pool's settings (``--jobs``, ``--backend``, ``--scheduler``,
``--worker-timeout``) and whether progress bars show (``--quiet``), and it keeps BLAS
single-threaded while it runs work (:meth:`Execution.pinned`): one level of parallelism,
the worker processes, and the same tables whatever ``jobs`` (forked workers inherit the
limit; two workers each running a BLAS pool of their own are also five times slower).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from hcid.errors import HcidError
from hcid.pipeline.parallel import check_backend, check_scheduler, parallel_map

__all__ = ["Execution"]


@dataclass(frozen=True)
class Execution:
    """Where and how a command's tasks run.

    ``jobs`` worker processes (1: in this process); ``backend`` ``loky`` (local workers,
    forked on Linux) or ``dask`` (``scheduler`` a ``tcp://host:port`` address, or None for a
    local cluster; a cluster without workers for ``worker_timeout`` seconds ends the run);
    ``progress`` shows a progress bar on stderr per stage.

    >>> Execution(jobs=1, progress=False).jobs
    1
    >>> Execution(jobs=0)
    Traceback (most recent call last):
    ...
    hcid.errors.HcidError: jobs (--jobs): must be an integer >= 1, got 0
    """

    jobs: int = 2
    backend: str = "loky"
    scheduler: str | None = None
    worker_timeout: float = 60.0
    progress: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.jobs, bool) or not isinstance(self.jobs, int) or self.jobs < 1:
            raise HcidError(f"jobs (--jobs): must be an integer >= 1, got {self.jobs!r}")
        if not self.worker_timeout > 0:
            raise HcidError(
                "worker_timeout (--worker-timeout): must be a positive number of seconds, "
                f"got {self.worker_timeout!r}"
            )
        check_backend(self.backend, self.scheduler)

    def check(self) -> None:
        """Refuse, before any work, a dask scheduler that cannot be reached or has no worker."""
        check_scheduler(self.backend, self.scheduler, self.worker_timeout)

    def map(self, func: Callable[..., Any], tasks: Sequence[tuple], label: str) -> Iterator[Any]:
        """``func(*task)`` for every task, in task order, on this execution's workers, BLAS
        single-threaded (:func:`hcid.pipeline.parallel.parallel_map`)."""
        with self.pinned():
            yield from parallel_map(
                func,
                tasks,
                jobs=self.jobs,
                label=label,
                show_progress=self.progress,
                backend=self.backend,
                scheduler=self.scheduler,
                worker_timeout=self.worker_timeout,
            )

    def run(self, func: Callable[..., Any], tasks: Sequence[tuple], label: str) -> list[Any]:
        """Every result of :meth:`map`, as a list."""
        return list(self.map(func, tasks, label))

    @staticmethod
    @contextlib.contextmanager
    def pinned() -> Iterator[None]:
        """BLAS (OpenBLAS, MKL, BLIS) limited to one thread inside, in this process and the
        workers it forks; the limits before are restored after (threadpoolctl)."""
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            yield
