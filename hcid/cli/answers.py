"""What the commands print: a short summary of each result, the answer first (the library computes;
this module only words and lays out)."""

from __future__ import annotations

import math

import typer

from hcid.config.fit_settings import FEEDFORWARD_PARAMETERS
from hcid.tables import PARAMETER_UNITS


def is_paper(cfg) -> bool:
    """Whether the paper's figures are printed beside this run's (its experiment only)."""
    from hcid.config import paper

    return paper.is_paper_experiment(cfg)


def print_simulation(result, is_paper: bool) -> None:
    import numpy as np

    from hcid.config import paper

    summary = result.summary.to_pydict()
    models = list(dict.fromkeys(summary["model"]))
    typer.echo(f"Kn = {result.kn:.6g} (remnant gain, from var(n)/var(u) in the disturbance-only task)")
    typer.echo(
        f"{'model':<8}{'seeds':>6}{'RMS(e) deg mean +- sd':>24}{'paper':>8}{'var(n)/var(u) dist-only':>26}"
    )
    for m in models:
        rows = [i for i, name in enumerate(summary["model"]) if name == m]
        rms = np.array([summary["rms_e_deg"][i] for i in rows])
        ratio = np.array([summary["noise_ratio_disturbance_only"][i] for i in rows])
        ref = paper.RMS_E_DEG.get(m) if is_paper else None
        ref_text = f"{ref:.2f}" if ref is not None else "-"
        typer.echo(
            f"{m:<8}{len(rows):>6}{rms.mean():>15.3f} +- {rms.std(ddof=1) if len(rows) > 1 else 0.0:.3f}"
            f"{ref_text:>8}{ratio.mean():>26.4f}"
        )
    typer.echo(f"wrote {result.run_dir / 'simulations.parquet'}")


def print_identification(result, is_paper: bool) -> None:
    if result.simulation is not None:
        print_simulation(result.simulation, is_paper)
    if result.imported:
        typer.echo(f"read {result.imported} measured run(s)")
    log = result.log.to_pydict()
    typer.echo(
        f"identified {result.computed} realization-methods, reused {result.reused}; "
        f"{sum(log['n_candidates']) + sum(log['stage1_candidates']):,} candidates in the tables, "
        f"{sum(log['n_unstable']) + sum(log['stage1_unstable']):,} unstable"
    )
    typer.echo(f"wrote {result.run_dir / 'frontier.parquet'}")


def print_thresholds(sweep, is_paper: bool) -> None:
    from hcid.config import paper

    rows = sweep.thresholds.to_pylist()
    typer.echo(f"{'method':<10}{'model':<8}{'threshold':<11}{'this run':>12}{'paper':>10}")
    for row in rows:
        for name in ("w_fp", "w_fn"):
            if row[name] is None:
                continue
            ref = paper.W_FP.get(row["method"]) if name == "w_fp" else paper.W_FN
            ref = ref if is_paper else None
            ref_text = f"{ref:.2g}" if ref is not None else "-"
            typer.echo(
                f"{row['method']:<10}{row['model']:<8}{name.upper():<11}{row[name]:>12.4g}{ref_text:>10}"
            )
    by_nf: dict[int, list[str]] = {}
    for row in rows:
        by_nf.setdefault(row["nf"], [])
        if row["method"] not in by_nf[row["nf"]]:
            by_nf[row["nf"]].append(row["method"])
    for nf, names in by_nf.items():
        marks = ", ".join(f"{c.label} = {c.w(nf):.4g}" for c in sweep.criteria)
        typer.echo(f"{marks} (Nf = {nf}: {', '.join(names)})")


