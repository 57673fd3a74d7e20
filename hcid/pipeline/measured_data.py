"""A measured data set entering a study: checked against the config (its rate, its windows, its
plant: :func:`check_plant`) and kept in the run directory (``measured.parquet``, ``runs.parquet``,
``skipped.parquet``), for :func:`hcid.pipeline.studies.identify_study`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import tables
from hcid.analysis.fourier import PLANT_MISMATCH_LIMIT, is_other_plant, plant_mismatch
from hcid.config import Config
from hcid.errors import DataError
from hcid.io import datasets, measured, results
from hcid.pipeline.plants import RunPlants, run_plants
from hcid.pipeline.rundir import check_run_dir, record_config

__all__ = ["check_data", "check_plant", "import_data", "write_skipped"]


def import_data(config: Config, run_dir: Path, data_set: datasets.DataSet, force: bool) -> None:
    """Keep a copy of a data set in ``measured.parquet`` and its runs' factors in
    ``runs.parquet``. Other data than the run's earlier identification results were made from
    are refused without ``force``: their results would be reused as if they were these data's."""
    data = config.data
    check_run_dir(config, run_dir, "identify", force=force)
    table = measured.records_table(data.name, data_set.records)
    if not force:
        old = results.read_optional(tables.MEASURED, run_dir)
        if old is not None and (run_dir / tables.FRONTIER.file).exists() and not old.equals(table):
            raise DataError(
                f"{run_dir}: holds identification results of other measured data (its "
                f"{tables.MEASURED.file} differs from these files); use --force to replace them, "
                "or another --run"
            )
    record_config(config, run_dir)
    results.write(tables.MEASURED, table, run_dir)
    results.write(tables.RUNS, datasets.runs_table(data.name, data_set), run_dir)


def check_data(config: Config, data: datasets.DataSet) -> None:
    """A data set made for this config: at its analysis rate, every run as long as its windows
    need (what :func:`hcid.assembly.resolve.read_study` gives; a data set read otherwise may not be)."""
    rate = config.timing.output_rate
    if not np.isclose(data.rate, rate, rtol=1e-9):
        raise DataError(
            f"data: the data set is at {data.rate:g} Hz, the config analyses at {rate:g} Hz; read it "
            "for this config (hcid.assembly.resolve.read_study)"
        )
    need = measured.samples_needed(config)
    short = next((run for run, rec in data.records.items() if rec["u"].size < need), None)
    if short is not None:
        raise DataError(
            f"data: run {short} holds {data.records[short]['u'].size} samples, the config's windows "
            f"need {need}; read it for this config (hcid.assembly.resolve.read_study)"
        )
    check_plant(config, data)


def write_skipped(run_dir: Path, data: datasets.DataSet) -> None:
    """``skipped.parquet``: the files a folder or glob of the data set found that are not runs."""
    rows = [{"file": f, "reason": why} for f, why in data.skipped]
    results.write(tables.SKIPPED, pa.Table.from_pylist(rows, schema=tables.SKIPPED.arrow), run_dir)


def check_plant(config: Config, data: datasets.DataSet, plants: RunPlants | None = None) -> None:
    """Refuse runs whose e is not ft minus the configured plant's output (a data set of another
    plant, or the disturbance at the other point): every result would be for the wrong loop.
    Each run is checked over the analysis window (where its multisines have whole periods; a
    single-input run at its input's lines) against its own plant (``plants``, from
    :func:`hcid.pipeline.plants.run_plants` where not given); runs whose forcing functions have no
    lines there, a config without a loop (identification alone) and one with
    ``data.plant_check: false`` are not checked."""
    loop, rate = config.loop, config.timing.output_rate
    if loop is None:
        return
    plants = run_plants(config, data) if plants is None else plants  # the factor checked first
    if not config.data.plant_check:
        return
    n = config.timing.record_samples
    found = {
        run: plant_mismatch({k: rec[k][:n] for k in ("ft", "fd", "e", "u")}, rate,
                            plants.plant_of(run).num, plants.plant_of(run).den, loop.disturbance_at)
        for run, rec in data.records.items()
    }  # fmt: skip
    over = {run: m for run, m in found.items() if is_other_plant(m)}
    if not over:
        return
    worst = max(over, key=over.get)
    file = next((r["file"] for r in data.runs if r.get("run") == worst), None)
    key = "loop.plant" if plants.factor is None else f"loop.plant.levels.{plants.level_of[worst]}"
    raise DataError(
        f"data: run {worst}{f' ({file})' if file else ''} is not the configured plant: "
        f"{over[worst]:.0%} (RMS) of its theta = ft - e at the forcing lines is not what "
        f"{key} {plants.plant_of(worst).text} with the disturbance at its {loop.disturbance_at} gives "
        f"({len(over)} of {len(found)} runs over {PLANT_MISMATCH_LIMIT:.0%}); check loop.plant and "
        "loop.disturbance_at, or the data files (data.plant_check: false where the plant leaves out "
        "a display delay)"
    )
