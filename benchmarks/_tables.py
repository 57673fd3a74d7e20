"""The markdown tables the docs quote of an analysed study, made from its run directory's tables
(one home: `benchmarks/lab_study.py` prints them, `benchmarks/docs_figures.py` checks the docs
against them)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq


def _pct(g: dict, rate: str) -> str:
    return f"{100 * g[rate + '_rate']:.0f}% [{100 * g[rate + '_low']:.0f}, {100 * g[rate + '_high']:.0f}]"


def _tables(run: Path) -> tuple[list[dict], list[dict]]:
    return (
        pq.read_table(run / "analysis_groups.parquet").to_pylist(),
        pq.read_table(run / "analysis.parquet").to_pylist(),
    )


def calibration_table(run: Path, truth: Callable[[dict], bool] | None = None) -> str:
    """Per group and method: SPEC 10's W, its rule and twins, the twins' stated FP / FN rates at W,
    the runs with feedforward at W, and (given each run's truth) the errors made."""
    groups, rows = _tables(run)
    head = "| group | method | W (rule, twins) | twins' FP / FN at W | feedforward at W |"
    lines = [head + (" errors made |" if truth else ""), "|---" * (5 + bool(truth)) + "|"]
    for g in groups:
        mine = [r for r in rows if r["group"] == g["group"] and r["method"] == g["method"]]
        rule = g["w_rule"] + (": uncertain" if g["uncertain"] else "")
        rates = f"{_pct(g, 'fp')} / {_pct(g, 'fn')}"
        line = (f"| {g['group']} | {g['method']} | {g['w']:.3g} ({rule}, {g['ff_twin']}) | {rates} | "
                f"{g['n_feedforward_at_w']} of {g['n_runs']} |")  # fmt: skip
        if truth:
            wrong = [r for r in mine if r["feedforward_at_w"] != truth(r)]
            kind = "misses" if mine and truth(mine[0]) else "false"
            line += f" {len(wrong)} {kind} |" if wrong else " none |"
        lines.append(line)
    return "\n".join(lines)


def evidence_table(run: Path, truth: Callable[[dict], bool] | None = None) -> str:
    """Per group and method: each run's own test (SPEC 11): the statistic that decides, the FB
    twins drawn, the runs at p <= alpha with the binomial p of that count, then per statistic (W*,
    the Fourier coefficients' size, the likelihood ratio) the runs its own p puts at p <= alpha
    (a statistic that does not decide has the calibration's FB twins only) and its median power,
    and the verdict; with each run's truth, the runs' truth."""
    groups, rows = _tables(run)
    head = ("| group | method | decided by | FB twins drawn | runs at p <= alpha (binomial p) | truth | "
            "at p <= alpha: W*, Fourier, LR | median power: W*, Fourier, LR | verdict |")  # fmt: skip
    if truth is None:
        head = head.replace(" truth |", "")
    lines = [head, "|---" * head.count(" | ") + "|---|"]
    stems = ("w_star", "fourier", "lr")
    for g in groups:
        mine = [r for r in rows if r["group"] == g["group"] and r["method"] == g["method"]]
        k = sum(r["p_value"] <= g["alpha"] for r in mine)
        found = ", ".join(str(sum(r[f"p_{c}"] <= g["alpha"] for r in mine)) for c in stems)
        powers = ", ".join(f"{np.median([r[f'power_{c}'] for r in mine]):.2f}" for c in stems)
        fact = "" if truth is None else f" {'feedforward' if mine and truth(mine[0]) else 'none'} |"
        lines.append(
            f"| {g['group']} | {g['method']} | {g['decided_by']} | "
            f"{g['fb_twins']} | {k} of {len(mine)} ({g['binomial_p']:.2g}) |{fact} {found} | {powers} | "
            f"{g['verdict']} |"
        )
    return "\n".join(lines)


def remnant_shares(run: Path, method: str = "direct") -> str:
    """The range of the remnant's share of var(u) over a study's runs: from the data alone and from
    the fitted model (`remnant_share_data`, `share_remnant`)."""
    rows = [r for r in pq.read_table(run / "analysis.parquet").to_pylist() if r["method"] == method]
    parts = []
    for column in ("remnant_share_data", "share_remnant"):
        x = np.array([r[column] for r in rows], dtype=float)
        x = x[np.isfinite(x)]
        parts.append(f"{100 * x.min():.0f}% to {100 * x.max():.0f}%" if x.size else "none")
    return " | ".join(parts)


#: The session findings the docs quote, as (row name, finding, source, quantity, band, format).
_SESSION_ROWS = (
    ("\\|Ht Yc\\| from 0.25 Hz, single-input trials", "model inversion", "single-input trials",
     "|Ht Yc| median over people", "from 0.25 Hz", "range"),
    ("\\|Ht Yc\\| from 0.25 Hz, two-input trials", "model inversion", "two-input trials",
     "|Ht Yc| median over people", "from 0.25 Hz", "range"),
    ("\\|Ht Yc\\| up to 0.15 Hz, single-input", "model inversion", "single-input trials",
     "|Ht Yc| median over people", "up to 0.15 Hz", "range"),
    ("\\|Ht Yc\\| up to 0.15 Hz, two-input", "model inversion", "two-input trials",
     "|Ht Yc| median over people", "up to 0.15 Hz", "range"),
    ("superposition U/R, magnitude single/two, pooled", "superposition", "single-input / two-input trials",
     "U/R magnitude ratio", "pooled over lines", "p"),
    ("superposition U/D, magnitude, pooled", "superposition", "single-input / two-input trials",
     "U/D magnitude ratio", "pooled over lines", "p"),
    ("superposition U/D, phase, pooled", "superposition", "single-input / two-input trials",
     "U/D phase difference deg", "pooled over lines", "deg"),
    ("prediction error ratio (FF+FB over FB), single -> two-input, at the lines", "prediction",
     "single-input trials -> two-input trials", "error ratio at the lines", "lines", "range"),
    ("the same over the whole window", "prediction", "single-input trials -> two-input trials",
     "error ratio (feedback and feedforward / feedback only)", "window", "range"),
)  # fmt: skip
#: What the study's README reports for each row (7 people), quoted, not computed.
_STUDY = ("0.54 (`fo`), 0.59 (`so`)", "", "about 1", "", "not significant", "not significant",
          "not significant", "about 0.5", "")  # fmt: skip


def session_table(fo: Path, so: Path) -> str:
    """The study's findings on both plants from two session runs' `session_findings.parquet`
    (SPEC 12), over all people: the median [range over people], or the pooled test's p."""
    from hcid.pipeline.sessions import ALL_PEOPLE

    found = {}
    for plant, run in (("fo", fo), ("so", so)):
        rows = pq.read_table(run / "session_findings.parquet").to_pylist()
        found[plant] = [r for r in rows if r["person"] == ALL_PEOPLE]
    lines = ["| | hcid `fo` | hcid `so` | study (7 people) |", "|---|---|---|---|"]
    for (name, finding, source, quantity, band, form), study in zip(_SESSION_ROWS, _STUDY, strict=True):
        cells = []
        for plant in ("fo", "so"):
            r = next(
                r for r in found[plant]
                if (r["finding"], r["source"], r["quantity"], r["band"]) == (finding, source, quantity, band)
            )  # fmt: skip
            if form == "range":
                cells.append(f"{r['estimate']:.2f} [{r['low']:.2f}, {r['high']:.2f}]")
            elif form == "p":
                cells.append(f"{r['estimate']:.2f}, p = {r['p']:.2g}")
            else:
                cells.append(f"{r['estimate']:.1f} deg, p = {r['p']:.2g}")
        lines.append(f"| {name} | {' | '.join(cells)} | {study} |")
    return "\n".join(lines)


def feedforward_by_person(fo: Path, so: Path) -> str:
    """Per plant and person (`--by subject`): the verdict and the runs at p <= alpha of each method
    (direct; indirect), and over all runs the count with its binomial p."""
    from hcid.selection.calibration import binomial_summary

    runs = {plant: _tables(run) for plant, run in (("fo", fo), ("so", so))}
    people = sorted({g["group"].split("=", 1)[1] for g in runs["fo"][0]})
    lines = [f"| | {' | '.join(people)} | all runs (binomial p) |", "|---" * (len(people) + 2) + "|"]
    for plant, (groups, rows) in runs.items():
        cells = []
        for person in people:
            mine = [g for g in groups if g["group"] == f"subject={person}"]
            cells.append("; ".join(f"{g['verdict']} {g['n_evidence']}/{g['n_runs']}" for g in mine))
        overall = []
        for method in ("direct", "indirect"):
            p = np.array([r["p_value"] for r in rows if r["method"] == method])
            k, n, binom = binomial_summary(p, groups[0]["alpha"])
            overall.append(f"{k}/{n} ({binom:.2g})")
        lines.append(f"| `{plant}` | {' | '.join(cells)} | {'; '.join(overall)} |")
    return "\n".join(lines)
