"""Command-line interface: thin commands over the library.

Each command loads the config, calls one library function, and prints a short
summary. A user's mistake (:class:`hcid.errors.HcidError`) becomes one line on
stderr and exit code 2, here and nowhere else.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Annotated

import typer

# One level of parallelism (the worker processes) and bit-identical results whatever
# --jobs: BLAS runs single-threaded. Set before numpy is first imported (typer does not).
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="hcid: identify human-controller models from closed-loop manual-control data.",
)


def _show_version(value: bool) -> None:
    if value:
        from hcid import __version__

        typer.echo(f"hcid {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", help="Print hcid's version and exit.", callback=_show_version, is_eager=True
        ),
    ] = False,
) -> None:
    """hcid: identify human-controller models from closed-loop manual-control data."""


ConfigArg = Annotated[Path, typer.Argument(help="Study config (YAML).", show_default=False)]
RunOpt = Annotated[Path | None, typer.Option("--run", help="Run directory (default: runs/<config name>).")]
JobsOpt = Annotated[int, typer.Option("--jobs", min=1, max=256, help="Worker processes.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", help="No progress bar.")]
ForceOpt = Annotated[bool, typer.Option("--force", help="Recompute what is already done.")]
MethodOpt = Annotated[
    str, typer.Option("--method", help="A method (direct, indirect), a comma-separated list, or all.")
]
BackendOpt = Annotated[
    str, typer.Option("--backend", help="loky (local worker processes, forked on Linux) or dask.")
]
TimeoutOpt = Annotated[
    float,
    typer.Option(
        "--worker-timeout", min=1.0, max=86400.0, help="dask: seconds without any worker before giving up."
    ),
]
SchedulerOpt = Annotated[
    str | None,
    typer.Option("--scheduler", help="dask scheduler address tcp://host:port (default: a local cluster)."),
]


def _user_errors(func):
    """Turn an HcidError into one line on stderr and exit code 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from hcid.errors import HcidError

        try:
            return func(*args, **kwargs)
        except HcidError as exc:
            typer.echo(f"hcid: error: {exc}", err=True)
            raise typer.Exit(code=2) from None

    return wrapper


def _load(
    config: Path,
    run: Path | None,
    backend: str = "loky",
    scheduler: str | None = None,
    method_names: tuple[str, ...] | None = None,
    *,
    reopen: bool = False,
    data: list[str] | None = None,
):
    """The config resolved for ``method_names`` (None: every method) and its run directory.

    ``data``: the measured data of the command, from which a measured study's analysis rate
    and window are taken when its config leaves them out.

    ``reopen``: a command that reads a run's results resolves the methods the run
    recorded (a method registered since changes nothing). A bad --backend or
    --scheduler is refused before any work.
    """
    from hcid.pipeline import check_backend
    from hcid.resolve import describe_file, described_name, methods_of_run, resolve_config

    check_backend(backend, scheduler)
    # The run directory's default needs the study's name, read first from the YAML itself.
    name = described_name(config)
    run_dir = run if run is not None else Path("runs") / name
    described = describe_file(config, data, run_dir)
    if reopen and method_names is None:
        method_names = methods_of_run(run_dir)
    return resolve_config(described, method_names), run_dir


def _methods(method: str) -> tuple[str, ...]:
    from hcid.errors import HcidError
    from hcid.methods import METHODS

    if method == "all":
        return tuple(METHODS)
    names = tuple(m.strip() for m in method.split(","))
    unknown = [m for m in names if m not in METHODS]
    if unknown or not names:
        raise HcidError(f"--method: must be all or among {', '.join(METHODS)}; got {method!r}")
    return names


@app.command()
@_user_errors
def simulate(
    config: ConfigArg, run: RunOpt = None, jobs: JobsOpt = 2, quiet: QuietOpt = False, force: ForceOpt = False
):
    """Simulate every model x seed of CONFIG and write RUN/simulations.parquet."""
    from hcid.pipeline import simulate_study

    cfg, run_dir = _load(config, run)
    _print_simulation(
        simulate_study(cfg, run_dir, jobs=jobs, show_progress=not quiet, force=force), _is_paper(cfg)
    )