def print_analysis(result) -> None:
    """Per group and method: the answer first (the verdict, then the counts and the evidence),
    SPEC 10's calibrated W, the parameters the runs determine, the loop, and the data check
    (SPEC 11); then what was set aside and where the tables are."""
    from hcid.pipeline.summary import summarise_groups

    if result.session is not None:
        typer.echo(_kinds_line(result.kinds))
    checked = set()  # groups whose model's data check is printed (the same for every method)
    for summary in summarise_groups(result.groups, result.runs):
        g = summary.group
        typer.echo(_verdict_line(summary))
        if summary.by_subject():
            typer.echo(_subjects_line(summary))
        if len(summary.statistics) > 1:
            typer.echo(_statistics_line(summary))
        typer.echo(_calibrated_line(summary))
        typer.echo(_analysis_parameters(summary.parameters, len(summary.runs)))
        remnant = summary.remnant_share
        remnant_text = (
            f"; remnant {100 * remnant:.0f}% of var(u) by the data" if math.isfinite(remnant) else ""
        )
        typer.echo(
            f"    loop: crossover {summary.crossover:.3g} rad/s, phase margin {summary.phase_margin:.3g} deg"
            f"{remnant_text} (medians over runs)"
        )
        typer.echo(_data_check_line(g, full=g["group"] not in checked))
        checked.add(g["group"])
    _print_session(result)
    if result.effects is not None:
        typer.echo(effects_line(result.effects.to_pylist(), float(result.groups.column("alpha")[0].as_py())))
    print_skipped(result.skipped, result.run_dir)
    if result.set_aside:
        typer.echo(
            f"SET ASIDE (--skip-unreadable): {len(result.set_aside)} file(s) could not be read and are "
            "not in this analysis (RUN/set_aside.parquet): " + "; ".join(why for _, why in result.set_aside)
        )
    typer.echo(
        f"analysed in {result.seconds:.1f} s ("
        + ", ".join(f"{name} {sec:.1f}" for name, sec in result.stages.items())
        + f"); wrote {result.run_dir / 'analysis.parquet'} (and .csv: one row "
        f"per run and method, with its factors) and {result.run_dir / 'analysis_groups.parquet'}"
    )


def _verdict_line(summary) -> str:
    """The group and method's verdict, its runs at p <= alpha and the evidence behind it."""
    g, (low, high) = summary.group, summary.power
    same = f"{low:.2f}" == f"{high:.2f}"
    power = f"{low:.2f} for every run" if same else f"{low:.2f} to {high:.2f} over the runs"
    if g["ff_twin"] == "study":  # the power is that of the study's feedforward, not the group's own
        power += f" (FF twins with the study's feedforward, Kpt {g['twin_Kpt']:.2g})"
    plural = "s" if g["forcing_sets"] > 1 else ""
    return (
        f"{g['group']}, {g['method']}: {g['verdict']}: {g['n_evidence']} of {g['n_runs']} runs show "
        f"feedforward at p <= {g['alpha']:g} (decided by their {g['decided_by']} against their own "
        f"forcing set's FB twins, up to {g['fb_twins']} drawn: the statistic with the most power; "
        f"binomial p = {g['binomial_p']:.2g}; power (FF twins found at this level) {power}, the "
        f"count's {g['group_power']:.2f}; {g['forcing_sets']} forcing set{plural})"
    )


def _subjects_line(summary) -> str:
    """Each subject's runs at p <= alpha (with the binomial p where there are any): whether the
    group's verdict rests on one person."""
    subjects, alpha = summary.by_subject(), summary.group["alpha"]
    parts = [f"{s} {k} of {n}" + (f" (binomial p = {p:.2g})" if k else "") for s, k, n, p in subjects]
    text = f"    by subject, runs at p <= {alpha:g}: " + ", ".join(parts)
    one = summary.one_subject
    if one is not None:
        text += f"; every run at p <= {alpha:g} is {one}'s: the verdict rests on one person"
    return text


def _statistics_line(summary) -> str:
    """Each evidence statistic's runs at p <= alpha and median power, the deciding one marked; where
    another with the power to tell gives another verdict, said in capitals (issue 47: on the
    recordings the statistics can disagree, each with its power)."""
    alpha = summary.group["alpha"]
    parts = [
        f"{s.name} {s.n_evidence} of {s.n_runs} (power {s.median_power:.2f}, its count's {s.group_power:.2f}"
        + ("; decides)" if s.deciding else ")")
        for s in summary.statistics
    ]
    whose = " (FF twins with the study's feedforward)" if summary.group["ff_twin"] == "study" else ""
    text = f"    per statistic, runs at p <= {alpha:g} and their twins' median power{whose}: " + ", ".join(
        parts
    )
    for s in summary.disagreeing:
        text += (
            f"; THE STATISTICS DISAGREE: the {s.name} alone, with power {s.median_power:.2f} (its "
            f"count's {s.group_power:.2f}), says "
            f"{s.verdict} ({s.n_evidence} of {s.n_runs} runs; binomial p = {s.binomial_p:.2g})"
        )
    return text


