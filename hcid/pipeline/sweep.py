"""``hcid sweep-w``: the selection of every record and method over the W grid, and its thresholds.

Reads ``frontier.parquet``; writes ``selection.parquet`` (the model selected at every W),
``breakpoints.parquet`` (the exact selection intervals), ``thresholds.parquet`` (W_FP,
W_FN with their sampling uncertainty, each criterion's W) and ``rates.parquet``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pyarrow as pa

from hcid import methods, tables
from hcid.config import Config, paper
from hcid.errors import DataError, IdentificationError
from hcid.io import results
from hcid.pipeline.rundir import check_run_dir, holds_run_dir, record_config
from hcid.selection import calibration, criteria, over_w
from hcid.selection.frontier import Frontier

__all__ = ["SweepRun", "selections", "sweep_study"]


@dataclass(frozen=True)
class SweepRun:
    """Selections over the W grid, exact breakpoints, and thresholds."""

    selection: pa.Table
    breakpoints: pa.Table
    thresholds: pa.Table
    criteria: tuple[criteria.Criterion, ...]
    run_dir: Path
    rates: pa.Table | None = None


@holds_run_dir(create=False)
def sweep_study(
    config: Config, run_dir: Path, frontiers: dict[tuple[str, int, str], Frontier] | None = None
) -> SweepRun:
    """Select by ``MSC = log V + W d`` for every realization, method and W of the grid.

    Writes ``selection.parquet`` (one row per model, seed, method and W),
    ``breakpoints.parquet`` (the exact intervals of W over which each
    selection holds), ``thresholds.parquet`` (each configured criterion's W,
    W_FP and W_FN per method and model with their sampling uncertainty, and
    the error rate at each criterion's W, computed from the breakpoints) and
    ``rates.parquet`` (the false-positive rate of a model without feedforward,
    the false-negative rate of one with it, over the W grid with exact 95% bands).
    ``frontiers`` are the run's by (model, seed, method) where the caller holds them
    (``run_study``, which has just made them); otherwise they are read from ``run_dir``.
    """
    check_run_dir(config, run_dir, "select")
    if frontiers is None:  # given by a caller that has just made them (run_study): not read again
        frontier = results.read(tables.FRONTIER, run_dir, hint="run `hcid identify` first")
        results.check_against_config(frontier, config, run_dir / tables.FRONTIER.file)
        frontiers = results.frontiers(frontier)
    w = np.asarray(config.selection.w_grid)
    sel_parts, bp_parts = [], []
    segments: dict[tuple[str, str], list] = {}
    nb_ft: dict[tuple[str, str], list] = {}
    for (model, seed, method), (seg, frontier) in selections(frontiers, run_dir).items():
        segments.setdefault((model, method), []).append(seg)
        nb_ft.setdefault((model, method), []).append(frontier.nb_ft)
        sel_parts.append(_rows_table(model, seed, method, {"w": w}, frontier, seg.at(w)))
        bp_parts.append(
            _rows_table(model, seed, method, {"w_from": seg.w_from, "w_to": seg.w_to}, frontier, seg.index)
        )
    selection_table = results.concat(sel_parts)
    breakpoints_table = results.concat(bp_parts)
    chosen = criteria.configured(config.selection.criteria)
    thresholds = _thresholds(config, chosen, segments, nb_ft)
    rates = _rates(config, segments, nb_ft, w)
    record_config(config, run_dir)
    results.write(tables.SELECTION, selection_table, run_dir)
    results.write(tables.BREAKPOINTS, breakpoints_table, run_dir)
    results.write(tables.thresholds([c.column for c in chosen]), thresholds, run_dir)
    results.write(tables.RATES, rates, run_dir)
    return SweepRun(selection_table, breakpoints_table, thresholds, chosen, run_dir, rates)


class RealizationSelection(NamedTuple):
    """A realization's selection over W and its frontier."""

    path: over_w.SelectionPath
    frontier: Frontier


def selections(
    frontiers: dict[tuple[str, int, str], Frontier], run_dir: Path
) -> dict[tuple[str, int, str], RealizationSelection]:
    """Per realization and method (model, seed, method): its selection over W and its frontier."""
    path = run_dir / tables.FRONTIER.file
    out = {}
    for (model, seed, method), frontier in frontiers.items():
        try:
            out[(model, seed, method)] = RealizationSelection(frontier.path(), frontier)
        except IdentificationError as exc:
            raise DataError(f"{path}: model {model}, seed {seed}, {method}: {exc}") from exc
    return out


def _rows_table(model, seed, method, w_columns: dict, frontier: Frontier, rows: np.ndarray) -> pa.Table:
    n = rows.size
    data = {
        "model": pa.array([model] * n, pa.string()),
        "seed": pa.array([seed] * n, pa.int64()),
        "method": pa.array([method] * n, pa.string()),
    }
    data.update({k: pa.array(v, pa.float64()) for k, v in w_columns.items()})
    data.update({c: pa.array(getattr(frontier, c)[rows]) for c in tables.SELECTED_COLUMNS})
    return pa.table(data)


def _error(model) -> str:
    """The error a model's realizations are judged for (SPEC 4): FB false positives, FF false negatives."""
    return "false_negative" if model.has_feedforward else "false_positive"


def _uncertainty(method: str, ff: bool, segs: list, nbs: list) -> dict:
    """SPEC 9: P(W_FP >= the paper's) for a study of the paper's size; a bootstrap interval of W_FN."""
    if not ff:
        extents = [over_w.false_positive_extent(s, nb) for s, nb in zip(segs, nbs, strict=True)]
        ref = paper.W_FP.get(method)
        p = None if ref is None else over_w.threshold_exceedance(extents, ref, paper.N_REALIZATIONS)
        return {"p_w_fp_at_paper": p}
    boot = over_w.false_negative_bootstrap(segs, nbs)
    return {
        "w_fn_low": boot.low,
        "w_fn_high": boot.high,
        "p_w_fn_at_paper": boot.share_at_or_above(paper.W_FN),
    }


def _thresholds(config: Config, chosen, segments: dict, nb_ft: dict) -> pa.Table:
    rows = []
    for model in config.models:
        for method in methods.METHODS.values():
            key = (model.name, method.name)
            if key not in segments:
                continue
            nf = method.nf(config.identify)
            ff = model.has_feedforward
            marks = {c.column: c.w(nf) for c in chosen}
            at_marks = calibration.error_rates(
                method.name, model.name, _error(model), segments[key], nb_ft[key], list(marks.values())
            )
            rows.append(
                {
                    "method": method.name,
                    "model": model.name,
                    "has_feedforward": ff,
                    "n_realizations": len(segments[key]),
                    "nf": nf,
                    **marks,
                    "w_fp": None if ff else over_w.false_positive_threshold(segments[key], nb_ft[key]),
                    "w_fn": over_w.false_negative_threshold(segments[key], nb_ft[key]) if ff else None,
                    **_uncertainty(method.name, ff, segments[key], nb_ft[key]),
                    **{tables.rate_column(c): float(r) for c, r in zip(marks, at_marks.rate, strict=True)},
                }
            )
    return pa.Table.from_pylist(rows, schema=tables.thresholds([c.column for c in chosen]).arrow)


def _rates(config: Config, segments: dict, nb_ft: dict, w: np.ndarray) -> pa.Table:
    parts = []
    for model in config.models:
        for method in methods.METHODS:
            key = (model.name, method)
            if key in segments:
                curve = calibration.error_rates(
                    method, model.name, _error(model), segments[key], nb_ft[key], w
                )
                parts.append(curve.to_arrow())
    return results.concat(parts) if parts else tables.RATES.arrow.empty_table()


# --------------------------------------------------------------------------- the whole study
