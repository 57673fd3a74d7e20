"""A measured study's answer (``hcid analyse``): per group, feedforward or not at the calibrated W
and how sure, the parameters, the twins' calibration and the model-free estimates."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa

from hcid import tables
from hcid.hcfit.consistency import CONTRADICTED, format_p
from hcid.io import results
from hcid.pipeline.evidence import FEEDFORWARD
from hcid.pipeline.summary import has_safe_interval, rate_interval, summarise_groups
from hcid.report import figures, figures_hcfit
from hcid.report.document import Doc
from hcid.report.run_table import factor_columns, num, run_table, split_runs
from hcid.tables import HC_PARAMETER_NAMES

TITLE = "The study's answer"


@dataclass(frozen=True)
class StudyData:
    answers: list[list[str]]
    uncertain: list[str]
    parameters: list[list[str]]
    runs_header: list[str]
    runs: list[list[str]]
    calibrations: list[tuple[str, str, str, pa.Table, dict, bool]] = field(default_factory=list)
    fc: list[tuple[str, str, dict, dict]] = field(default_factory=list)
    fc_problems: list[str] = field(default_factory=list)
    checks: list[list[str]] = field(default_factory=list)
    contradicted: list[str] = field(default_factory=list)
    evidence: list[tuple[str, str, list, list, float, str]] = field(default_factory=list)
    set_aside: list[list[str]] = field(default_factory=list)
    without_paths: list[str] = field(default_factory=list)
    subjects: list[list[str]] = field(default_factory=list)
    one_person: list[str] = field(default_factory=list)
    statistics: list[list[str]] = field(default_factory=list)
    disagree: list[str] = field(default_factory=list)


def _degrees(x: float) -> str:
    """An angle in whole degrees, as the console prints it (114, not 1.1e+02)."""
    return "-" if x is None or not math.isfinite(x) else f"{x:.0f}"


def _slug(folder: str) -> str:
    """A group's name for its figure files: its twins folder's (unique per group)."""
    return folder.rsplit("/", 1)[-1]


def _group_loop(run, group: str):
    """The group's loop: with a plant per level of a factor, its runs' (a group holds one plant)."""
    factor = run.config.plant_factor
    if factor is None:
        return run.config.loop
    level = next(r[factor] for r in run.analysis.to_pylist() if r["group"] == group)
    return run.config.with_plant(level).loop


def _model_curves(run, twin: dict, lines: list[float]) -> dict:
    """The group's fitted model (the FF twin's parameters) on a dense grid around the forcing
    lines (half the lowest to 1.5 times the highest): omega, He, Ht."""
    from hcid.hcfit import hc_response
    from hcid.loop.hcmodel import plant

    top = min(1.5 * max(lines), np.pi * run.config.timing.output_rate)
    omega = np.geomspace(0.5 * min(lines), top, 300)
    # The group's own model (from what its runs determine), as fc_estimates.parquet's model columns.
    values = {p: twin[f"fitted_{p}"] for p in HC_PARAMETER_NAMES}
    hft, he = hc_response(values, plant(_group_loop(run, twin["group"])), omega)
    return {"omega": omega, "e": he, "ft": hft if values["Kpt"] > 0 else None}


def _answer(summary) -> list[str]:
    """A group and method's answer row: verdict, evidence, W and the twins' rates."""
    g = summary.group
    safe = f"[{num(g['safe_low'])}, {num(g['safe_high'])})" if has_safe_interval(g) else "none"
    return [
        g["group"],
        g["method"],
        g["verdict"],
        f"{g['n_evidence']} of {g['n_runs']}",
        num(g["binomial_p"], 2),
        num(g["median_power"], 2),
        num(g["group_power"], 2),
        f"{g['n_feedforward_at_w']} of {g['n_runs']}",
        num(g["w"]),
        g["w_rule"],
        "own" if g["ff_twin"] == "own" else f"study's FF (Kpt {num(g['twin_Kpt'], 2)})",
        safe,
        rate_interval(g["fp_rate"], g["fp_low"], g["fp_high"], long=False),
        rate_interval(g["fn_rate"], g["fn_low"], g["fn_high"], long=False),
        "UNCERTAIN" if g["uncertain"] else "certain",
    ]


def _parameter_rows(summary) -> list[list[str]]:
    """A group and method's parameters: median over the runs that determine each, and why not."""
    g, out = summary.group, []
    for p in summary.parameters:
        left_out = "; ".join(f"{n}: {why}" for why, n in p.left_out.items()) or "-"
        care = "; ".join(f"{n}: {flag}" for flag, n in p.flagged.items()) or "-"
        out.append(
            [
                g["group"],
                g["method"],
                p.name,
                p.unit,
                f"{p.kept} of {p.fitted}",
                num(p.median),
                num(p.sd, 2),
                num(p.median_se, 2),
                left_out,
                care,
            ]
        )
    return out