def _calibrated_line(summary) -> str:
    """SPEC 10's calibrated W: feedforward in how many runs there, how W was chosen, the twins' rates."""
    from hcid.pipeline.summary import has_safe_interval, rate_interval

    g = summary.group
    if has_safe_interval(g):
        safe = f"safe interval [{g['safe_low']:.3g}, {g['safe_high']:.3g})"
        if g["ff_twin"] == "study":
            safe += (
                f" for the study's feedforward (Kpt {g['twin_Kpt']:.2g}; this group's own fitted "
                f"Kpt is {g['fitted_Kpt']:.2g})"
            )
    elif g["uncertain"]:
        whose = " (with the study's feedforward)" if g["ff_twin"] == "study" else ""
        safe = (
            f"NO W separates the twins{whose}: W of least total error, every decision at this W "
            "UNCERTAIN (the verdict above needs no W)"
        )
    else:
        safe = (
            "no contiguous safe interval; W of least total error, where the twins' rates are "
            "within the target"
        )
    return (
        f"    calibrated W (SPEC 10): feedforward in {g['n_feedforward_at_w']} of {g['n_runs']} runs at "
        f"W = {g['w']:.3g} ({safe}; twins' FP {rate_interval(g['fp_rate'], g['fp_low'], g['fp_high'])}, "
        f"FN {rate_interval(g['fn_rate'], g['fn_low'], g['fn_high'])})" + _without_paths(summary)
    )


def _data_check_line(g: dict, *, full: bool) -> str:
    """The group's model against the data's own frequency response (in ``full`` once per group:
    the model is the same for every method), and the method's runs whose own fits it contradicts."""
    from hcid.hcfit.consistency import CONTRADICTED, p_text

    if g["fc_dof"] <= 0:
        return f"    data check: {g['fc_verdict']}"
    contradicted = (
        f"{g['n_contradicted']} of {g['n_runs']} runs' own fits at W are contradicted by the data "
        f"(p < {CONTRADICTED:g})"
    )
    if not full:
        return f"    data check: the group's model as above; {contradicted}"
    ht = ""
    if g["ht_error_db"] == g["ht_error_db"]:  # NaN without feedforward lines
        ht = f", Ht {g['ht_error_db']:.1f} dB {g['ht_error_deg']:.0f} deg"
    return (
        f"    data check: the group's model{_model_source(g)} is {g['fc_verdict']} "
        f"(chi-square {g['fc_chi2']:.1f} on {g['fc_dof']} dof, {p_text(g['fc_p'])}, spread "
        f"{g['fc_spread']}; median |error| against the Fourier-coefficient estimates He "
        f"{g['he_error_db']:.1f} dB {g['he_error_deg']:.0f} deg{ht}); {contradicted}"
    )


def _flat(reason: str) -> str:
    """A status read inside the answer's own parentheses: ``x (y)`` as ``x: y``."""
    return reason.replace(" (", ": ").removesuffix(")")


def _model_source(group: dict) -> str:
    """Where the group's model is not the medians of its runs' fits: whose it is, and why."""
    from hcid.hcfit.determined import FROM_MEDIANS

    return "" if group["twin_source"] == FROM_MEDIANS else f" ({_flat(group['twin_source'])})"


def _without_paths(summary) -> str:
    """What the calibrated W line adds where some runs' selection at W keeps no path at all."""
    n = summary.without_paths
    if not n:
        return ""
    return (
        f"; at this W {n} of {len(summary.runs)} runs keep no path at all (nb_ft = nb_e = 0): "
        "W is beyond what their data support"
    )


def _parameter_text(s, runs: int) -> str:
    """One parameter's median over the runs that determine it, of ``runs``, their sd and how many
    of them are flagged (read with care)."""
    unit = "" if s.unit == "-" else f" {s.unit}"
    sd = f", sd {s.sd:.2g}" if s.kept > 1 else ""
    care = "".join(f"; {n} of them {_flat(flag)}" for flag, n in s.flagged.items())
    return f"{s.name} {s.median:.3g}{unit} ({s.kept} of {runs} runs{sd}{care})"


