"""What ``hcid analyse``'s steps take and return (:mod:`hcid.pipeline.analyse`): the study as given
(:class:`Study`), then one frozen result per step, passed on in memory:

=================  ============================================  ==========================
step               returns                                        module
=================  ============================================  ==========================
1 identify         :class:`hcid.pipeline.studies.IdentifyRun`     :mod:`.studies`
2 fit runs         ``{run: RunFits}``                             :mod:`.fit_hc`
3 twins            ``{group: GroupTwins}``                        :mod:`.analyse_twins`
selection paths    ``{(run, method): RunPath}``                   :mod:`.analyse`
line statistics    ``{run: {statistic: value} or None}``          :mod:`.line_statistics`
4 more FB twins    ``{group: Tested}``, ``Evidence``              :mod:`.analyse_twins`
5 fit selected     :class:`Selected`                              :mod:`.analyse`
6 tables           ``AnalysisTables``, written by one writer      :mod:`.analysis_tables`
=================  ============================================  ==========================

Step 4 also returns the :class:`hcid.pipeline.evidence.Evidence` that steps 5 and 6 read: the
twins' line statistics computed once and the FB twins drawn per forcing set (a frozen value,
built round by round in step 4).

A run is named by its id (the ``seed`` column of ``runs.parquet``), a group by its factor
values (a tuple of str), a method by its registered name."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from hcid.config import Config
from hcid.hcfit.determined import GroupModel
from hcid.hcfit.selected import SelectedAnalysis
from hcid.methods import StageChoice
from hcid.pipeline.execution import Execution
from hcid.pipeline.options import AnalysisOptions
from hcid.pipeline.plants import RunPlants
from hcid.pipeline.twin_values import Remnant
from hcid.pipeline.twins import TwinSets
from hcid.selection.calibration import WChoice
from hcid.selection.frontier import Frontier
from hcid.selection.over_w import SelectionPath

__all__ = ["Group", "GroupTwins", "RunOutcome", "RunPath", "Selected", "Study", "Tested"]

Group = tuple[str, ...]


@dataclass(frozen=True)
class Study:
    """A study being analysed: what every step reads."""

    config: Config
    run_dir: Path
    options: AnalysisOptions
    execution: Execution
    by: tuple[str, ...]
    runs: dict[int, Mapping]  # run id -> its file, file_run and factors (DataSet.runs)
    factors: tuple[str, ...]
    records: dict[int, dict]
    groups: dict[Group, list[int]]
    kn_rate: float
    plants: RunPlants  # each run's config, with its own plant


@dataclass(frozen=True)
class GroupTwins:
    """A group's model (medians of what its runs determine), its twins' remnant, and per method
    the twins it uses (its own, or with the study's feedforward: ``--ff-twin``)."""

    model: GroupModel
    remnant: Remnant
    used: dict[str, TwinSets]


class RunPath(NamedTuple):
    """A run's identification by one method: its frontier, its selection path over W, and the
    choices of the method's earlier stages (what its final stage and the selected model's fit
    build on)."""

    frontier: Frontier
    path: SelectionPath
    choices: tuple[StageChoice, ...]


@dataclass(frozen=True)
class Tested:
    """A group's test of feedforward: per method the statistic that decides (the one whose twins
    show the most power) and how many FB twins its runs' p-values used."""

    deciding: dict[str, str]
    fb_drawn: dict[str, int]


@dataclass(frozen=True)
class RunOutcome:
    """One run and method: its evidence columns (p-value, statistic, power, verdict) and the
    analysis of its model selected at the group's W."""

    evidence: dict
    final: SelectedAnalysis


@dataclass(frozen=True)
class Selected:
    """Every group's W per method, and every run's outcome per method."""

    chosen: dict[tuple[Group, str], WChoice]
    runs: dict[tuple[int, str], RunOutcome]
