"""4b. False-positive and false-negative rates over W, and the thresholds' sampling uncertainty (SPEC 9)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from hcid import tables
from hcid.config import paper
from hcid.report import figures
from hcid.report.document import Doc
from hcid.report.run import marks_for_plot
from hcid.report.verdicts import W_FN_RULE, W_FP_RULE
from hcid.selection import criteria
from hcid.selection.calibration import clopper_pearson

TITLE = "4b. Error rates over W and the thresholds' sampling uncertainty (SPEC 9)"

_ERROR_WORDS = {"false_positive": "FP rate (nb_ft > 0)", "false_negative": "FN rate (nb_ft < 2)"}


@dataclass(frozen=True)
class RatesData:
    table: pa.Table
    name: str
    marks: dict[str, float]
    header: list[str]
    rows: list[list[str]]
    is_paper: bool = True  # the paper's experiment: the sampling column judges its thresholds


def rate_with_band(rate: float | None, n: int) -> str:
    """``rate [low, high]`` with the exact 95% band of k = rate * n out of n."""
    if rate is None or not np.isfinite(rate):
        return "-"
    k = round(rate * n)
    low, high = clopper_pearson(np.array([k]), n)
    return f"{k}/{n} = {rate:.2f} [{low[0]:.2f}, {high[0]:.2f}]"


def _uncertainty(r: dict, is_paper: bool) -> str:
    """A threshold's sampling uncertainty: W_FN's bootstrap interval, and for the paper's
    experiment how likely its W_FP and W_FN were under this run's (another experiment's
    thresholds are not the paper's to compare with)."""
    if not is_paper:
        if r["has_feedforward"] and r.get("w_fn_low") is not None:
            return f"95% [{r['w_fn_low']:.3g}, {r['w_fn_high']:.3g}]"
        return "-"
    if not r["has_feedforward"]:
        p = r.get("p_w_fp_at_paper")
        ref = paper.W_FP.get(r["method"])
        if p is None or ref is None:
            return "-"
        return f"P(W_FP >= {ref:.2g}) = {p:.3g}"
    if r.get("w_fn_low") is None:
        return "-"
    return (
        f"95% [{r['w_fn_low']:.3g}, {r['w_fn_high']:.3g}]; "
        f"P*(W_FN >= {paper.W_FN:g}) = {r['p_w_fn_at_paper']:.3g}"
    )


def compute(run, done) -> RatesData | None:
    if run.rates is None or run.rates.num_rows == 0 or run.thresholds is None:
        return None
    is_paper = paper.is_paper_experiment(run.config)
    chosen = criteria.configured(run.config.selection.criteria)
    present = [c for c in chosen if tables.rate_column(c.column) in run.thresholds.column_names]
    rows = []
    for r in run.thresholds.to_pylist():
        n = r["n_realizations"]
        threshold = r["w_fn"] if r["has_feedforward"] else r["w_fp"]
        rows.append(
            [
                r["method"],
                r["model"],
                _ERROR_WORDS["false_negative" if r["has_feedforward"] else "false_positive"],
                ("W_FN " if r["has_feedforward"] else "W_FP ") + f"{threshold:.3g}",
                _uncertainty(r, is_paper),
                *(rate_with_band(r[tables.rate_column(c.column)], n) for c in present),
            ]
        )
    header = ["method", "model", "error", "threshold", "sampling", *(f"rate at {c.label}" for c in present)]
    marks = marks_for_plot(run.criterion_marks())
    return RatesData(run.rates, run.config.name, marks, header, rows, is_paper)


def render(data: RatesData | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    doc.text(
        "W_FP is an extreme (the largest W at which any FB realization is a false positive) and W_FN "
        "the crossing of a mean, so both move from one set of realizations to the next. Beside them: "
        "the share of realizations making the error at each W, with exact 95% (Clopper-Pearson) bands, "
        "and each threshold's sampling uncertainty. "
        + (
            "Rules: W_FP: " + W_FP_RULE + ". W_FN: " + W_FN_RULE + "."
            if data.is_paper
            else "W_FN's: its bootstrap 95% interval (2000 resamples of the realizations, seed 0); "
            "this is not the paper's experiment, so its thresholds are not compared with the paper's."
        )
    )
    doc.figure(
        "rates_vs_w.png",
        "False-positive rate of the models without feedforward and false-negative rate of the models "
        "with it, over W, with exact 95% bands over realizations; the criteria's W marked.",
        lambda: figures.plot_rates(data.table, data.marks, data.name),
    )
    doc.table(data.header, data.rows)