def _analysis_parameters(summaries, n_runs: int | None = None) -> str:
    """The runs' fits at W (hcid.pipeline.evidence.summarise_parameters): median over the runs that
    determine each, their sd and count, units; the feedforward parameters' runs where fewer than
    the group's ``n_runs`` have them; then what some runs leave undetermined, and why."""
    parts, left_out = [], []
    for s in summaries:
        if s.kept:
            parts.append(_parameter_text(s, s.fitted))
        if s.left_out:
            several = len(s.left_out) > 1  # then each reason with its count of runs
            whys = ", ".join(
                f"{n}\u00d7 {_flat(why)}" if several else _flat(why) for why, n in s.left_out.items()
            )
            left_out.append(f"{s.name} in {sum(s.left_out.values())} of {s.fitted} runs ({whys})")
    text = "    runs' fits at W (median over the runs that determine each; sd over them): " + ", ".join(parts)
    partial = [
        s for s in summaries if n_runs is not None and s.name in FEEDFORWARD_PARAMETERS and s.fitted < n_runs
    ]
    if partial:
        text += (
            f"; {', '.join(s.name for s in partial)} fitted only in the {partial[0].fitted} of {n_runs} runs "
            "whose selection at W keeps feedforward (the others' fits have none)"
        )
    if left_out:
        text += "\n    not determined, left out: " + "; ".join(left_out)
    return text


def _num4(x: float) -> str:
    import numpy as np

    return "-" if x is None or not np.isfinite(x) else f"{x:.4g}"


def print_hc_fit(result) -> None:
    from hcid import tables

    for method, pairs in result.w_of.items():
        typer.echo(f"{method:<9} W = " + ", ".join(f"{w:.4g} ({source})" for w, source in pairs))
    rows = result.parameters.to_pylist()
    # The model column fits the longest name (a measured file's data name is often long).
    m = max([10, *(len(r["model"]) + 1 for r in rows)])
    if rows:
        typer.echo(f"target {rows[0]['target']}, standard errors {rows[0]['covariance'] or '-'}")
    # One record: its estimate with se and 95% interval; several: medians, the spread across
    # records beside the median se, and how many 95% intervals hold the true value.
    typer.echo(
        "(one record: its estimate, standard error and 95% interval; n records: the median estimate, the "
        "median se, the sd across records, how many 95% intervals hold the true value, how many on a bound)"
    )
    header = f"{'model':<{m}}{'method':<10}{'W':>9} {'parameter':<10}{'unit':<6}{'estimate':>10} {'se':>9}"
    header += f" {'sd':>9} {'95% interval':>21} {'true':>9}{'n':>5}{'covers':>7}{'bound':>6}"
    typer.echo(header)
    _print_fit_parameters(result.parameters, m)
    _print_fit_loop(result.loop.to_pylist(), m)
    written = ", ".join(str(result.run_dir / t.file) for t in (tables.HC_PARAMETERS, tables.HC_LOOP))
    typer.echo(
        f"fitted {result.computed} record-methods, reused {result.reused}, in {result.seconds:.1f} s; "
        f"wrote {written} (and residuals, remnant spectra)"
    )


def _print_fit_parameters(params, m: int) -> None:
    """One line per (model, method, W, parameter): one record's estimate, se and 95% interval, or
    over several the median estimate and se, the sd across them, the coverage and the bound hits
    (:func:`hcid.pipeline.summary.summarise_fits`)."""
    from hcid.pipeline.summary import summarise_fits

    num = _num4
    for (model, method, w, name), f in summarise_fits(params).items():
        one = f.records == 1
        median = num(f.first["estimate"]) if one else num(f.median)
        se_text = num(f.first["se"]) if one else num(f.median_se)
        sd = "-" if one else num(f.sd)
        interval = f"[{num(f.first['ci_low'])}, {num(f.first['ci_high'])}]" if one else "-"
        covers = f"{f.covered}/{f.n_se}" if math.isfinite(f.true) else "-"
        typer.echo(
            f"{model:<{m}}{method:<10}{w:>9.4g} {name:<10}{PARAMETER_UNITS.get(name, ''):<6}{median:>10} "
            f"{se_text:>9} {sd:>9} {interval:>21}"
            f" {num(f.true):>9}{f.records:>5}{covers:>7}{f.at_bound:>6}"
        )


