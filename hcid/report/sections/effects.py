"""What differs between conditions (SPEC 13; ``hcid analyse --compare FACTOR``): the answer first
(the effects at p <= alpha after Holm's correction), then every effect's estimate with its 95%
interval in a forest plot and a table, per method and test."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from hcid.hcfit.consistency import format_p
from hcid.report.document import Doc

TITLE = "What differs between conditions"


@dataclass(frozen=True)
class EffectsData:
    compare: str
    alpha: float
    answer: list[list[str]]
    rows: list[list[str]]
    effects: list[dict]


def _num(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.3g}"


def _p(p: float) -> str:
    return "-" if not math.isfinite(p) else format_p(p)


def _interval(e: dict) -> str:
    if not math.isfinite(e["estimate"]):
        return "-"
    if not (math.isfinite(e["low"]) and math.isfinite(e["high"])):
        return f"{_num(e['estimate'])} (no interval)"
    return f"{_num(e['estimate'])} [{_num(e['low'])}, {_num(e['high'])}]"


def _unit(e: dict) -> str:
    return "" if e["unit"] in ("-", "1") else e["unit"]


def compute(run, done) -> EffectsData | None:
    if run.study_effects is None or run.study_effects.num_rows == 0:
        return None
    effects = run.study_effects.to_pylist()
    alpha = float(run.analysis_groups.column("alpha")[0].as_py()) if run.analysis_groups is not None else 0.05
    found = [e for e in effects if math.isfinite(e["p_holm"]) and e["p_holm"] <= alpha]
    answer = [
        [e["source"], e["quantity"], e["effect"].split(": ", 1)[-1], _interval(e), _unit(e), e["test"],
         _p(e["p_holm"]), str(e["subjects"])]
        for e in found
    ]  # fmt: skip
    rows = [
        [e["source"], e["quantity"], e["effect"].split(": ", 1)[-1], e["test"], _interval(e), _unit(e),
         _p(e["p"]), _p(e["p_holm"]), str(e["subjects"]), str(e["runs"]), str(e["left_out"]), e["note"]]
        for e in effects
    ]  # fmt: skip
    compared = " and ".join(dict.fromkeys(e["effect"].split(":", 1)[0] for e in effects))
    return EffectsData(compared, alpha, answer, rows, effects)


def render(data: EffectsData | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    if data.answer:
        doc.text(
            f"**{len(data.answer)} effect(s) of {data.compare} at p <= {data.alpha:g} after Holm's "
            "correction** (subjects as repeated measures):"
        )
        header = ["source", "quantity", "effect", "estimate [95% interval]", "unit", "test", "Holm p"]
        doc.table([*header, "subjects"], data.answer)
    else:
        doc.text(f"**No effect of {data.compare} at p <= {data.alpha:g} after Holm's correction.**")
    doc.text(
        "Each quantity of the runs' fits at their group's W (parameters where determined, with their "
        "standard errors as weights; the loop's crossover, phase margin and the remnant's share from "
        "the data), compared between the levels of the factor with the subjects as repeated measures: "
        "a linear mixed model (REML, a random intercept per subject; its interval the wider of the "
        "model's and the one robust to subjects whose effects differ), the paired Wilcoxon signed-rank "
        "test of the subjects' means (Kruskal-Wallis for more than two levels), and Holm's correction "
        "over the quantities per test. Undetermined values are left out and counted."
    )
    doc.figure(
        "effects_forest.png",
        f"Effects of {data.compare} per quantity and method: the mixed model's estimate with its 95% "
        "interval, filled where Holm's p is at most the level; each quantity in its own unit, so the "
        "rows are read one by one, not against each other.",
        lambda d=data: plot_forest(d.effects, d.alpha),
    )
    doc.table(
        ["source", "quantity", "effect", "test", "estimate [95% interval]", "unit", "p", "Holm p", "subjects",
         "runs", "left out", "note"],
        data.rows,
    )  # fmt: skip


def plot_forest(effects: list[dict], alpha: float) -> Figure:
    """A forest plot of the mixed model's effects, one row per quantity and method. Quantities
    differ in their units, so each row is drawn in units of its own 95% half-interval (the
    estimate over the half-width, the interval then -1 to +1 about it: it crosses 0 where the
    effect is not told from none) and its value in its own unit is written at the right; filled
    where Holm's p is at most ``alpha``; a quantity that could not be compared says so."""
    from hcid.analysis.effects import MIXED  # statsmodels and pandas loaded only where effects are drawn

    rows = [e for e in effects if e["test"] == MIXED]
    fig = Figure(figsize=(9.0, 1.3 + 0.26 * max(len(rows), 1)))
    ax = fig.subplots()
    right = ax.get_yaxis_transform()  # x in axes fraction, y in data
    labels = []
    for i, e in enumerate(rows):
        labels.append(f"{e['source']}: {e['quantity']}")
        half = (e["high"] - e["low"]) / 2.0
        if not (math.isfinite(e["estimate"]) and math.isfinite(half) and half > 0):
            ax.text(1.01, -i, "not compared", transform=right, va="center", fontsize=7, color="0.4")
            continue
        hit = math.isfinite(e["p_holm"]) and e["p_holm"] <= alpha
        z = e["estimate"] / half
        ax.plot([z - 1.0, z + 1.0], [-i, -i], color="C0", lw=1.5)
        ax.plot(z, -i, "s", color="C0", mfc="C0" if hit else "white", ms=6)
        unit = f" {e['unit']}" if e["unit"] not in ("", "-", "1") else ""
        text = f"{_num(e['estimate'])} [{_num(e['low'])}, {_num(e['high'])}]{unit}"
        ax.text(1.01, -i, text, transform=right, va="center", fontsize=7)
    ax.axvline(0.0, color="0.4", lw=0.8, ls="--")
    ax.set_yticks(-np.arange(len(rows)))
    ax.set_yticklabels(labels, fontsize=7)
    ax.set_ylim(-len(rows) + 0.4, 0.6)
    levels = rows[0]["effect"].split(": ", 1)[-1] if rows else ""
    ax.set_xlabel(f"effect ({levels}) in units of its own 95% half-interval")
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout(rect=(0, 0, 0.74, 1))
    return fig
