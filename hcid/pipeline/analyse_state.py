"""What ``hcid analyse`` holds between its phases (:mod:`hcid.pipeline.analyse`): the study as
given (:class:`Study`) and what the phases found (:class:`Found`, filled phase by phase)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa

from hcid.config import Config
from hcid.pipeline.execution import Execution
from hcid.pipeline.options import AnalysisOptions
from hcid.pipeline.plants import RunPlants

__all__ = ["Found", "Study"]


@dataclass(frozen=True)
class Study:
    """A study being analysed: what every phase reads."""

    config: Config
    run_dir: Path
    options: AnalysisOptions
    execution: Execution
    by: tuple[str, ...]
    runs: pa.Table
    records: dict[int, dict]
    groups: dict[tuple[str, ...], list[int]]
    kn_rate: float
    plants: RunPlants  # each run's config, with its own plant


@dataclass
class Found:
    """What the phases found: each run's fits; per group its model, twins (per method) and their
    remnant; per run and method its frontier and selection path, evidence and final analysis."""

    fitted: dict = field(default_factory=dict)  # seed -> ({ff: HCFit}, remnant fit or None)
    models: dict = field(default_factory=dict)  # group -> GroupModel
    remnants: dict = field(default_factory=dict)  # group -> (kn, w_n, zeta_n)
    used: dict = field(default_factory=dict)  # (group, method) -> TwinSets
    paths: dict = field(default_factory=dict)  # (seed, method) -> (frontier, selection path, nb_ft)
    deciding: dict = field(default_factory=dict)  # group -> {method: statistic}
    fb_drawn: dict = field(default_factory=dict)  # (group, method) -> FB twins the p-values used
    chosen: dict = field(default_factory=dict)  # (group, method) -> (w, rule, uncertain)
    evidence: dict = field(default_factory=dict)  # (seed, method) -> evidence columns
    finals: dict = field(default_factory=dict)  # (seed, method) -> SelectedAnalysis