def _print_fit_loop(loop: list[dict], m: int) -> None:
    """The loop's descriptors per (model, method, W, source), medians over records."""
    import numpy as np

    num = _num4
    if loop:
        typer.echo(
            f"{'model':<{m}}{'method':<10}{'W':>9} {'source':<8}{'wc rad/s':>9} {'PM deg':>7}"
            f" {'true wc':>8} {'true PM':>7} {'remnant':>7} {'w_n':>6} {'zeta_n':>6}  (medians)"
        )
        by: dict[tuple, list[dict]] = {}
        for row in loop:
            by.setdefault((row["model"], row["method"], row["w"], row["source"]), []).append(row)
        for (model, method, w, source), group in by.items():

            def med(c, group=group):
                x = np.array([r[c] for r in group], dtype=float)
                return num(np.nanmedian(x)) if np.isfinite(x).any() else "-"

            typer.echo(
                f"{model:<{m}}{method:<10}{w:>9.4g} {source:<8}{med('crossover'):>9} {med('phase_margin'):>7}"
                f" {med('true_crossover'):>8} {med('true_phase_margin'):>7} {med('share_remnant'):>7}"
                f" {med('remnant_w_n'):>6} {med('remnant_zeta_n'):>6}"
            )


def _kinds_line(kinds: dict) -> str:
    """The runs per condition kind, and what each kind answers (SPEC 12)."""
    from hcid.analysis.conditions import ANSWERS, Kind

    parts = [f"{kinds[k.value]} {k.value} ({ANSWERS[k]})" for k in Kind if kinds.get(k.value)]
    return "CONDITIONS (each run's kind from its data): " + "; ".join(parts)


def print_skipped(skipped, run_dir) -> None:
    """The files a folder or glob found that are not runs, counted by reason (one example each),
    and the table in ``run_dir`` that lists them all."""
    if skipped:
        typer.echo(_skipped_line(skipped, run_dir))


def _skipped_line(skipped, run_dir) -> str:
    from hcid.io.datasets import skipped_by_reason

    by_reason = skipped_by_reason(skipped)
    parts = [f"{len(paths)} {key} (e.g. {paths[0].rsplit('/', 1)[-1]})" for key, paths in by_reason.items()]
    where = f"{run_dir}/skipped.parquet"
    return f"SKIPPED: {len(skipped)} file(s) found are not runs ({where}): " + "; ".join(parts)


def _range(r: dict, digits: int = 2) -> str:
    """An estimate with its range, or alone where the range is of one value."""
    if not math.isfinite(r["estimate"]):
        return "not measured"
    if r["n"] == 1 and r["spread"].endswith("people"):
        return f"{r['estimate']:.{digits}f}"
    return f"{r['estimate']:.{digits}f} [{r['low']:.{digits}f}, {r['high']:.{digits}f}]"


def _p(p: float) -> str:
    return "p -" if not math.isfinite(p) else f"p = {p:.2g}" if p >= 1e-4 else "p < 1e-4"


def effects_line(rows: list[dict], alpha: float) -> str:
    """What differs between the levels of the compared factor (SPEC 13): each effect whose p after
    Holm's correction is at most ``alpha``, by method, with its 95% interval and test; or that none
    does."""
    compared = list(dict.fromkeys(r["effect"].split(":", 1)[0] for r in rows)) or ["the factor"]
    how = "--compare; " if compared != ["trials"] else "a whole experiment's superposition; "
    found = [r for r in rows if math.isfinite(r["p_holm"]) and r["p_holm"] <= alpha]
    tested = {r["quantity"] for r in rows if math.isfinite(r["p"])}
    head = (f"EFFECTS of {' and '.join(compared)} ({how}subjects as repeated measures, "
            f"RUN/study_effects.parquet): {len(tested)} quantities tested")  # fmt: skip
    if not found:
        return f"{head}; none differs at p <= {alpha:g} after Holm's correction"

    def unit(r: dict) -> str:
        return f" {r['unit']}" if r["unit"] not in ("", "-", "1") else ""

    parts = [
        f"{r['source']} {r['quantity']} {r['effect'].split(': ', 1)[-1]} {r['estimate']:+.3g}{unit(r)} "
        f"[{r['low']:.3g}, {r['high']:.3g}] ({r['test']}, Holm p = {r['p_holm']:.2g}, "
        f"{r['subjects']} subjects)"
        for r in found
    ]
    return f"{head}; at p <= {alpha:g} after Holm's correction: " + "; ".join(parts)


