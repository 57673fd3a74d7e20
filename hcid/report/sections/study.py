"""A measured study's answer (``hcid analyse``): per group, feedforward or not at the calibrated W
and how sure, the parameters, the twins' calibration and the model-free estimates."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa

from hcid import results, tables
from hcid.report import figures, figures_hcfit
from hcid.report.document import Doc
from hcid.tables import HC_PARAMETER_NAMES

TITLE = "The study's answer"


@dataclass(frozen=True)
class StudyData:
    answers: list[list[str]]
    uncertain: list[str]
    parameters: list[list[str]]
    runs_header: list[str]
    runs: list[list[str]]
    calibrations: list[tuple[str, str, str, pa.Table, dict]] = field(default_factory=list)
    fc: list[tuple[str, str, dict, dict]] = field(default_factory=list)
    fc_problems: list[str] = field(default_factory=list)


def _num(x, digits: int = 3) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _pct(rate: float, low: float, high: float) -> str:
    return f"{100 * rate:.0f}% [{100 * low:.0f}, {100 * high:.0f}]"


def _slug(folder: str) -> str:
    """A group's name for its figure files: its twins folder's (unique per group)."""
    return folder.rsplit("/", 1)[-1]


def _model_curves(run, twin: dict, lines: list[float]) -> dict:
    """The group's fitted model (the FF twin's parameters) on a dense grid around the forcing
    lines (half the lowest to 1.5 times the highest): omega, He, Ht."""
    from hcid.hcfit import hc_response
    from hcid.hcmodel import plant

    top = min(1.5 * max(lines), np.pi * run.config.timing.output_rate)
    omega = np.geomspace(0.5 * min(lines), top, 300)
    # The group's own fitted model as fc_estimates.parquet's model columns have it: the twins'
    # feedback (the group's own) and the group's own feedforward path (fitted_<p>).
    values = {p: twin.get(f"fitted_{p}", twin[f"twin_{p}"]) for p in HC_PARAMETER_NAMES}
    hft, he = hc_response(values, plant(run.config.loop), omega)
    return {"omega": omega, "e": he, "ft": hft if values["Kpt"] > 0 else None}


def compute(run, done) -> StudyData | None:
    groups, runs = run.analysis_groups, run.analysis
    if groups is None or runs is None:
        return None
    answers, uncertain, parameters = [], [], []
    rows = runs.to_pylist()
    for g in groups.to_pylist():
        safe = f"[{_num(g['safe_low'])}, {_num(g['safe_high'])})" if not g["uncertain"] else "none"
        answers.append(
            [g["group"], g["method"], f"{g['n_feedforward']} of {g['n_runs']}", _num(g["w"]), g["w_rule"],
             "own" if g["ff_twin"] == "own" else f"study's FF (Kpt {_num(g['twin_Kpt'], 2)})",
             safe, _pct(g["fp_rate"], g["fp_low"], g["fp_high"]),
             _pct(g["fn_rate"], g["fn_low"], g["fn_high"]), "UNCERTAIN" if g["uncertain"] else "yes"]
        )  # fmt: skip
        if g["uncertain"]:
            uncertain.append(f"{g['group']} ({g['method']})")
        mine = [r for r in rows if r["group"] == g["group"] and r["method"] == g["method"]]
        for p in HC_PARAMETER_NAMES:
            x = np.array([r[p] for r in mine], dtype=float)
            se = np.array([r[f"{p}_se"] for r in mine], dtype=float)
            if not np.isfinite(x).any():
                continue
            spread = float(np.nanstd(x, ddof=1)) if np.isfinite(x).sum() > 1 else math.nan
            parameters.append(
                [g["group"], g["method"], p, str(int(np.isfinite(x).sum())), _num(float(np.nanmedian(x))),
                 _num(spread, 2), _num(float(np.nanmedian(se)), 2) if np.isfinite(se).any() else "-"]
            )  # fmt: skip
    factors = [c for c in runs.column_names if c not in tables.ANALYSIS.names]
    header = ["seed (run)", *factors, "method", "nb_ft", "feedforward", "Kpt", "Kpe", "tau_pe", "w_nms",
              "zeta_nms", "wc rad/s", "PM deg", "VAF %"]  # fmt: skip
    table_rows = []
    for r in rows:

        def with_se(p, r=r):
            """The estimate with its se; * where it has none although fitted (on a bound)."""
            if not math.isfinite(r[p]):
                return "-"
            return _num(r[p]) + (f" ± {_num(r[p + '_se'], 2)}" if math.isfinite(r[p + "_se"]) else "*")

        table_rows.append(
            [str(r["seed"]), *[str(r[f]) for f in factors], r["method"], str(r["nb_ft"]),
             ("yes" if r["feedforward"] else "no") + (" (uncertain)" if r["uncertain"] else ""),
             with_se("Kpt"), with_se("Kpe"), with_se("tau_pe"), with_se("w_nms"), with_se("zeta_nms"),
             _num(r["crossover"]), _num(r["phase_margin"]), _num(r["vaf_validation"])]
        )  # fmt: skip
    calibrations = []
    group_rows = groups.to_pylist()
    # Each group's twins: its own (calibrated unless --ff-twin study) and, where they were not
    # separated or with --ff-twin study, the study's feedforward on its feedback; the W marked
    # where it is not a safe interval's.
    folders = {(g["group"], g["twins_folder"].removesuffix("-study")): None for g in group_rows}
    folders.update({(g["group"], g["twins_folder"]): None for g in group_rows})
    for name, folder in folders:
        table = results.read_optional(tables.CALIBRATION, run.run_dir / folder)
        mine = [g for g in group_rows if g["group"] == name and g["twins_folder"] == folder]
        used = {g["method"]: g["w"] for g in mine if g["w_rule"] != "safe interval"}
        if folder.endswith("-study"):
            kpt = next((g["twin_Kpt"] for g in mine), math.nan)
            title = f"{name}, study's FF"
            twins = f"twins with the study's strongest feedforward (Kpt {_num(kpt, 2)}) on its own feedback"
        else:
            title, twins = name, "twins of its own fitted model"
        methods = ", ".join(g["method"] for g in mine) or "no method (no W separates them, below)"
        if table is not None:
            calibrations.append((title, f"{name}, {twins}, used for {methods}", folder, table, used))
    fc, problems = [], []
    if run.fc_estimates is not None:
        for name in dict.fromkeys(run.fc_estimates.column("group").to_pylist()):
            t = [r for r in run.fc_estimates.to_pylist() if r["group"] == name]
            if t[0]["problem"]:
                problems.append(f"{name}: {t[0]['problem']}")
                continue
            twin = next(g for g in group_rows if g["group"] == name)
            by_path = {path: [r for r in t if r["path"] == path] for path in ("e", "ft")}
            curves = _model_curves(run, twin, [r["omega"] for r in t])
            fc.append((name, twin["twins_folder"].removesuffix("-study"), by_path, curves))
    return StudyData(answers, uncertain, parameters, header, table_rows, calibrations, fc, problems)


def render(data: StudyData | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    doc.text(
        "Per group of runs and method: feedforward (nb_ft > 0) in how many runs at the group's W, "
        "calibrated on twins of the group's own fitted model (FF twin) and the same without "
        "feedforward (FB twin), with the twins' false-positive and false-negative rates there and "
        "their exact 95% bands. Where no W separates a group's own twins (nobody there uses "
        "feedforward, or too little to tell), its FF twin takes the feedforward path of the group "
        'with the strongest ("study\'s FF"): would feedforward of that size be found here? Where '
        "no W separates the twins used, W is the grid's least total error and the decisions are "
        "**uncertain**."
    )
    doc.table(
        ["group", "method", "feedforward in", "W", "rule", "FF twin", "safe interval", "twins' FP at W",
         "twins' FN at W", "decided"],
        data.answers,
    )  # fmt: skip
    if data.uncertain:
        doc.text(
            "**No W separates the twins of** " + "; ".join(data.uncertain) + ": the feedforward decisions "
            "there cannot be trusted at any W (the group's fitted feedforward is too weak, or its "
            "feedback twin finds feedforward too often)."
        )
    for title, caption, folder, table, used in data.calibrations:
        what = (
            "the W used, the least total error: no W is safe"
            if used
            else "the safe interval and its recommended W where there is one"
        )
        doc.figure(
            f"calibration_{_slug(folder)}.png",
            f"{caption}: the twins' FP and FN rates over W (exact 95% bands), {what}.",
            lambda t=table, n=title, u=used: figures.plot_calibration(t, n, used=u),
        )
    doc.text(
        "Parameters per group (SPEC 8): median and spread over the runs, and the runs' median standard error."
    )
    doc.table(
        ["group", "method", "parameter", "runs", "median", "sd over runs", "median se"], data.parameters
    )
    for name, folder, paths, curves in data.fc:
        doc.figure(
            f"fc_{_slug(folder)}.png",
            f"{name}: model-free (Fourier-coefficient) estimates of both paths at the forcing lines, "
            "the group's coefficient average with its spread across runs (points), and the group's "
            "fitted parametric model (lines; Ht only where its fitted Kpt is above 0).",
            lambda p=paths, n=name, c=curves: figures_hcfit.plot_fc(p, c, title=n),
        )
    for problem in data.fc_problems:
        doc.text(f"No model-free estimate for {problem}.")
    doc.text(
        "Every run (`analysis.csv` holds all columns, one row per run and method, ready for a "
        "repeated-measures ANOVA or a mixed model):"
    )
    doc.table(data.runs_header, data.runs)
