"""The evidence statistics read from a record's forcing lines (SPEC 11, issue 47), of the runs and
of their twins: the model-free feedforward size (:func:`hcid.hcfit.lines.feedforward_size`) and
the likelihood ratio of the parametric fits with and without the feedforward path
(:func:`hcid.hcfit.lr.feedforward_lr`), both fitted from the run's group model. A run and every
twin it is judged against get the same start, so their statistics are made alike."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from hcid import tables
from hcid.config import Config, Loop
from hcid.config.fit import FEEDFORWARD_PARAMETERS, FitSettings
from hcid.errors import DataError
from hcid.hcfit.determined import DETERMINED
from hcid.hcfit.lines import feedforward_size, record_lines
from hcid.hcfit.lr import feedforward_lr
from hcid.io import results
from hcid.loop.hcmodel import plant
from hcid.pipeline.execution import Execution

__all__ = [
    "LINE_STATISTICS",
    "deviations",
    "record_statistics",
    "run_statistics",
    "twin_statistics",
    "twin_statistics_of",
]

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
    folder: Path,
    config: Config,
    start: Mapping[str, float],
    execution: Execution,
    offsets: Sequence[Mapping[str, float]] = (),
) -> dict[str, dict[str, np.ndarray]]:
    """:func:`record_statistics` of every twin realization in a twin folder: model (``FB``,
    ``FF``) -> statistic -> values in seed order; empty where the forcing has no lines.

    A twin is simulated from ``start`` (the group's model), so fits started there would start at
    its truth, where a run's start lies away from its own optimum by the run's deviation from its
    group's medians. ``offsets`` are the group's runs' deviations (each run's fitted values minus
    the group model's): twin ``k`` (the FB and the FF twin of seed ``k`` alike) starts at ``start``
    minus deviation ``(k - 1) mod len(offsets)``, away from its truth as a run is from its own."""
    return twin_statistics_of([(folder, config, start, offsets)], execution)[0]


def twin_statistics_of(
    folders: Sequence[tuple[Path, Config, Mapping[str, float], Sequence[Mapping[str, float]]]],
    execution: Execution,
) -> list[dict[str, dict[str, np.ndarray]]]:
    """:func:`twin_statistics` of every ``(folder, config, start, offsets)``, in one pool."""
    keys, tasks = [], []
    for folder, config, start, offsets in folders:
        table = results.read(tables.SIMULATIONS, folder)
        records = results.records(table, folder / tables.SIMULATIONS.file)
        keys.append(sorted(records))
        tasks += [
            (records[k], config.timing.output_rate, config.loop, _offset(start, offsets, k[1]), config.fit_hc)
            for k in keys[-1]
        ]
    found = list(execution.map(record_statistics, tasks, "twins' line statistics")) if tasks else []
    out, first = [], 0
    for mine in keys:
        values_of, first = found[first : first + len(mine)], first + len(mine)
        if any(f is None for f in values_of):
            out.append({})
            continue
        by_model: dict[str, dict[str, list[float]]] = {}
        for (model, _), values in zip(mine, values_of, strict=True):
            for name, value in values.items():
                by_model.setdefault(model, {}).setdefault(name, []).append(value)
        out.append({m: {n: np.array(v) for n, v in by.items()} for m, by in by_model.items()})
    return out


def _offset(start: Mapping[str, float], offsets: Sequence[Mapping[str, float]], seed: int) -> dict:
    if not offsets:
        return dict(start)
    deviation = offsets[(int(seed) - 1) % len(offsets)]
    return {p: v - deviation.get(p, 0.0) for p, v in start.items()}


def deviations(model: Mapping[str, float], fits: Sequence) -> list[dict[str, float]]:
    """Each run's fitted values minus the group model's, over the feedback parameters its fit
    determines (:data:`hcid.hcfit.determined.DETERMINED`; 0 for the others: along an undetermined
    direction the cost is flat, and a run's optimum there says nothing of how far its start is),
    in the order given (``fits``: the runs' :class:`hcid.hcfit.fit.HCFit`): the offsets of
    :func:`twin_statistics`.

    The feedforward path's parameters get no offset: a run's feedforward fit starts at the group
    model's Kpt, TI and tau_pt, and so does every twin's. Under the null the FB twin's and the
    run's feedforward truth is the same (none), so equal starts are what makes them alike; an
    offset there pushed half the twins' Kpt starts onto its bound at 0 (a run's fitted Kpt above
    the group's median), whose fits then more often stayed at the nested model, and the runs'
    ratios sat above their twins' (null study, 2026-11-28: KS p 1e-15, p-values between 0.1 and 0.4
    too many, above 0.7 too few)."""
    out = []
    for fit in fits:
        values, status = fit.values, fit.status
        out.append(
            {
                p: float(values[p] - v)
                if p not in FEEDFORWARD_PARAMETERS
                and status.get(p) == DETERMINED
                and np.isfinite(values.get(p, np.nan) - v)
                else 0.0
                for p, v in model.items()
            }
        )
    return out