def _print_session(result) -> None:
    """A whole experiment's findings (SPEC 12): model inversion by band, superposition, and
    prediction across conditions, each with its spread and test."""
    if result.session is None:
        return
    from hcid.pipeline.sessions import ALL_PEOPLE, BANDS, ONE_PERSON
    from hcid.pipeline.summary import study_verdicts

    for line in study_verdicts(result.groups, result.runs):
        typer.echo(line)
    rows = result.session.findings.to_pylist()
    people = {r["person"] for r in rows if r["person"] != ALL_PEOPLE}
    if people == {ONE_PERSON}:
        typer.echo(
            "ONE PERSON: the data set names no person (--person FACTOR, or a factor named subject): "
            "every run is combined as one person's, and nothing is compared across people"
        )
    who = f"median over {len(people)} people [range over them]" if len(people) > 1 else "one person"
    summary = [r for r in rows if r["person"] == ALL_PEOPLE]
    inversion = [r for r in summary if r["finding"] == "model inversion"]
    if inversion:
        typer.echo(f"MODEL INVERSION |Ht Yc| (1 = the plant's exact inverse; {who}):")
        for band in BANDS:
            here = [r for r in inversion if r["band"] == band]
            text = "; ".join(
                f"{_range(r)} from {r['source']} (vs 1: Wilcoxon {_p(r['p'])} over the people's lines)"
                for r in here
            )
            typer.echo(f"    {band}: {text or 'no line'}")
    pooled = [r for r in summary if r["finding"] == "superposition" and r["band"]]
    if pooled and len(people) > 1:
        lines = [
            r for r in rows if r["finding"] == "superposition" and not r["band"] and math.isfinite(r["p"])
        ]
        least = min((r["p"] for r in lines), default=math.nan)
        typer.echo(
            "SUPERPOSITION (single-input against two-input trials, paired across people, their lines "
            "pooled; median [range] over the person-lines):"
        )
        for r in pooled:
            unit = " deg" if "phase" in r["quantity"] else ""
            if r["n"] == 0:
                typer.echo(f"    {r['quantity']}: not measured (no trials of one of the kinds)")
                continue
            typer.echo(
                f"    {r['quantity']}: {_range(r, 1 if unit else 2)}{unit}, Wilcoxon {_p(r['p'])} "
                f"({r['n']} person-lines)"
            )
        typer.echo(
            f"    per line: the smallest p is {least:.2g} (with {len(people)} people a line's test "
            f"cannot go below {2 / 2 ** len(people):.2g})"
        )
    if result.session.feedback is not None:
        typer.echo(_feedback_line(result.session.feedback))
    prediction = [r for r in summary if r["finding"] == "prediction"]
    if prediction:
        typer.echo(
            "PREDICTION across conditions (error RMS(u - u_hat) / RMS(u), feedback and feedforward over "
            f"feedback only; {who}):"
        )
        for source in dict.fromkeys(r["source"] for r in prediction):
            here = {r["band"]: r for r in prediction if r["source"] == source}
            typer.echo(
                f"    {source}: {_range(here['window'])} over the window, "
                f"{_range(here['lines'])} at the lines"
            )


def _feedback_line(feedback) -> str:
    """The disturbance-only runs' feedback alone: the parameters they determine (median, sd over
    those runs) and each method's ARX selection at W_BIC."""
    import numpy as np

    from hcid.config.fit_settings import FEEDBACK_PARAMETERS
    from hcid.pipeline.evidence import determines, summarise_parameters

    rows = feedback.to_pylist()
    first = {r["run_id"]: r for r in rows}  # the fit is the run's, the same for every method
    n = len(first)
    parts = [
        _parameter_text(s, n)
        for s in summarise_parameters(list(first.values()), FEEDBACK_PARAMETERS)
        if s.kept
    ]
    loop = [r["crossover"] for r in first.values() if determines(r, "Kpe") and math.isfinite(r["crossover"])]
    arx = []
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == method]
        arx.append(
            f"{method} VAF {np.median([r['vaf_validation'] for r in mine]):.0f}% (median na "
            f"{np.median([r['na'] for r in mine]):.0f}, nb_e {np.median([r['nb_e'] for r in mine]):.0f})"
        )
    crossover = (
        f"crossover {np.median(loop):.3g} rad/s (median over the {len(loop)} runs that determine Kpe)"
        if loop
        else "crossover not determined"
    )
    return (
        f"FEEDBACK ALONE ({n} disturbance-only runs: no target, so no feedforward test): fitted "
        "(median over the runs that determine each; sd over them) "
        + ", ".join(parts or ["no parameter determined"])
        + f"; {crossover}; ARX without the target path at W_BIC: "
        + "; ".join(arx)
    )