@app.command()
@_user_errors
def identify(
    config: ConfigArg,
    method: MethodOpt = "all",
    run: RunOpt = None,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    worker_timeout: TimeoutOpt = 60.0,
    force: ForceOpt = False,
    quiet: QuietOpt = False,
    data: Annotated[
        list[str] | None,
        typer.Option(
            "--data",
            help="Measured data to identify instead of simulations: a file (.csv, .parquet, .mat), "
            "a quoted glob ('trials/*.csv'), a folder, or a manifest CSV with a 'file' column and "
            "one column per factor; repeat for several. Columns mapped and factors named by the "
            "config's data section.",
        ),
    ] = None,
):
    """Identify every model x seed of CONFIG (or every run of --data); writes RUN/frontier.parquet."""
    from hcid.pipeline import identify_study

    cfg, run_dir = _load(config, run, backend, scheduler, _methods(method), data=data)
    result = identify_study(
        cfg,
        run_dir,
        _methods(method),
        data_path=data or None,
        jobs=jobs,
        force=force,
        backend=backend,
        scheduler=scheduler,
        worker_timeout=worker_timeout,
        show_progress=not quiet,
    )
    _print_identification(result, _is_paper(cfg))


@app.command("sweep-w")
@_user_errors
def sweep_w(config: ConfigArg, run: RunOpt = None):
    """Select models over the W grid; writes selection, breakpoints and thresholds tables."""
    from hcid.pipeline import sweep_study

    cfg, run_dir = _load(config, run, reopen=True)
    result = sweep_study(cfg, run_dir)
    _print_thresholds(result, _is_paper(cfg))
    typer.echo(f"wrote {run_dir / 'thresholds.parquet'}")


@app.command("run")
@_user_errors
def run_all(
    config: ConfigArg,
    run: RunOpt = None,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    worker_timeout: TimeoutOpt = 60.0,
    quiet: QuietOpt = False,
):
    """Simulate, identify every method and sweep W, skipping what is already done."""
    from hcid.pipeline import run_study

    cfg, run_dir = _load(config, run, backend, scheduler)
    result = run_study(
        cfg,
        run_dir,
        jobs=jobs,
        backend=backend,
        scheduler=scheduler,
        worker_timeout=worker_timeout,
        show_progress=not quiet,
    )
    _print_identification(result.identification, _is_paper(cfg))
    _print_thresholds(result.sweep, _is_paper(cfg))
    typer.echo(f"done in {result.seconds:.1f} s; tables in {run_dir}")


@app.command("calibrate-w")
@_user_errors
def calibrate_w(
    config: ConfigArg,
    run: RunOpt = None,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    worker_timeout: TimeoutOpt = 60.0,
    quiet: QuietOpt = False,
):
    """Calibrate W on simulations of the config's FB and FF twins: rates, safe interval, recommended W."""
    from hcid.pipeline import calibrate_study

    cfg, run_dir = _load(config, run, backend, scheduler)
    result = calibrate_study(
        cfg,
        run_dir,
        jobs=jobs,
        backend=backend,
        scheduler=scheduler,
        worker_timeout=worker_timeout,
        show_progress=not quiet,
    )
    _print_identification(result.study.identification, _is_paper(cfg))
    rate = cfg.selection.target_rate
    typer.echo(f"target rate {rate:g} for false positives (FB twin) and false negatives (FF twin)")
    for cal in result.calibrations:
        if cal.has_safe_interval:
            typer.echo(
                f"{cal.method:<9} safe W in [{cal.safe_low:.4g}, {cal.safe_high:.4g}), "
                f"recommended W = {cal.recommended:.4g} (geometric midpoint)"
            )
        else:
            typer.echo(
                f"{cal.method:<9} no safe W: false positives up to {cal.safe_low:.4g}, "
                f"false negatives from {cal.safe_high:.4g}"
            )
    typer.echo(f"wrote {run_dir / 'calibration.parquet'}")


