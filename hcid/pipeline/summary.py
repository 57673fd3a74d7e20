"""What ``hcid analyse`` found, summed up once per group and method from its tables: the
answer line's evidence, the parameters its runs determine, the loop's medians. The CLI prints
these summaries and the report draws them (:mod:`hcid.cli.answers`,
:mod:`hcid.report.sections.study`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from hcid.pipeline.evidence import ParameterSummary, summarise_parameters

__all__ = ["GroupSummary", "rate_interval", "summarise_groups"]


@dataclass(frozen=True)
class GroupSummary:
    """One group and method of an analysis: its ``analysis_groups`` row, its runs' ``analysis``
    rows, the range of the runs' stated power, the parameters its runs determine (medians over
    them) and the loop's crossover (rad/s) and phase margin (deg), medians over its runs."""

    group: dict
    runs: list[dict]
    power: tuple[float, float]
    parameters: list[ParameterSummary]
    crossover: float
    phase_margin: float


def summarise_groups(groups: pa.Table, runs: pa.Table) -> list[GroupSummary]:
    """Every group and method of an analysis, in the groups table's order."""
    rows = runs.to_pylist()
    out = []
    for g in groups.to_pylist():
        mine = [r for r in rows if r["group"] == g["group"] and r["method"] == g["method"]]
        power = [r["power"] for r in mine]
        out.append(
            GroupSummary(
                g,
                mine,
                (min(power), max(power)) if power else (math.nan, math.nan),
                summarise_parameters(mine),
                _median([r["crossover"] for r in mine]),
                _median([r["phase_margin"] for r in mine]),
            )
        )
    return out


def _median(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def rate_interval(rate: float, low: float, high: float, *, long: bool = True) -> str:
    """An error rate with its exact 95% interval, in percent.

    >>> rate_interval(0.05, 0.001, 0.25)
    '5% (95% interval 0 to 25%)'
    >>> rate_interval(0.05, 0.001, 0.25, long=False)
    '5% [0, 25]'
    """
    if long:
        return f"{100 * rate:.0f}% (95% interval {100 * low:.0f} to {100 * high:.0f}%)"
    return f"{100 * rate:.0f}% [{100 * low:.0f}, {100 * high:.0f}]"
