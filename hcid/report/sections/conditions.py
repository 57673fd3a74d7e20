"""A whole experiment's conditions combined per person (SPEC 12; ``hcid analyse`` on a session
folder): the kinds of trial, the files left out, the model inversion |Ht Yc| and He per person at
every line, and the study's comparisons (superposition, prediction across conditions)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from matplotlib.figure import Figure

from hcid.analysis.conditions import ANSWERS, SOURCES, Kind
from hcid.config.fit_settings import FEEDBACK_PARAMETERS
from hcid.io.datasets import skipped_by_reason
from hcid.pipeline.evidence import determines, summarise_parameters
from hcid.pipeline.sessions import ALL_PEOPLE, BANDS
from hcid.report.document import Doc
from hcid.report.figures import plain_log
from hcid.tables import PARAMETER_UNITS

TITLE = "A whole experiment: every condition, combined per person"


@dataclass(frozen=True)
class ConditionsData:
    kinds: list[list[str]]
    skipped: list[list[str]]
    inversion: list[list[str]]
    superposition: list[list[str]]
    superposition_lines: list[list[str]]
    prediction: list[list[str]]
    feedback: tuple[list[str], list[list[str]]] = ([], [])
    curves: dict = field(default_factory=dict)  # source -> person -> (hz, |Ht Yc|, |He| dB, measured)
    people: int = 0
    name: str = ""


def _range(r: dict, digits: int = 2) -> str:
    if not math.isfinite(r["estimate"]):
        return "-"
    if r["n"] == 1 or r["low"] == r["high"]:  # one person, pair or trial: no range to show
        return f"{r['estimate']:.{digits}f}"
    return f"{r['estimate']:.{digits}f} [{r['low']:.{digits}f}, {r['high']:.{digits}f}]"


def _p(p: float) -> str:
    return "-" if not math.isfinite(p) else f"{p:.2g}" if p >= 1e-4 else "< 1e-4"


def _skipped(run) -> list[list[str]]:
    """The files left out, by reason: how many, and the first two."""
    if run.skipped is None or run.skipped.num_rows == 0:
        return []
    by_reason = skipped_by_reason([(r["file"], r["reason"]) for r in run.skipped.to_pylist()])
    return [
        [
            reason,
            str(len(files)),
            ", ".join(f.rsplit("/", 1)[-1] for f in files[:2]) + (", ..." if len(files) > 2 else ""),
        ]
        for reason, files in by_reason.items()
    ]


def compute(run, done) -> ConditionsData | None:
    if run.session_findings is None or run.session_trials is None:
        return None
    trials = run.session_trials.to_pylist()
    counts = {k: sum(t["kind"] == k.value for t in trials) for k in Kind}
    kinds = [[k.value, str(n), ANSWERS[k]] for k, n in counts.items() if n]
    findings = run.session_findings.to_pylist()
    people = sorted({r["person"] for r in findings if r["person"] != ALL_PEOPLE})
    inversion = []
    for source in SOURCES:
        row = [source]
        for band in BANDS:
            r = next(
                (
                    f
                    for f in findings
                    if f["finding"] == "model inversion"
                    and f["person"] == ALL_PEOPLE
                    and f["source"] == source
                    and f["band"] == band
                ),
                None,
            )
            row += [_range(r), _p(r["p"])] if r else ["-", "-"]
        per_person = [
            f"{f['person']} {f['estimate']:.2f}"
            for f in findings
            if f["finding"] == "model inversion"
            and f["person"] != ALL_PEOPLE
            and f["source"] == source
            and f["band"] == list(BANDS)[-1]
        ]
        inversion.append(row + ["; ".join(per_person) or "-"])
    superposition = [
        [r["quantity"], _range(r, 1 if "phase" in r["quantity"] else 2), _p(r["p"]), str(r["n"])]
        for r in findings
        if r["finding"] == "superposition" and r["band"]
    ]
    per_line: dict[float, list[str]] = {}
    for r in findings:
        if r["finding"] == "superposition" and not r["band"] and r["quantity"].endswith("ratio"):
            row = per_line.setdefault(r["omega"], [f"{r['omega']:.3g}", "-", "-", "-", "-"])
            at = 1 if r["quantity"].startswith("U/R") else 3
            row[at : at + 2] = [_range(r), _p(r["p"])]
    superposition_lines = [per_line[w] for w in sorted(per_line)]
    prediction = [
        [r["source"], r["quantity"], r["band"], _range(r), r["spread"], str(r["n"])]
        for r in findings
        if r["finding"] == "prediction" and r["person"] == ALL_PEOPLE
    ]
    curves: dict = {}
    if run.session_lines is not None:
        for r in run.session_lines.to_pylist():
            c = curves.setdefault(r["source"], {}).setdefault(
                r["person"], {"hz": [], "inv": [], "he": [], "measured": []}
            )
            c["hz"].append(r["hz"])
            c["inv"].append(r["inversion"])
            c["he"].append(r["he_db"])
            c["measured"].append(r["he_measured"])
    return ConditionsData(
        kinds,
        _skipped(run),
        inversion,
        superposition,
        superposition_lines,
        prediction,
        _feedback(run),
        curves,
        len(people),
        run.config.name,
    )


def _feedback(run) -> tuple[list[str], list[list[str]]]:
    """Per person, the disturbance-only runs' feedback alone: each parameter's median over the
    runs that determine it (and how many), the loop's crossover, each method's ARX VAF."""
    if run.feedback_runs is None:
        return [], []
    rows = run.feedback_runs.to_pylist()
    methods = list(dict.fromkeys(r["method"] for r in rows))
    header = ["person", "runs"]
    header += [f"{p} ({PARAMETER_UNITS[p]})" if PARAMETER_UNITS[p] != "-" else p for p in FEEDBACK_PARAMETERS]
    header += ["crossover (rad/s; runs that determine Kpe)"] + [f"VAF {m} (%)" for m in methods]
    out = []
    for person in sorted({r["person"] for r in rows}):
        mine = [r for r in rows if r["person"] == person]
        first = list({r["run_id"]: r for r in mine}.values())
        cells = [person, str(len(first))]
        kept = {s.name: s for s in summarise_parameters(first, FEEDBACK_PARAMETERS) if s.kept}
        cells += [f"{kept[p].median:.3g} ({kept[p].kept})" if p in kept else "-" for p in FEEDBACK_PARAMETERS]
        loop = [r["crossover"] for r in first if determines(r, "Kpe") and math.isfinite(r["crossover"])]
        cells.append(f"{np.median(loop):.3g}" if loop else "-")
        for method in methods:
            cells.append(f"{np.median([r['vaf_validation'] for r in mine if r['method'] == method]):.0f}")
        out.append(cells)
    return header, out


def plot_inversion(curves: dict, title: str, axes=None):
    """|Ht Yc| (top, the exact inverse at 1) and |He| (dB, bottom) per person (thin) and their
    median (thick) over frequency, one column per source of trials."""
    sources = [s for s in SOURCES if s in curves]
    if axes is None:
        fig = Figure(figsize=(4.2 * len(sources), 6.0))
        ax = fig.subplots(2, len(sources), squeeze=False, sharex=True)
    else:
        ax = np.asarray(axes, dtype=object).reshape(2, len(sources))
        fig = ax.flat[0].figure
    for j, source in enumerate(sources):
        for person, c in sorted(curves[source].items()):
            median = person == "median"
            style = (
                {"color": "k", "lw": 2.2, "marker": "o", "ms": 4}
                if median
                else {"lw": 0.9, "marker": ".", "alpha": 0.8}
            )
            hz = np.array(c["hz"])
            ax[0, j].plot(hz, c["inv"], label=person, **style)
            ax[1, j].plot(hz, c["he"], label=person, **style)
            if not median:
                open_ = ~np.array(c["measured"])
                ax[1, j].plot(hz[open_], np.array(c["he"])[open_], "o", mfc="none", color="0.4", ms=7)
        ax[0, j].axhline(1.0, color="tab:red", ls="--", lw=1.2, label="exact inverse")
        for low, high in BANDS.values():
            edge = high if math.isfinite(high) else low
            ax[0, j].axvline(edge, color="0.6", ls=":", lw=0.8)
        ax[0, j].set_title(source, fontsize=10)
        ax[0, j].set_ylim(bottom=0.0)
        ax[1, j].set_xscale("log")
        plain_log(ax[1, j].xaxis)
        ax[1, j].set_xlabel("frequency (Hz)")
    ax[0, 0].set_ylabel("|Ht Yc| (1: the plant's inverse)")
    ax[1, 0].set_ylabel("|He| (dB)")
    ax[0, -1].legend(fontsize=7, loc="upper right")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def render(data: ConditionsData | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    doc.text(
        "Every run's kind comes from its data (SPEC 12): an input is absent where its power at every "
        "forcing line is below 1e-6 of the other's. Only runs with both a target and a disturbance are "
        "tested for feedforward above; every run, whatever its kind, is combined here per person from "
        "its Fourier coefficients: U/D at the disturbance lines gives the feedback He, U/R at the "
        "target lines then the feedforward Ht = U/R (1 + He Yc) - He, and |Ht Yc| = 1 is the plant's "
        "exact inverse. He at a line comes from the trials that measured it as a disturbance line "
        "(interpolated only where none did: open circles)."
    )
    doc.table(["kind of run", "runs", "what it answers"], data.kinds)
    if data.skipped:
        doc.text("**Files left out** (not runs; every one in `skipped.parquet` with its reason):")
        doc.table(["why", "files", "e.g."], data.skipped)
    doc.text(
        "**Model inversion** |Ht Yc| per source of trials: the median over people of each person's "
        "median over the band's lines [range over people], and a Wilcoxon signed-rank test of "
        "log |Ht Yc| against 0 (the exact inverse) over every person's lines in the band."
    )
    header = ["trials"]
    for band in BANDS:
        header += [f"|Ht Yc| {band}", f"p vs 1 ({band})"]
    doc.table([*header, f"per person, {list(BANDS)[-1]}"], data.inversion)
    if data.curves:
        doc.figure(
            "conditions_inversion.png",
            f"{data.name}: the model inversion |Ht Yc| (top; dashed: the plant's exact inverse) and the "
            "feedback |He| (bottom) at every line, per person (thin) and their median (thick), from "
            "every trial, the two-input trials alone and the single-input trials alone. Dotted: the "
            "study's bands (up to 0.15 Hz, from 0.25 Hz).",
            lambda c=data.curves, n=data.name: plot_inversion(c, n),
        )
    if data.feedback[1]:
        doc.text(
            "**Feedback alone** (disturbance-only runs: no target, so no feedforward test): per "
            "person the median of each fitted parameter over the runs that determine it (how many), "
            "the loop's crossover (rad/s), and each method's ARX model without the target path at "
            "W_BIC (validation VAF, %); every run in `feedback_runs.parquet`."
        )
        doc.table(*data.feedback)
    if data.superposition:
        doc.text(
            "**Superposition**: each person's single-input estimate (target-only trials for U/R, "
            "disturbance-only for U/D) against their two-input one, paired across people: the median "
            "ratio single/two [range over the pairs] and the Wilcoxon signed-rank test, pooled over "
            "every person's lines, then per line"
            + (
                f" (with {data.people} people a line's test cannot go below {2 / 2**data.people:.2g})."
                if data.people > 1
                else " (one person: no test per line)."
            )
        )
        doc.table(["quantity (pooled over lines)", "median [range]", "p", "pairs"], data.superposition)
        doc.table(
            ["line (rad/s)", "U/R ratio [range]", "p", "U/D ratio [range]", "p"], data.superposition_lines
        )
    if data.prediction:
        doc.text(
            "**Prediction across conditions**: each trial's u predicted from its measured ft and e by "
            "the person's model from the other kind of trials (u_hat = Ht ft + He e at the lines): the "
            "error RMS(u - u_hat) / RMS(u) of the model with feedforward over that of feedback alone "
            "(Ht = 0), over the window (the remnant off the lines counts against both) and at the "
            "lines; disturbance-only trials (no target: both models alike) left out."
        )
        doc.table(["model -> trials", "quantity", "where", "median [range]", "spread", "n"], data.prediction)