def _checks(groups) -> tuple[list[list[str]], list[str]]:
    """Each group's model against its data (once: the same for every method), and the groups
    whose model the data contradict."""
    checks, contradicted = [], []
    for g in groups.to_pylist():
        if g["method"] != groups.column("method")[0].as_py():
            continue  # the group's model and its runs' own fits are the same for every method
        checks.append(
            [
                g["group"],
                g["fc_verdict"],
                num(g["fc_chi2"]),
                str(g["fc_dof"]),
                format_p(g["fc_p"]),
                g["fc_spread"],
                f"{num(g['he_error_db'], 2)} dB, {_degrees(g['he_error_deg'])} deg",
                f"{num(g['ht_error_db'], 2)} dB, {_degrees(g['ht_error_deg'])} deg",
                g["twin_source"],
                g["twin_undetermined"] or "-",
            ]
        )
        if g["fc_dof"] > 0 and g["fc_p"] < CONTRADICTED:
            contradicted.append(g["group"])
    return checks, contradicted


def _calibrations(run, group_rows: list[dict]) -> list[tuple]:
    """Each group's twins: its own (calibrated unless --ff-twin study) and, where they were not
    separated or with --ff-twin study, the study's feedforward on its feedback; the W marked
    where it is not a safe interval's."""
    out = []
    folders = {(g["group"], g["twins_folder"].removesuffix("-study")): None for g in group_rows}
    folders.update({(g["group"], g["twins_folder"]): None for g in group_rows})
    for name, folder in folders:
        table = results.read_optional(tables.CALIBRATION, run.run_dir / folder)
        mine = [g for g in group_rows if g["group"] == name and g["twins_folder"] == folder]
        used = {g["method"]: g["w"] for g in mine if not has_safe_interval(g)}
        if folder.endswith("-study"):
            kpt = next((g["twin_Kpt"] for g in mine), math.nan)
            title = f"{name}, study's FF"
            twins = f"twins with the study's strongest feedforward (Kpt {num(kpt, 2)}) on its own feedback"
        else:
            title, twins = name, "twins of its own fitted model"
        methods = ", ".join(g["method"] for g in mine) or "no method (no W separates them, below)"
        if table is not None:
            out.append((title, f"{name}, {twins}, used for {methods}", folder, table, used, bool(mine)))
    return out


def _fourier(run, group_rows: list[dict]) -> tuple[list[tuple], list[str]]:
    """Each group's Fourier-coefficient estimates beside its model's curves, and the groups
    that have none (with the reason)."""
    fc, problems = [], []
    if run.fc_estimates is None:
        return fc, problems
    for name in dict.fromkeys(run.fc_estimates.column("group").to_pylist()):
        t = [r for r in run.fc_estimates.to_pylist() if r["group"] == name]
        if t[0]["problem"]:
            problems.append(f"{name}: {t[0]['problem']}")
            continue
        twin = next(g for g in group_rows if g["group"] == name)
        by_path = {path: [r for r in t if r["path"] == path] for path in ("e", "ft")}
        curves = _model_curves(run, twin, [r["omega"] for r in t])
        if not any(g["verdict"] == FEEDFORWARD for g in group_rows if g["group"] == name):
            curves["ft"] = None  # no model feedforward drawn where no method's answer shows it
        fc.append((name, twin["twins_folder"].removesuffix("-study"), by_path, curves))
    return fc, problems


