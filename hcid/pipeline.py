"""Batch runs over models x seeds on a joblib pool, with a progress bar.

Each task is one realization; results come back in task order whatever the
number of workers, and every task is deterministic in its seed, so the tables
are identical for any ``jobs``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa

from hcid import results
from hcid.config import Config
from hcid.simulate import remnant_gain, simulate_realization

__all__ = ["SimulationRun", "parallel_map", "simulate_study"]


def parallel_map(
    func: Callable[..., Any],
    tasks: Sequence[tuple],
    *,
    jobs: int,
    label: str,
    show_progress: bool = True,
    backend: str = "loky",
) -> Iterable[Any]:
    """Yield ``func(*task)`` for every task, in task order, on ``jobs`` workers.

    A progress bar on stderr counts finished tasks; ``jobs = 1`` runs in-process.
    """
    from joblib import Parallel, delayed
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

    if jobs == 1 and backend == "loky":
        stream = (func(*task) for task in tasks)
    else:
        stream = Parallel(n_jobs=jobs, backend=backend, return_as="generator")(
            delayed(func)(*task) for task in tasks
        )
    with Progress(
        "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
        TimeElapsedColumn(), TimeRemainingColumn(), disable=not show_progress, transient=False,
    ) as progress:
        bar = progress.add_task(label, total=len(tasks))
        for result in stream:
            progress.advance(bar)
            yield result


def _simulate_task(config: Config, model_name: str, seed: int, kn: float):
    model = config.model(model_name)
    return (
        simulate_realization(config, model, seed, kn),
        simulate_realization(config, model, seed, kn, disturbance_only=True),
    )


@dataclass(frozen=True)
class SimulationRun:
    """Tables of one simulation run and where they were written."""

    simulations: pa.Table
    summary: pa.Table
    kn: float
    run_dir: Path


def simulate_study(
    config: Config, run_dir: Path, *, jobs: int = 2, show_progress: bool = True
) -> SimulationRun:
    """Simulate every model x seed of ``config`` and write the run's tables.

    Writes ``config.yaml``, ``simulations.parquet`` and
    ``simulation_summary.parquet`` in ``run_dir``, each atomically.
    """
    kn = remnant_gain(config)
    tasks = [(config, m.name, seed, kn) for m in config.models for seed in config.seeds]
    pairs = list(parallel_map(_simulate_task, tasks, jobs=jobs, label="simulate",
                              show_progress=show_progress))
    realizations = [p[0] for p in pairs]
    simulations = results.realizations_table(realizations)
    summary = results.summary_table(realizations, [p[1] for p in pairs])
    results.write_text(config.to_yaml(), run_dir / "config.yaml")
    results.write_table(simulations, run_dir / results.SIMULATIONS)
    results.write_table(summary, run_dir / results.SIMULATION_SUMMARY)
    return SimulationRun(simulations=simulations, summary=summary, kn=kn, run_dir=run_dir)