@app.command()
@_user_errors
def analyse(
    config: ConfigArg,
    data: Annotated[
        list[str],
        typer.Option(
            "--data",
            help="The study's data: files, a quoted glob ('trials/*.csv'), a folder, or a manifest CSV "
            "(a 'file' column and one column per factor); repeat for several.",
        ),
    ],
    run: RunOpt = None,
    by: Annotated[
        str | None,
        typer.Option(
            "--by",
            help="Factor(s) whose runs share one calibrated W, comma-separated (default: condition, "
            "if the data set has it; e.g. --by subject or --by subject,condition).",
        ),
    ] = None,
    twins: Annotated[
        int, typer.Option("--twins", help="Realizations of each twin (FB and FF) per group.")
    ] = 20,
    ff_twin: Annotated[
        str,
        typer.Option(
            "--ff-twin",
            help="The FF twin's feedforward: own (the group's fitted model), study (the group with the "
            "largest fitted Kpt: would feedforward of the size seen in the study be found?) or auto (the "
            "default: own, and study where no W separates a group's own twins).",
        ),
    ] = "auto",
    alpha: Annotated[
        float,
        typer.Option(
            "--alpha",
            help="Level of each run's feedforward test (its W* against its FB twins'; SPEC 11).",
        ),
    ] = 0.05,
    fdr: Annotated[
        bool,
        typer.Option(
            "--fdr",
            help="Control the false discovery rate at --alpha over the study's runs (Benjamini-Hochberg) "
            "instead of testing each run at --alpha.",
        ),
    ] = False,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    force: ForceOpt = False,
    quiet: QuietOpt = False,
):
    """Analyse a measured study end to end: identify every run, calibrate W per condition on twins of
    the condition's own fitted model, select every run there and fit its parameters; writes
    RUN/analysis.parquet, analysis.csv, analysis_groups.parquet and the report RUN/report/report.html."""
    from hcid.pipeline.analyse import analyse_study

    cfg, run_dir = _load(config, run, backend, scheduler, data=data)
    result = analyse_study(
        cfg,
        run_dir,
        data,
        by=None if by is None else [b.strip() for b in by.split(",") if b.strip()],
        twins=twins,
        ff_twin=ff_twin,
        alpha=alpha,
        fdr=fdr,
        jobs=jobs,
        force=force,
        backend=backend,
        scheduler=scheduler,
        show_progress=not quiet,
    )
    _print_analysis(result)
    from hcid.report import build_report

    typer.echo(f"report: {build_report(run_dir).html}")


@app.command("fit-hc")
@_user_errors
def fit_hc(
    config: ConfigArg,
    run: RunOpt = None,
    w: Annotated[
        list[float] | None,
        typer.Option(
            "--w", help="W to analyse (repeat for several; default: the calibrated W if any, else W_BIC)."
        ),
    ] = None,
    method: MethodOpt = "all",
    target: Annotated[
        str | None,
        typer.Option(
            "--target",
            help="Estimator: auto, lines, time, closed_loop or frequency (default: the config's "
            "fit_hc.target, else auto: lines for multisine forcing functions with at least 5 "
            "disturbance lines, else time).",
        ),
    ] = None,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    force: ForceOpt = False,
    quiet: QuietOpt = False,
):
    """Fit the parametric HC model to every selected model, describe its loop and remnant and
    analyse its residuals; writes RUN/hc_parameters.parquet, hc_loop.parquet,
    remnant_spectrum.parquet and residuals.parquet."""
    from hcid.pipeline import fit_hc_study

    cfg, run_dir = _load(config, run, backend, scheduler, reopen=True)
    result = fit_hc_study(
        cfg,
        run_dir,
        _methods(method),
        w,
        target=target,
        jobs=jobs,
        force=force,
        backend=backend,
        scheduler=scheduler,
        show_progress=not quiet,
    )
    _print_hc_fit(result)


@app.command()
@_user_errors
def report(
    run_dir: Annotated[Path, typer.Argument(help="Run directory.", show_default=False)],
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory (default: RUN_DIR/report).")
    ] = None,
):
    """Write RUN_DIR/report/report.md and report.html with the paper's figures and verdicts."""
    from hcid.report import build_report

    result = build_report(run_dir, out)
    if result.missing:
        typer.echo(f"missing stages: {', '.join(result.missing)} (reported what is there)")
    width = max((len(v.claim) for v in result.verdicts), default=10)
    for v in result.verdicts:
        mark = v.status_text if v.holds is not False else "DOES NOT HOLD"
        typer.echo(f"{v.claim:<{width}}  {mark:<14} {v.this_run}")
    typer.echo(f"report: {result.html}")


def main() -> None:
    """The ``hcid`` command: a misused option or argument is one line on stderr and exit code 2."""
    import sys

    if len(sys.argv) <= 1:
        sys.argv.append("--help")
    try:
        code = app(standalone_mode=False)
    except typer.TyperException as exc:  # typer's usage errors: a bad option value, a missing argument
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        typer.echo(f"hcid: error: {' '.join(message.split())}", err=True)
        code = getattr(exc, "exit_code", 2)
    except typer.Abort:
        typer.echo("hcid: aborted", err=True)
        code = 130
    sys.exit(code if isinstance(code, int) else 0)