def _evidence(run, summaries) -> list[tuple]:
    """Per group and method, its runs' statistics and the FB twins they were judged against."""
    if run.evidence_twins is None:
        return []
    twins, out = run.evidence_twins.to_pylist(), []
    for summary in summaries:
        g, mine = summary.group, summary.runs
        theirs = [t for t in twins if t["group"] == g["group"] and t["method"] == g["method"]]
        if mine and theirs:
            folder = _slug(g["twins_folder"].removesuffix("-study"))
            out.append((g["group"], g["method"], theirs, mine, g["alpha"], folder))
    return out


def compute(run, done) -> StudyData | None:
    groups, runs = run.analysis_groups, run.analysis
    if groups is None or runs is None:
        return None
    summaries = summarise_groups(groups, runs)
    answers = [_answer(s) for s in summaries]
    uncertain = [f"{s.group['group']} ({s.group['method']})" for s in summaries if s.group["uncertain"]]
    without_paths = [
        f"{s.group['group']} ({s.group['method']}): {s.without_paths} of {len(s.runs)} runs"
        for s in summaries
        if s.without_paths
    ]
    parameters = [row for s in summaries for row in _parameter_rows(s)]
    subjects = [
        [s.group["group"], s.group["method"], subject, f"{k} of {n}", num(p, 2) if k else "-"]
        for s in summaries
        for subject, k, n, p in s.by_subject()
    ]
    one_person = [
        f"{s.group['group']} ({s.group['method']}): {s.one_subject}" for s in summaries if s.one_subject
    ]
    statistics = [
        [s.group["group"], s.group["method"], x.name + (" (decides)" if x.deciding else ""),
         f"{x.n_evidence} of {x.n_runs}", num(x.binomial_p, 2), num(x.median_power, 2),
         num(x.group_power, 2), x.verdict]
        for s in summaries if len(s.statistics) > 1 for x in s.statistics
    ]  # fmt: skip
    disagree = [
        f"{s.group['group']} ({s.group['method']}): {s.group['decided_by']} decides {s.group['verdict']}, "
        f"the {x.name} (power {x.median_power:.2f}, its count's {x.group_power:.2f}) alone says {x.verdict}"
        for s in summaries for x in s.disagreeing
    ]  # fmt: skip
    checks, contradicted = _checks(groups)
    header, table_rows = run_table(runs)
    group_rows = groups.to_pylist()
    fc, problems = _fourier(run, group_rows)
    set_aside = (
        [[r["file"], r["reason"]] for r in run.set_aside.to_pylist()] if run.set_aside is not None else []
    )
    return StudyData(
        answers,
        uncertain,
        parameters,
        header,
        table_rows,
        _calibrations(run, group_rows),
        fc,
        problems,
        checks,
        contradicted,
        _evidence(run, summaries),
        set_aside,
        without_paths,
        subjects if len(subjects) <= _SUBJECT_ROWS else [],
        one_person,
        statistics,
        disagree,
    )


