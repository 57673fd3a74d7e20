"""The evidence statistics read from a record's forcing lines (SPEC 11, issue 47), of the runs and
of their twins: the model-free feedforward size (:func:`hcid.hcfit.lines.feedforward_size`) and
the likelihood ratio of the parametric fits with and without the feedforward path
(:func:`hcid.hcfit.lr.feedforward_lr`), both fitted from the run's group model. A run and every
twin it is judged against get the same start, so their statistics are made alike."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from hcid import tables
from hcid.config import Config, Loop
from hcid.config.fit import FitSettings
from hcid.errors import DataError
from hcid.hcfit.lines import feedforward_size, record_lines
from hcid.hcfit.lr import feedforward_lr
from hcid.io import results
from hcid.loop.hcmodel import plant
from hcid.pipeline.execution import Execution

__all__ = ["LINE_STATISTICS", "record_statistics", "run_statistics", "twin_statistics"]

#: The statistics of a record's lines, by name in the tables: (value column, columns' stem, as in
#: ``p_<stem>``, ``p_<stem>_method``, ``power_<stem>``, ``fb_twins_<stem>``).
LINE_STATISTICS = {
    "Fourier coefficients": ("fourier_size", "fourier"),
    "likelihood ratio": ("likelihood_ratio", "lr"),
}


def record_statistics(
    signals: Mapping[str, np.ndarray],
    rate: float,
    loop: Loop,
    start: Mapping[str, float],
    settings: FitSettings = FitSettings(),  # noqa: B008 (frozen)
) -> dict[str, float] | None:
    """Each statistic of :data:`LINE_STATISTICS` of one record (``ft``, ``fd``, ``e``, ``u`` at
    ``rate`` Hz; the parameters' bounds of ``settings``, the config's ``fit_hc``); None where its
    forcing functions have no lines."""
    try:
        data = record_lines(signals, rate)
    except DataError:
        return None
    return {
        "Fourier coefficients": feedforward_size(data),
        "likelihood ratio": feedforward_lr(data, plant(loop), loop.disturbance_at, start, settings),
    }


def run_statistics(
    records: Mapping[int, Mapping[str, np.ndarray]],
    configs: Mapping[int, Config],
    starts: Mapping[int, Mapping[str, float]],
    execution: Execution,
) -> dict[int, dict[str, float] | None]:
    """:func:`record_statistics` of every run (``configs``: each run's, with its own plant;
    ``starts``: each run's group model), by run."""
    seeds = sorted(starts)
    tasks = [(records[s], configs[s].timing.output_rate, configs[s].loop, dict(starts[s])) for s in seeds]
    return dict(zip(seeds, execution.map(record_statistics, tasks, "line statistics"), strict=True))


def twin_statistics(
    folder: Path, config: Config, start: Mapping[str, float], execution: Execution
) -> dict[str, dict[str, np.ndarray]]:
    """:func:`record_statistics` of every twin realization in a twin folder: model (``FB``,
    ``FF``) -> statistic -> values in seed order; empty where the forcing has no lines."""
    records = results.records(results.read(tables.SIMULATIONS, folder), folder / tables.SIMULATIONS.file)
    keys = sorted(records)
    tasks = [(records[k], config.timing.output_rate, config.loop, dict(start), config.fit_hc) for k in keys]
    found = list(execution.map(record_statistics, tasks, "twins' line statistics"))
    if any(f is None for f in found):
        return {}
    out: dict[str, dict[str, list[float]]] = {}
    for (model, _), values in zip(keys, found, strict=True):
        for name, value in values.items():
            out.setdefault(model, {}).setdefault(name, []).append(value)
    return {m: {n: np.array(v) for n, v in by.items()} for m, by in out.items()}