# --------------------------------------------------------------------------- summaries


def _is_paper(cfg) -> bool:
    """Whether the paper's figures are printed beside this run's (its experiment only)."""
    from hcid import paper

    return paper.is_paper_experiment(cfg)


def _print_simulation(result, is_paper: bool) -> None:
    import numpy as np

    from hcid import paper

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


def _print_identification(result, is_paper: bool) -> None:
    if result.simulation is not None:
        _print_simulation(result.simulation, is_paper)
    if result.imported:
        typer.echo(f"read {result.imported} measured run(s)")
    log = result.log.to_pydict()
    typer.echo(
        f"identified {result.computed} realization-methods, reused {result.reused}; "
        f"{sum(log['n_candidates']) + sum(log['stage1_candidates']):,} candidates in the tables, "
        f"{sum(log['n_unstable']) + sum(log['stage1_unstable']):,} unstable"
    )
    typer.echo(f"wrote {result.run_dir / 'frontier.parquet'}")


def _print_thresholds(sweep, is_paper: bool) -> None:
    from hcid import paper

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


def _print_analysis(result) -> None:
    """Per group and method: the answer first (feedforward in k of N runs at W, how sure), then
    the parameters the runs determine, the loop, and the data check (SPEC 11)."""
    import numpy as np

    from hcid.hcfit.consistency import CONTRADICTED, format_p

    def pct(k: float, lo: float, hi: float) -> str:
        return f"{100 * k:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}]"

    runs = result.runs.to_pylist()
    for g in result.groups.to_pylist():
        rows = [r for r in runs if r["group"] == g["group"] and r["method"] == g["method"]]
        if g["w_rule"] == "safe interval":
            safe = f"safe interval [{g['safe_low']:.3g}, {g['safe_high']:.3g})"
            if g["ff_twin"] == "study":
                safe += (
                    f" for the study's feedforward (Kpt {g['twin_Kpt']:.2g}; this group's own fitted "
                    f"Kpt is {g['fitted_Kpt']:.2g})"
                )
        elif g["uncertain"]:
            whose = " (with the study's feedforward)" if g["ff_twin"] == "study" else ""
            safe = f"NO W separates the twins{whose}: W of least total error, every decision UNCERTAIN"
        else:
            safe = (
                "no contiguous safe interval; W of least total error, where the twins' rates are "
                "within the target"
            )
        power = [r["power"] for r in rows]
        typer.echo(
            f"{g['group']}, {g['method']}: {g['verdict']}: {g['n_evidence']} of {g['n_runs']} runs show "
            f"feedforward at p <= {g['alpha']:g} (decided by their {g['decided_by']} against their own "
            "forcing set's FB twins: the statistic with the higher power; "
            f"binomial p = {g['binomial_p']:.2g}; power {min(power):.2f} to {max(power):.2f}, "
            f"{g['forcing_sets']} forcing set{'s' if g['forcing_sets'] > 1 else ''})"
        )
        typer.echo(
            f"    calibrated W (SPEC 10): feedforward in {g['n_feedforward']} of {g['n_runs']} runs at "
            f"W = {g['w']:.3g} ({safe}; twins' FP {pct(g['fp_rate'], g['fp_low'], g['fp_high'])}, "
            f"FN {pct(g['fn_rate'], g['fn_low'], g['fn_high'])})"
        )
        typer.echo(_analysis_parameters(rows))
        wc = np.nanmedian([r["crossover"] for r in rows])
        pm = np.nanmedian([r["phase_margin"] for r in rows])
        typer.echo(f"    loop: crossover {wc:.3g} rad/s, phase margin {pm:.3g} deg (medians over runs)")
        contradicted = (
            f"{g['n_contradicted']} of {g['n_runs']} runs' own fits at W are contradicted by the data"
        )
        if g["fc_dof"] > 0:
            ht = "" if g["ht_error_db"] != g["ht_error_db"] else (
                f", Ht {g['ht_error_db']:.1f} dB {g['ht_error_deg']:.0f} deg")  # fmt: skip
            typer.echo(
                f"    data check: the group's model is {g['fc_verdict']} (chi-square {g['fc_chi2']:.1f} on "
                f"{g['fc_dof']} dof, p = {format_p(g['fc_p'])}, spread {g['fc_spread']}; median |error| "
                f"against the Fourier-coefficient estimates He {g['he_error_db']:.1f} dB "
                f"{g['he_error_deg']:.0f} deg{ht}); {contradicted} (p < {CONTRADICTED:g})"
            )
        else:
            typer.echo(f"    data check: {g['fc_verdict']}")
    typer.echo(
        f"analysed in {result.seconds:.1f} s ("
        + ", ".join(f"{name} {sec:.1f}" for name, sec in result.stages.items())
        + f"); wrote {result.run_dir / 'analysis.parquet'} (and .csv: one row "
        f"per run and method, with its factors) and {result.run_dir / 'analysis_groups.parquet'}"
    )


