"""Effects across people (SPEC 13; ``hcid analyse --compare FACTOR``): what differs between the
levels of a factor, per method, for every fitted parameter and loop figure of the study's runs,
with subjects as repeated measures (:mod:`hcid.analysis.effects`), written to
``study_effects.parquet`` and ``.csv``."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import pyarrow as pa

from hcid import tables
from hcid.errors import ConfigError
from hcid.hcfit.determined import DETERMINED
from hcid.io import folders, results

__all__ = ["LOOP_FIGURES", "compare_levels", "effects_rows", "forget_effects", "long_table", "write_effects"]

#: The loop figures compared beside the parameters: (column, unit); none has a standard error.
LOOP_FIGURES = (("crossover", "rad/s"), ("phase_margin", "deg"), ("remnant_share_data", "1"))


def compare_levels(rows: Sequence[dict], compare: str, person: str | None) -> list[str]:
    """The compared factor's levels in the runs, checked: the factor exists, is not the people's
    own factor, and has at least two levels, each with runs of at least two people."""
    if not rows:
        return []
    if compare not in rows[0]:
        factors = [c for c in rows[0] if c not in tables.ANALYSIS.names]
        raise ConfigError(f"compare (--compare): the data have no factor {compare!r}; they have {factors}")
    if person is None:
        raise ConfigError(
            "compare (--compare): needs the people the runs belong to (a `subject` factor, or --person)"
        )
    if compare == person:
        raise ConfigError(f"compare (--compare): {compare!r} names the people; compare a condition of theirs")
    levels = sorted({str(r[compare]) for r in rows})
    if len(levels) < 2:
        raise ConfigError(f"compare (--compare): {compare!r} has one level only ({levels[0]})")
    return levels


def long_table(rows: Sequence[dict], compare: str, person: str):
    """One row per run and quantity of one method's runs: the parameter with its standard error
    (undetermined where its status is not ``determined``), and each loop figure (no se): a pandas
    DataFrame (pandas and statsmodels are imported here, not with ``hcid analyse``)."""
    import pandas as pd

    out = []
    for r in rows:
        base = {"subject": str(r[person]), compare: str(r[compare])}
        for p in tables.HC_PARAMETER_NAMES:
            undetermined = r[f"{p}_status"] != DETERMINED or not math.isfinite(r[p])
            out.append(
                {**base, "quantity": p, "value": r[p], "se": r[f"{p}_se"], "undetermined": undetermined}
            )
        for name, _ in LOOP_FIGURES:
            value = r[name]
            out.append({**base, "quantity": name, "value": value, "se": math.nan,
                        "undetermined": value is None or not math.isfinite(value)})  # fmt: skip
    table = pd.DataFrame(out)
    # A quantity whose standard errors are known for some determined runs only is compared
    # without weights (the mixed model weighs all runs or none).
    known = table["se"].apply(lambda x: x is not None and math.isfinite(x) and x > 0)
    partial = table[~table["undetermined"]].assign(known=known).groupby("quantity")["known"].all()
    table.loc[table["quantity"].isin(partial[~partial].index), "se"] = math.nan
    return table


def effects_rows(rows: Sequence[dict], compare: str, person: str) -> list[dict]:
    """Every method's effects of ``compare`` (its first level the reference), one dict per
    effect with its ``method`` (rows of ``study_effects.parquet``)."""
    from hcid.analysis.effects import study_effects

    units = {**tables.PARAMETER_UNITS, **dict(LOOP_FIGURES)}
    out = []
    for method in sorted({r["method"] for r in rows}):
        mine = [r for r in rows if r["method"] == method]
        effects = study_effects(long_table(mine, compare, person), compare, units=units)
        out += [{"method": method, **e.__dict__} for e in effects]
    return out


def write_effects(run_dir: Path, rows: list[dict]) -> pa.Table:
    """``study_effects.parquet`` and ``.csv``, each written atomically; returns the table."""
    table = pa.Table.from_pylist(rows, schema=tables.STUDY_EFFECTS.arrow)
    results.write(tables.STUDY_EFFECTS, table, run_dir)
    frame = table.to_pandas()
    folders.atomic_write(Path(run_dir) / "study_effects.csv", lambda tmp: frame.to_csv(tmp, index=False))
    return table


def forget_effects(run_dir: Path) -> None:
    """An earlier comparison's tables, removed where this analysis compares nothing."""
    names = [n for n in (tables.STUDY_EFFECTS.file, "study_effects.csv") if (Path(run_dir) / n).is_file()]
    if names:
        folders.remove_owned(Path(run_dir), names)
