"""3-4. VAF and nb_ft of the selected models over W (paper Figs. 5, 6), with the thresholds."""

from __future__ import annotations

from dataclasses import dataclass

from hcid import tables
from hcid.config import paper
from hcid.report import compute as calc
from hcid.report import figures
from hcid.report.document import Doc
from hcid.report.run import marks_for_plot

TITLE = "3. Model fit vs W"


@dataclass(frozen=True)
class CurvesData:
    curves: calc.Curves
    criterion_marks: dict[str, float]
    threshold_marks: dict[str, float]
    criterion_labels: list[str]
    thresholds: list[dict]
    is_paper: bool = True


def compute(run, done) -> CurvesData | None:
    if run.selection is None:
        return None
    marks = run.criterion_marks()
    threshold_marks = {}
    rows = run.thresholds.to_pylist() if run.thresholds is not None else []
    for r in rows:
        if r["w_fp"] is not None:
            threshold_marks[f"W_FP {r['method']}"] = r["w_fp"]
        if r["w_fn"] is not None:
            threshold_marks[f"W_FN {r['method']}"] = r["w_fn"]
    return CurvesData(
        curves=calc.compute_curves(run.selection),
        criterion_marks=marks_for_plot(marks),
        threshold_marks=threshold_marks,
        criterion_labels=list(marks),
        thresholds=rows,
        is_paper=paper.is_paper_experiment(run.config),
    )


def render(data: CurvesData | None, doc: Doc) -> None:
    doc.text(f"## {TITLE}" + (" (paper Fig. 5)" if data is not None and data.is_paper else ""))
    if data is None:
        doc.text("_Missing: `selection.parquet` (run `hcid sweep-w`)._")
        return
    doc.figure(
        "vaf_vs_w.png",
        "Mean VAF (estimation rows) +- one sd of the selected models over the realizations; "
        "the configured criteria's W marked.",
        lambda: figures.plot_vaf(data.curves, data.criterion_marks),
    )
    doc.text("## 4. Feedforward found vs W" + (" (paper Fig. 6)" if data.is_paper else ""))
    doc.figure(
        "nb_ft_vs_w.png",
        "Mean nb_ft of the selected models. FB: any nb_ft > 0 is a false "
        "positive; FF: a mean below 2 is a false negative.",
        lambda: figures.plot_nb_ft(data.curves, data.threshold_marks),
    )
    if data.thresholds:
        # The criteria's W columns (w_aic, ...), not the thresholds' sampling columns (w_fn_low, ...).
        columns = [
            c
            for c in data.thresholds[0]
            if c.startswith("w_") and c not in ("w_fp", "w_fn") and c not in tables.UNCERTAINTY_COLUMNS
        ]
        paper_column = ["paper"] if data.is_paper else []  # another experiment: no paper figure
        doc.table(
            ["method", "model", "Nf", *(c.upper() for c in columns), "W_FP", "W_FN", *paper_column],
            [
                [
                    r["method"],
                    r["model"],
                    str(r["nf"]),
                    *(f"{r[c]:.3g}" if r[c] is not None else "-" for c in columns),
                    "-" if r["w_fp"] is None else f"{r['w_fp']:.3g}",
                    "-" if r["w_fn"] is None else f"{r['w_fn']:.3g}",
                    *([_paper_threshold(r)] if data.is_paper else []),
                ]
                for r in data.thresholds
            ],
        )


def _paper_threshold(row: dict) -> str:
    if row["has_feedforward"]:
        return f"W_FN {paper.W_FN:g}"
    ref = paper.W_FP.get(row["method"])
    return f"W_FP {ref:.2g}" if ref is not None else "-"