def _analysis_parameters(rows: list[dict]) -> str:
    """The runs' fits at W (hcid.pipeline.analyse.summarise_parameters): median over the runs that
    determine each, their sd and count, units; then what some runs leave undetermined, and why."""
    from hcid.pipeline.analyse import summarise_parameters

    parts, left_out = [], []
    for s in summarise_parameters(rows):
        unit = "" if s.unit == "-" else f" {s.unit}"
        if s.kept:
            sd = f", sd {s.sd:.2g}" if s.kept > 1 else ""
            parts.append(f"{s.name} {s.median:.3g}{unit} ({s.kept} of {s.fitted} runs{sd})")
        left_out += [f"{s.name} in {n} of {s.fitted} runs ({why})" for why, n in s.left_out.items()]
    text = "    runs' fits at W (median over the runs that determine each; sd over them): " + ", ".join(parts)
    if left_out:
        text += "\n    not determined, left out: " + "; ".join(left_out)
    return text


def _print_hc_fit(result) -> None:
    import numpy as np

    from hcid import tables

    def num(x: float) -> str:
        return "-" if x is None or not np.isfinite(x) else f"{x:.4g}"

    for method, pairs in result.w_of.items():
        typer.echo(f"{method:<9} W = " + ", ".join(f"{w:.4g} ({source})" for w, source in pairs))
    rows = result.parameters.to_pylist()
    # The model column fits the longest name (a measured file's data name is often long).
    m = max([10, *(len(r["model"]) + 1 for r in rows)])
    if rows:
        typer.echo(f"target {rows[0]['target']}, standard errors {rows[0]['covariance'] or '-'}")
    # One record: its estimate with se and 95% interval; several: medians, the spread across
    # records beside the median se, and how many 95% intervals hold the true value.
    header = f"{'model':<{m}}{'method':<10}{'W':>9} {'parameter':<10}{'estimate':>10} {'se':>9}"
    header += f" {'sd':>9} {'95% interval':>21} {'true':>9}{'n':>5}{'covers':>7}{'bound':>6}"
    typer.echo(header)
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault((row["model"], row["method"], row["w"], row["parameter"]), []).append(row)
    for (model, method, w, name), group in groups.items():
        column = {
            c: np.array([r[c] for r in group], dtype=float) for c in ("estimate", "se", "ci_low", "ci_high")
        }
        est, se = column["estimate"], column["se"]
        true = group[0]["true_value"]
        one = len(group) == 1
        median = num(est[0]) if one else num(np.nanmedian(est)) if np.isfinite(est).any() else "-"
        se_text = num(se[0]) if one else num(np.nanmedian(se)) if np.isfinite(se).any() else "-"
        sd = "-" if one or np.isfinite(est).sum() < 2 else num(np.nanstd(est, ddof=1))
        interval = f"[{num(column['ci_low'][0])}, {num(column['ci_high'][0])}]" if one else "-"
        covers = "-"
        if true is not None and np.isfinite(true):
            given = np.isfinite(column["se"])  # rows with an interval (none on a bound)
            held = given & (column["ci_low"] <= true) & (true <= column["ci_high"])
            covers = f"{int(held.sum())}/{int(given.sum())}"
        hits = sum(bool(r["at_bound"]) for r in group)
        typer.echo(
            f"{model:<{m}}{method:<10}{w:>9.4g} {name:<10}{median:>10} {se_text:>9} {sd:>9} {interval:>21}"
            f" {num(true):>9}{len(group):>5}{covers:>7}{hits:>6}"
        )
    loop = result.loop.to_pylist()
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
    written = ", ".join(str(result.run_dir / t.file) for t in (tables.HC_PARAMETERS, tables.HC_LOOP))
    typer.echo(
        f"fitted {result.computed} record-methods, reused {result.reused}, in {result.seconds:.1f} s; "
        f"wrote {written} (and residuals, remnant spectra)"
    )