def render(data: StudyData | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    doc.text(
        "*Words used here.* A run's **W\\*** is the largest penalty W at which its selected ARX model "
        "still has a feedforward path (nb_ft > 0): the larger, the more its data ask for feedforward. "
        "**Twins** are simulations of the group's fitted HC model: the **FF twin** as fitted, the "
        "**FB twin** the same without feedforward (Kpt = 0), driven by the group's recorded forcing "
        "functions (a **forcing set**: the runs whose target and disturbance agree, or agree with both "
        "signs flipped), identified exactly as the runs are. A run's **p-value** is how often FB "
        "twins reach its statistic (W\\*, or a statistic of its forcing lines: below); the **power**, "
        "how often FF twins would be found at the level alpha. "
        "SPEC n names a section of the specification hcid follows (docs/methodology.md)."
    )
    _render_answers(data, doc)
    _render_evidence(data, doc)
    _render_checks(data, doc)
    _render_parameters(data, doc)
    (evidence_header, evidence_rows), (parameter_header, parameter_rows) = split_runs(
        data.runs_header, data.runs
    )
    doc.text(
        "Every run (`analysis.csv` holds all columns, one row per run and method, ready for a "
        "repeated-measures ANOVA or a mixed model), in two tables. First its evidence and fit: "
        "p (evidence): the run's feedforward p-value by the statistic that decides for its group "
        "(W*, the Fourier coefficients' model-free size, or LR: the likelihood ratio of the parametric "
        "fits with and without feedforward at the forcing lines); nb_ft and feedforward at W: its "
        "selection at the group's "
        "calibrated W (SPEC 10); remnant: the share of var(u) the fitted model's paths leave given "
        "the measured e (the remnant injected at u), and the remnant's share of var(u) in the closed "
        "loop from the data alone (u's power off the forcing lines; the remnant also moves e, so the "
        "two differ); data check: the p-value of the run's own model against its data. * marks a "
        "run whose two answers disagree: its own test (its W* against its FB twins, at alpha) and its "
        "selection at the one W calibrated for its whole group; a run's W* can lie below the group's W "
        "(its feedforward found by its test, lost at W) or above it by chance (kept at W, not shown "
        "by its test). The test is the run's answer."
    )
    doc.table(evidence_header, evidence_rows)
    doc.text(
        "Then its parameters: estimates ± standard error; † a value the run does not determine, "
        "without its se (the reason and the se in `analysis.csv`), ‡ a value it determines but "
        "outside the parameter's plausible range or not told from 0, (held) held at a literature value "
        "(`hc_form` nms fixed)."
    )
    doc.table(parameter_header, parameter_rows)


def _render_answers(data: StudyData, doc: Doc) -> None:
    """The files set aside, then the answer table per group and method."""
    if data.set_aside:
        doc.text(
            f"**Set aside:** {len(data.set_aside)} file(s) of the data set could not be read and are not in "
            "this analysis (`--skip-unreadable`; `set_aside.parquet`):"
        )
        doc.table(["file", "why it could not be read"], data.set_aside)
    doc.text(
        "Per group of runs and method, first the runs' own evidence (SPEC 11): each run's statistic "
        "(W*, the Fourier coefficients' size or the likelihood ratio, the one whose twins show the "
        "most power) against its forcing set's FB twins gives a p-value; the verdict is FEEDFORWARD "
        "where the number of runs at p <= alpha is itself unlikely without feedforward (binomial p), "
        "else UNCERTAIN where that count's power is below 0.8 (the chance it would be significant "
        "were every run's feedforward its FF twins', from each run's power: a finding needs no power, "
        "an answer of none does) and NO "
        "FEEDFORWARD SHOWN where it is not. Where the two methods differ, the one whose twins give the "
        "higher power is the one that can tell (the power comes from the twins alone, before the runs "
        "are read); report both. Then SPEC 10's calibrated W: feedforward (nb_ft > 0) in "
        "how many runs at the group's W, "
        "calibrated on twins of the group's own fitted model (FF twin) and the same without "
        "feedforward (FB twin), with the twins' false-positive and false-negative rates there and "
        "their exact 95% bands. Where no W separates a group's own twins (nobody there uses "
        "feedforward, or too little to tell), its FF twin takes the feedforward path of the group "
        'with the strongest ("study\'s FF"): would feedforward of that size be found here? Where '
        "no W separates the twins used, W is the grid's least total error and the decisions are "
        "**uncertain**."
    )
    doc.table(
        [
            "group",
            "method",
            "verdict",
            "runs at p <= alpha",
            "binomial p",
            "runs' median power",
            "the count's power",
            "feedforward at W",
            "W",
            "rule",
            "FF twin",
            "safe interval",
            "twins' FP at W (95% interval)",
            "twins' FN at W (95% interval)",
            "decisions at W",
        ],
        data.answers,
    )
    _render_answer_notes(data, doc)


def _render_answer_notes(data: StudyData, doc: Doc) -> None:
    """Below the answer table: verdicts resting on one person, the per-subject table, groups whose
    twins no W separates and runs that keep no path at W."""
    if data.one_person:
        doc.text(
            "**A verdict that rests on one person:** " + "; ".join(data.one_person) + ": every run "
            "at p <= alpha is that subject's (the binomial counts runs, not people)."
        )
    if data.statistics:
        doc.text(
            "Per evidence statistic, what it alone says: runs at p <= alpha, binomial p, its twins' "
            "median power, its count's power and its verdict by the same rule. The one that decides "
            "was chosen by its calibration twins' power before any run was read (its p and power are "
            "over every FB twin drawn for it, the others' over the calibration's), so another's "
            "verdict is not a test at level alpha of its own."
        )
        header = ["group", "method", "statistic", "runs at p <= alpha", "binomial p", "median power",
                  "the count's power", "alone"]  # fmt: skip
        doc.table(header, data.statistics)
    if data.disagree:
        doc.text(
            "**The statistics disagree**, each with the power to tell: " + "; ".join(data.disagree) + ". "
            "The verdict stands on the statistic chosen before the runs were read; that another, "
            "with power too, finds otherwise says the evidence depends on what is measured of the "
            "runs (the model's fit, or its selection over W): read both."
        )
    if data.subjects:
        doc.text("Per subject within each group: runs at p <= alpha and their binomial p (where any).")
        doc.table(["group", "method", "subject", "runs at p <= alpha", "binomial p"], data.subjects)
    if data.uncertain:
        doc.text(
            "**No W separates the twins of** " + "; ".join(data.uncertain) + ": the yes/no at the "
            "calibrated W (feedforward at W) cannot be trusted there, whether the group's fitted "
            "feedforward is too weak to tell from none or its FB twin keeps feedforward up to W where "
            "its FF twin loses it. The verdict (each run's p-value against its own FB twins) needs no "
            "W and stands on its stated power."
        )
    if data.without_paths:
        doc.text(
            "**At the calibrated W some runs keep no path at all** (nb_ft = nb_e = 0: the selection "
            "has dropped both paths, a W beyond what their data support): "
            + "; ".join(data.without_paths)
            + ". Their yes/no at W says nothing about feedforward; their p-values need no W."
        )


#: The most rows of the per-subject table (beyond, the console's lines and analysis.csv have them).
_SUBJECT_ROWS = 48


def _render_evidence(data: StudyData, doc: Doc) -> None:
    """Each run's evidence on its twins, then each group's calibration of W."""
    for group, method, twins, runs, alpha, folder in data.evidence:
        named = figures_hcfit.run_labels(runs, factor_columns(runs[0]) if runs else [])
        doc.figure(
            f"evidence_{folder}_{method}.png",
            f"{group}, {method} method: each run's W* (the largest W at which its selection keeps "
            "feedforward) on its own forcing set's twins: a run shows feedforward where its p-value is "
            f"at most {alpha:g} (filled). FB twins are drawn until 5 are at or above the run's W* (p = 5 "
            "over the draws: Besag and Clifford's sequential p-value), else p from the generalized Pareto "
            "tail of all drawn (SPEC 13; the Monte Carlo (1 + those at or above) / (1 + all drawn) where "
            "no tail fits: analysis.csv's p_method); the FF twins show how often such a run would be "
            "found (the power).",
            lambda t=twins, r=named, n=f"{group}, {method}", a=alpha: figures_hcfit.plot_evidence(t, r, n, a),
        )
    for title, caption, folder, table, used, in_use in data.calibrations:
        drawn = list(dict.fromkeys(table.column("method").to_pylist()))
        doc.figure(
            f"calibration_{_slug(folder)}.png",
            _calibration_caption(caption, drawn, used, in_use),
            lambda t=table, n=title, u=used: figures.plot_calibration(t, n, used=u),
        )


def _calibration_caption(caption: str, drawn: list[str], used: dict, in_use: bool) -> str:
    """A calibration figure's caption: per method drawn, what it marks (the W used where no W is
    safe, else the safe interval); for twins no method took its W from, their rates alone."""
    if not in_use:
        what = "their rates alone, for comparison (no method's W comes from these twins)"
    else:
        what = "; ".join(
            f"{m}: the W used, the least total error (no W is safe)"
            if m in used
            else f"{m}: the safe interval and its recommended W where there is one"
            for m in drawn
        )
    return f"{caption}: the twins' FP and FN rates over W (exact 95% bands), {what}."


def _render_checks(data: StudyData, doc: Doc) -> None:
    """Each group's model against its data."""
    if data.checks:
        doc.text(
            "**Do the fitted models agree with the data's own frequency response?** (SPEC 11) Each "
            "group's model (from the values its runs determine) against its runs at the forcing "
            "lines, relative to the spread across runs (spread column; a one-run group: the remnant "
            f'beside the lines): a chi-square test (p below {CONTRADICTED:g}: "contradicted by the '
            'data"), and the median |error| of He (disturbance lines) and Ht (target lines) against '
            "the Fourier-coefficient estimates. Each run's own model is tested against its remnant "
            "beside the lines (the run table's last column)."
        )
        doc.table(
            [
                "group",
                "verdict",
                "chi-square",
                "dof",
                "p",
                "spread",
                "He error",
                "Ht error",
                "model built from",
                "not determined (by any run, or by the run taken)",
            ],
            data.checks,
        )
        if data.contradicted:
            doc.text(
                "**Contradicted by the data:** the model of " + "; ".join(data.contradicted) + ". Its "
                "parameters describe a model these runs do not support as one group; read them as such. "
                "The test also rejects a group's model where its people differ from one another even "
                "when each run's own fit holds: the run table's last column tests each run."
            )


def _render_parameters(data: StudyData, doc: Doc) -> None:
    """The parameters per group and method, then the model-free estimates beside the models."""
    doc.text(
        "Parameters per group and method (SPEC 8, 11), from each run's fit at the group's W: the "
        "median and the sd over the runs that determine the parameter, and their median standard "
        "error; runs whose fit leaves it undetermined (on a "
        "search bound, a 95% interval wider than its plausible range, correlated above 0.95 with "
        "another, or a fit that describes u worse than u = 0) are left out, with their reasons; "
        "values kept but to read with care are counted in the last column."
    )
    doc.table(
        [
            "group",
            "method",
            "parameter",
            "unit",
            "runs determining",
            "median",
            "sd over runs",
            "median se",
            "left out (runs: reason)",
            "kept, read with care (runs: why)",
        ],
        data.parameters,
    )
    for name, folder, paths, curves in data.fc:
        doc.figure(
            f"fc_{_slug(folder)}.png",
            f"{name}: model-free (Fourier-coefficient) estimates of both paths at the forcing lines, "
            "the group's coefficient average (points) with its spread across runs (band: +-1 sd), "
            "and the group's model (lines; Ht only where a method answers FEEDFORWARD).",
            lambda p=paths, n=name, c=curves: figures_hcfit.plot_fc(p, c, title=n),
        )
        if paths.get("ft"):
            doc.figure(
                f"inversion_{_slug(folder)}.png",
                f"{name}: model inversion, the feedforward path times the plant (Ht Yc) at every "
                "target line, from the model-free estimates: the group's coefficient average "
                "(circles; its phase with +-1 sd across runs) and the median of the runs' own "
                "magnitudes (diamonds, bars from 25% to 75% of the runs). Where the runs' phases "
                "scatter (large remnant, or people who differ) the average falls below the runs' "
                "own, which the remnant in each run biases upward. 1 is the plant's exact inverse.",
                lambda p=paths["ft"], n=name: figures_hcfit.plot_inversion(p, title=n),
            )
    for problem in data.fc_problems:
        doc.text(f"No model-free estimate for {problem}.")
