"""Effects across people (SPEC 13; ``hcid analyse --compare FACTOR``): what differs between the
levels of a factor, per method, for every fitted parameter and loop figure of the study's runs,
and (method ``model-free``) for each run's Fourier-coefficient responses at the forcing lines,
with subjects as repeated measures (:mod:`hcid.analysis.effects`), written to
``study_effects.parquet`` and ``.csv``. A whole experiment's superposition (SPEC 12: each
person's single-input trials against their two-input ones) is compared the same way, with or
without ``--compare`` (source ``superposition``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa

from hcid import tables
from hcid.analysis.fourier import fc_estimate
from hcid.config import Plant
from hcid.errors import ConfigError, DataError
from hcid.hcfit.determined import is_undetermined
from hcid.io import folders, results

__all__ = [
    "LOOP_FIGURES", "MODEL_FREE", "SUPERPOSITION", "compare_levels", "effects_rows", "forget_effects",
    "effects_table", "line_values", "long_table", "superposition_rows", "write_effects",
]  # fmt: skip

#: The source of the effects on the runs' Fourier-coefficient responses (no model behind them).
MODEL_FREE = "model-free"

#: The source of the superposition effects, its factor and levels (the reference first), and the
#: combined estimates (:data:`hcid.analysis.conditions.SOURCES`) each level is.
SUPERPOSITION = "superposition"
TRIALS = "trials"
TRIAL_LEVELS = {"two-input": "two-input trials", "single-input": "single-input trials"}

#: The loop figures compared beside the parameters: (column, unit); none has a standard error.
LOOP_FIGURES = (("crossover", "rad/s"), ("phase_margin", "deg"), ("remnant_share_data", "1"))


def compare_levels(rows: Sequence[dict], compare: str, person: str | None) -> list[str]:
    """The compared factor's levels in the runs, checked: the factor exists, the runs belong to
    people (``person``), it is not the people's own factor, and it has at least two levels."""
    if not rows:
        return []
    if compare not in rows[0]:
        ours = {*tables.ANALYSIS.names, *tables.RUNS.names}
        factors = [c for c in rows[0] if c not in ours]
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
    (undetermined where its status says so, :func:`hcid.hcfit.determined.is_undetermined`; a
    flagged value, outside its plausible range or not told from 0, is determined and kept, as in
    the group summaries), and each loop figure (no se): a pandas
    DataFrame (pandas and statsmodels are imported here, not with ``hcid analyse``)."""
    import pandas as pd

    out = []
    for r in rows:
        base = {"subject": str(r[person]), compare: str(r[compare])}
        for p in tables.HC_PARAMETER_NAMES:
            undetermined = is_undetermined(r[f"{p}_status"]) or not math.isfinite(r[p])
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


def line_values(
    records: Mapping[int, dict], rate: float, n: int, plants: Mapping[int, Plant] | None = None
) -> dict[int, list[tuple[str, float]]]:
    """Each run's Fourier-coefficient responses (SPEC 10) over the first ``n`` samples: |He| (dB)
    and its phase (deg) at every disturbance line, |Ht| and its phase at every target line, each
    named with the line's frequency; none for a run whose design allows no estimate.

    With each run's plant (``plants``: a study whose runs' plants differ), also the model
    inversion |Ht Yc| (dB, SPEC 11; 0 dB the plant's exact inverse) at every target line, with the
    run's own Yc. A study of one plant leaves it out: there |Ht Yc| in dB is |Ht| plus the same
    constant per line in every run, so its effects would be |Ht|'s again, doubling the Holm family.
    """
    out = {}
    for run, record in records.items():
        try:
            fc = fc_estimate([record], rate, slice(0, n))
        except DataError:
            continue
        values = []
        yc = None if plants is None else plants[run].response(fc.omega_t)
        paths = [("He", fc.omega_e, fc.he), ("Ht", fc.omega_t, fc.ht)]
        for path, omega, h in paths + ([("Ht Yc", fc.omega_t, fc.ht * yc)] if yc is not None else []):
            for w, x in zip(omega, h, strict=True):
                if np.isfinite(x) and abs(x) > 0:
                    values.append((f"|{path}| at {w:.3g} rad/s", float(20 * np.log10(abs(x)))))
                    if path != "Ht Yc":  # the inversion's size, as SPEC 12's |Ht Yc|; no phase
                        values.append((f"{path} phase at {w:.3g} rad/s", float(np.degrees(np.angle(x)))))
        out[run] = values
    return out


def _line_table(rows: Sequence[dict], lines: Mapping[int, list], compare: str, person: str):
    import pandas as pd

    out = [
        {"subject": str(r[person]), compare: str(r[compare]), "quantity": name, "value": value,
         "se": math.nan, "undetermined": False}
        for r in rows
        for name, value in lines.get(int(r["run_id"]), [])
    ]  # fmt: skip
    return pd.DataFrame(out)


def effects_rows(
    rows: Sequence[dict], compare: str, person: str, lines: Mapping[int, list] | None = None
) -> list[dict]:
    """Every method's effects of ``compare`` (its first level the reference), one dict per
    effect with its ``source`` (the method whose fits it compares: rows of
    ``study_effects.parquet``); with each run's ``lines`` (:func:`line_values`), their effects as
    source :data:`MODEL_FREE` at the lines every level of ``compare`` has (the CPHS `so` trials'
    forcing lines are some of the `fo` trials'), with Holm's correction over each source's
    quantities apart."""
    from hcid.analysis.effects import study_effects

    units = {**tables.PARAMETER_UNITS, **dict(LOOP_FIGURES)}
    out = []
    for method in sorted({r["method"] for r in rows}):
        mine = [r for r in rows if r["method"] == method]
        effects = study_effects(long_table(mine, compare, person), compare, units=units)
        out += [{"source": method, **e.__dict__} for e in effects]
    if lines:
        runs = list({int(r["run_id"]): r for r in rows}.values())  # one row per run
        table = _line_table(runs, lines, compare, person)
        if len(table):  # the lines every level has: a line of some levels only has no contrast
            levels = table.groupby("quantity")[compare].nunique()
            table = table[table["quantity"].map(levels) == table[compare].nunique()]
            names = list(dict.fromkeys(table["quantity"]))
            angles = {q for q in names if " phase at " in q}
            units = {q: "deg" if q in angles else "dB" for q in names}
            effects = study_effects(table, compare, angles=angles, units=units)
            out += [{"source": MODEL_FREE, **e.__dict__} for e in effects]
    return out


def superposition_rows(lines: pa.Table) -> list[dict]:
    """A whole experiment's superposition (SPEC 12) as effects across people: per response (U/R
    at the target lines, U/D at the disturbance lines) and line, each person's single-input
    estimate of |H| (dB) and of its phase (deg, by circular statistics) against their two-input
    one (the reference), from ``session_lines`` (:class:`hcid.pipeline.sessions.Session`); Holm's
    correction over these quantities. A line is compared where at least two people measured it
    both ways; empty where no line is."""
    import pandas as pd

    from hcid.analysis.effects import study_effects

    sources = {source: level for level, source in TRIAL_LEVELS.items()}
    rows = [r for r in lines.to_pylist() if r["source"] in sources and r["person"] != "median"]
    both = {r["person"] for r in rows if r["source"] == TRIAL_LEVELS["two-input"]} & {
        r["person"] for r in rows if r["source"] == TRIAL_LEVELS["single-input"]
    }
    if len(both) < 2:
        return []
    out = []
    for r in rows:
        if r["person"] not in both:
            continue
        for name, column in (("U/R", "h_ur"), ("U/D", "h_ud")):
            db, deg = r[f"{column}_db"], r[f"{column}_deg"]
            if not (math.isfinite(db) and math.isfinite(deg)):
                continue
            at = f"at {r['omega']:.3g} rad/s"
            base = {
                "subject": r["person"],
                TRIALS: sources[r["source"]],
                "se": math.nan,
                "undetermined": False,
            }
            out += [{**base, "quantity": f"|{name}| {at}", "value": db},
                    {**base, "quantity": f"{name} phase {at}", "value": deg}]  # fmt: skip
    if not out:
        return []
    table = pd.DataFrame(out)
    # A line is compared where at least two people measured it both ways (not every person's
    # trials measured every line of the study).
    paired = table.groupby(["quantity", "subject"])[TRIALS].nunique().eq(2).groupby("quantity").sum()
    table = table[table["quantity"].isin(paired[paired >= 2].index)]
    if table.empty:
        return []
    names = list(dict.fromkeys(table["quantity"]))
    angles = {q for q in names if " phase at " in q}
    units = {q: "deg" if q in angles else "dB" for q in names}
    effects = study_effects(table, TRIALS, reference="two-input", angles=angles, units=units)
    return [{"source": SUPERPOSITION, **e.__dict__} for e in effects]


def effects_table(rows: list[dict]) -> pa.Table:
    """``study_effects``' table of :func:`effects_rows` and :func:`superposition_rows`."""
    return pa.Table.from_pylist(rows, schema=tables.STUDY_EFFECTS.arrow)


def write_effects(run_dir: Path, table: pa.Table) -> pa.Table:
    """``study_effects.parquet`` and ``.csv`` (:func:`effects_table`), each written atomically."""
    results.write(tables.STUDY_EFFECTS, table, run_dir)
    frame = table.to_pandas()
    folders.atomic_write(Path(run_dir) / "study_effects.csv", lambda tmp: frame.to_csv(tmp, index=False))
    return table


def forget_effects(run_dir: Path) -> None:
    """An earlier comparison's tables, removed where this analysis compares nothing."""
    names = [n for n in (tables.STUDY_EFFECTS.file, "study_effects.csv") if (Path(run_dir) / n).is_file()]
    if names:
        folders.remove_owned(Path(run_dir), names)
