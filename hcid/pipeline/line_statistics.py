"""The evidence statistics read from a record's forcing lines (SPEC 11, issue 47), of the runs and
of their twins: the model-free feedforward size (:func:`hcid.hcfit.lines.feedforward_size`) and
the likelihood ratio of the parametric fits with and without the feedforward path
(:func:`hcid.hcfit.lr.feedforward_lr`), both fitted from the run's group model. A run and every
twin it is judged against get the same start, so their statistics are made alike."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from hcid import tables
from hcid.config import Config, Loop
from hcid.config.fit_settings import FEEDFORWARD_PARAMETERS, FitSettings
from hcid.errors import DataError
from hcid.hcfit.closed_loop import loop_is_stable
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
    runs = sorted(starts)
    tasks = [
        (
            records[r],
            configs[r].timing.output_rate,
            configs[r].loop,
            dict(starts[r]),
            configs[r].fit_hc or FitSettings(),
        )
        for r in runs
    ]
    return dict(zip(runs, execution.map(record_statistics, tasks, "line statistics"), strict=True))


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
    group's medians. ``offsets`` are the group's runs' deviations (:func:`deviations`): twin ``k``
    (the FB and the FF twin of seed ``k`` alike) starts at ``start`` minus deviation
    ``(k - 1) mod len(offsets)``, away from its truth as a run is from its own (nearer where that
    start's loop would be unstable: :func:`_offset`)."""
    return twin_statistics_of([(folder, config, start, offsets, None)], execution)[0]


def twin_statistics_of(
    folders: Sequence[tuple[Path, Config, Mapping[str, float], Sequence[Mapping[str, float]], dict | None]],
    execution: Execution,
) -> list[dict[str, dict[str, np.ndarray]]]:
    """:func:`twin_statistics` of every ``(folder, config, start, offsets, simulations)``, in one
    pool; ``simulations``: the folder's records by (model, seed) where the caller holds them (made
    by this command), else None (read from the folder)."""
    keys, tasks = [], []
    for folder, config, start, offsets, records in folders:
        path = folder / tables.SIMULATIONS.file
        if records is None:
            records = results.records(results.read(tables.SIMULATIONS, folder), path)
        else:
            results.check_records(records, path)
        keys.append(sorted(records))
        polynomials = np.array(config.loop.plant.num), np.array(config.loop.plant.den)
        settings = config.fit_hc or FitSettings()
        starts = {
            seed: _offset(start, offsets, seed, *polynomials, settings) for seed in {k[1] for k in keys[-1]}
        }
        tasks += [
            (records[k], config.timing.output_rate, config.loop, starts[k[1]], settings) for k in keys[-1]
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


#: A twin's start whose loop is unstable is moved towards its truth by halving its offset at most
#: this many times, then the truth itself (:func:`_offset`).
_HALVINGS = 8


def _offset(
    start: Mapping[str, float],
    offsets: Sequence[Mapping[str, float]],
    seed: int,
    num_c: np.ndarray,
    den_c: np.ndarray,
    settings: FitSettings = FitSettings(),  # noqa: B008 (frozen)
) -> dict:
    """Twin ``seed``'s start: ``start`` minus deviation ``(seed - 1) mod len(offsets)``, that
    deviation halved (at most :data:`_HALVINGS` times, then ``start`` itself) until the start, as
    the fits take it (clipped into ``settings``' bounds), makes a stable loop with the plant
    (``num_c``, ``den_c``).

    A run's fits start at its group's model, a stable loop (:func:`hcid.hcfit.determined.group_model`
    takes no other), and so must a twin's: from an unstable loop the lines' cost is flat (no
    slope), neither fit moves and the likelihood ratio is 0 whatever the record holds
    (docs/methodology.md, "A third statistic")."""
    if not offsets:
        return dict(start)
    deviation = offsets[(int(seed) - 1) % len(offsets)]
    for _ in range(_HALVINGS + 1):
        moved = {p: v - deviation.get(p, 0.0) for p, v in start.items()}
        if loop_is_stable(_clipped(moved, settings), num_c, den_c):
            return moved
        deviation = {p: d / 2.0 for p, d in deviation.items()}
    return dict(start)


def _clipped(values: Mapping[str, float], settings: FitSettings) -> dict[str, float]:
    """``values`` clipped into ``settings``' bounds, as :func:`hcid.hcfit.lr.feedforward_lr`'s fits
    start."""
    return {p: min(max(v, settings.bound(p).lower), settings.bound(p).upper) for p, v in values.items()}


def deviations(model: Mapping[str, float], fits: Sequence) -> list[dict[str, float]]:
    """How far each twin's fits start from its truth, in the order of ``fits`` (the group's runs'
    :class:`hcid.hcfit.fit.HCFit`): the offsets of :func:`twin_statistics`.

    A run's fits start at the group model, away from the run's truth by the run's true deviation
    from the group; its fitted deviation (fitted value minus the group model's) is that plus the
    fit's own error. A twin's fitted optimum already carries a fit error of its own, so a twin
    started at its truth minus a run's *fitted* deviation would start further away than the run
    (by the fit error twice over), and under feedback-only truth the runs' likelihood ratios sat
    above their twins' (null study, 2026-11-28: KS p 1e-13 with these offsets unshrunk; 0.63
    with none, but conservative at 0.05, 3.3%). Each parameter's deviations are therefore shrunk
    towards 0 by ``sqrt(max(0, 1 - mean(se^2) / mean(deviation^2)))`` over the runs that determine
    it: what is left estimates the spread of the true deviations (the fitted spread minus the fit
    error's, from the runs' own standard errors).

    Only the feedback parameters the run's fit determines (status ``determined``; a flagged value,
    outside its plausible range or not told from 0, gets none: the null study that measured this
    rule took them so, and a value not told from 0 is mostly its fit error) get an offset
    (:data:`hcid.hcfit.determined.DETERMINED`; along an undetermined direction the cost is flat);
    the feedforward path's start is the group model's for runs and twins alike (under the null
    their feedforward truth is the same: none)."""
    raw = [
        {
            p: (float(fit.values[p] - v), float(fit.se[fit.names.index(p)]))
            for p, v in model.items()
            if p not in FEEDFORWARD_PARAMETERS
            and p in fit.names
            and fit.status.get(p) == DETERMINED
            and np.isfinite(fit.values[p] - v)
        }
        for fit in fits
    ]
    shrink = {}
    for p in model:
        pairs = np.array([r[p] for r in raw if p in r], dtype=float).reshape(-1, 2)
        spread = float(np.mean(pairs[:, 0] ** 2)) if len(pairs) else 0.0
        se = pairs[np.isfinite(pairs[:, 1]), 1]
        error = float(np.mean(se**2)) if se.size else 0.0
        shrink[p] = math.sqrt(max(0.0, 1.0 - error / spread)) if spread > 0 else 0.0
    return [{p: r[p][0] * shrink[p] if p in r else 0.0 for p in model} for r in raw]
