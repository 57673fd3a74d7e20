"""Each run's plant in a measured study: the config's one plant, or the plant of the run's value of
a data factor (``loop.plant: {by: FACTOR, levels: {...}}``), checked against the data set once,
before anything is written (:func:`run_plants`).

A run of a level is analysed with :meth:`hcid.config.Config.with_plant` of its level: the same
config as one giving that plant alone, so that every per-run and per-group step (the plant check,
the fits, the twins, the loop figures, the model inversion) reads one plant, as it does for a
study of one plant, and a plant's runs give the tables its own config gives.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from hcid.config import Config, Plant
from hcid.errors import ConfigError, DataError
from hcid.io.datasets import DataSet

__all__ = ["ONE_PLANT", "RunPlants", "run_plants"]

#: The level of every run of a study of one plant.
ONE_PLANT = ""


@dataclass(frozen=True)
class RunPlants:
    """Each run's level of the plant factor, and the config of each level (with its one plant).

    ``factor`` is ``loop.plant.by`` (None for one plant: every run's level :data:`ONE_PLANT`, its
    config the study's own); ``level_of`` maps a run id to its level, ``configs`` a level the runs
    hold to its config, in the order of ``loop.plant.levels``.
    """

    factor: str | None
    level_of: Mapping[int, str]
    configs: Mapping[str, Config]

    def of_run(self, run: int) -> Config:
        """The config a run is analysed with: its own plant."""
        return self.configs[self.level_of[run]]

    def of_runs(self, runs: Iterable[int]) -> Config:
        """The config of runs of one plant (a group's: :meth:`grouping` keeps each group to one).

        Raises
        ------
        DataError
            For runs of several plants.
        """
        levels = sorted({self.level_of[s] for s in runs})
        if len(levels) != 1:
            raise DataError(f"runs of {len(levels)} plants ({', '.join(levels)}) in one group")
        return self.configs[levels[0]]

    def plant_of(self, run: int) -> Plant:
        return self.of_run(run).loop.plant

    def grouping(self, by: Sequence[str]) -> tuple[str, ...]:
        """The factors the runs are grouped by: ``by``, and the plant factor after them where
        ``by`` does not hold it.

        A group's twins are the group's fitted model in the group's plant's loop, driven by each of
        its forcing sets; a group of several plants would have no one loop, and runs of two plants
        driven alike (the CPHS recordings' plants share their forcing functions) would share one
        forcing set's twins. Grouping by the plant too keeps every group to one plant, so each
        group's twins, W and p-values are exactly those of a study of its plant alone; giving each
        run twins of its own plant instead would need per-plant twins within a group and a group
        model pooled over plants, whose parameters (Kpt scales the inverse of the plant) mean
        different things."""
        by = tuple(by)
        return by if self.factor is None or self.factor in by else (*by, self.factor)

    def split(self, groups: Mapping[tuple, list[int]]) -> dict[str, dict[tuple, list[int]]]:
        """The groups of each level (each group of one plant), in the groups' order."""
        out: dict[str, dict[tuple, list[int]]] = {}
        for key, runs in groups.items():
            out.setdefault(self.level_of[runs[0]], {})[key] = runs
        return out

    @property
    def several(self) -> bool:
        """Whether the runs hold more than one plant."""
        return len(self.configs) > 1


def run_plants(config: Config, data: DataSet) -> RunPlants:
    """Each run's plant, checked: the data set has the plant factor, and every run's value of it
    is a level of ``loop.plant.levels``.

    Raises
    ------
    ConfigError
        For a data set without the factor ``loop.plant.by`` (naming the data's factors).
    DataError
        For a run whose value of the factor has no plant (naming its file, the run and the value).
    """
    factor = config.plant_factor
    if factor is None:
        return RunPlants(None, dict.fromkeys(data.records, ONE_PLANT), {ONE_PLANT: config})
    if factor not in data.factors:
        raise ConfigError(
            f"loop.plant.by: the data set has no factor {factor!r} (its factors: "
            f"{', '.join(data.factors) or 'none'}; name them with data.pattern or a manifest)"
        )
    given = config.loop.plant.names
    rows = {int(r["run"]): r for r in data.runs}
    level_of = {}
    for run in data.records:
        level = str(rows[run][factor])
        if level not in given:
            raise DataError(
                f"{rows[run]['file']}: run {run} has {factor} {level!r}, for which loop.plant.levels "
                f"gives no plant (it has {', '.join(given)})"
            )
        level_of[run] = level
    held = set(level_of.values())
    return RunPlants(factor, level_of, {lv: config.with_plant(lv) for lv in given if lv in held})
