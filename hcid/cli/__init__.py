"""Command-line interface: thin commands over the library.

Each command loads the config, calls one library function, and prints a short
summary. A user's mistake (:class:`hcid.errors.HcidError`) becomes one line on
stderr and exit code 2, here and nowhere else.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated

import typer

from hcid.cli import answers

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
    """Turn an HcidError into one line on stderr and exit code 2; the command runs with BLAS
    single-threaded (:meth:`hcid.pipeline.Execution.pinned`: the same tables whatever --jobs)."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from hcid.errors import HcidError
        from hcid.pipeline.execution import Execution

        try:
            with Execution.pinned():
                return func(*args, **kwargs)
        except HcidError as exc:
            typer.echo(f"hcid: error: {exc}", err=True)
            raise typer.Exit(code=2) from None

    return wrapper


def _execution(
    jobs: int = 1,
    backend: str = "loky",
    scheduler: str | None = None,
    worker_timeout: float = 60.0,
    quiet: bool = False,
):
    """The command's execution settings; a bad --backend or --scheduler is refused before any work."""
    from hcid.pipeline import Execution

    return Execution(jobs, backend, scheduler, worker_timeout, progress=not quiet)


def _run_dir(config: Path, run: Path | None) -> Path:
    """--run, else runs/<the study's name> (read first from the YAML itself)."""
    from hcid.assembly.resolve import described_name

    return run if run is not None else Path("runs") / described_name(config)


def _load(
    config: Path, run: Path | None, method_names: tuple[str, ...] | None = None, *, reopen: bool = False
):
    """The config resolved for ``method_names`` (None: every method) and its run directory.

    ``reopen``: a command that reads a run's results resolves the methods the run
    recorded (a method registered since changes nothing).
    """
    from hcid.assembly.resolve import describe_file, methods_of_run, resolve_config

    run_dir = _run_dir(config, run)
    described = describe_file(config, run_dir)
    if reopen and method_names is None:
        method_names = methods_of_run(run_dir)
    return resolve_config(described, method_names), run_dir


def _load_data(config: Path, run: Path | None, data: list[str], execution, method_names=None, skip=False):
    """A measured study's config, completed from its data where it leaves the analysis rate or
    window out, its run directory and its data set, each file found and read once; a dask
    scheduler without workers is refused before anything is read."""
    from hcid.assembly.resolve import read_study

    execution.check()
    run_dir = _run_dir(config, run)
    cfg, data_set = read_study(config, data, method_names, skip_unreadable=skip)
    return cfg, run_dir, data_set


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

    execution = _execution(jobs, quiet=quiet)
    cfg, run_dir = _load(config, run)
    answers.print_simulation(
        simulate_study(cfg, run_dir, execution=execution, force=force), answers.is_paper(cfg)
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

    execution = _execution(jobs, backend, scheduler, worker_timeout, quiet)
    if data:
        cfg, run_dir, data_set = _load_data(config, run, data, execution, _methods(method))
    else:
        (cfg, run_dir), data_set = _load(config, run, _methods(method)), None
    result = identify_study(cfg, run_dir, _methods(method), data=data_set, execution=execution, force=force)
    answers.print_identification(result, answers.is_paper(cfg))
    answers.print_skipped(data_set.skipped if data_set is not None else (), run_dir)


@app.command("sweep-w")
@_user_errors
def sweep_w(config: ConfigArg, run: RunOpt = None):
    """Select models over the W grid; writes selection, breakpoints and thresholds tables."""
    from hcid.pipeline import sweep_study

    cfg, run_dir = _load(config, run, reopen=True)
    result = sweep_study(cfg, run_dir)
    answers.print_thresholds(result, answers.is_paper(cfg))
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

    execution = _execution(jobs, backend, scheduler, worker_timeout, quiet)
    cfg, run_dir = _load(config, run)
    result = run_study(cfg, run_dir, execution=execution)
    answers.print_identification(result.identification, answers.is_paper(cfg))
    answers.print_thresholds(result.sweep, answers.is_paper(cfg))
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

    execution = _execution(jobs, backend, scheduler, worker_timeout, quiet)
    cfg, run_dir = _load(config, run)
    result = calibrate_study(cfg, run_dir, execution=execution)
    answers.print_identification(result.study.identification, answers.is_paper(cfg))
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
        int,
        typer.Option(
            "--twins",
            help="Realizations of each twin (FB and FF) per group and forcing set for W's calibration "
            "(SPEC 10) and the power; also the batch in which more FB twins are drawn.",
        ),
    ] = 20,
    max_fb_twins: Annotated[
        int | None,
        typer.Option(
            "--max-fb-twins",
            help="The most FB twins per forcing set for the runs' p-values: drawn in batches until 5 show "
            "at least each run's statistic (Besag-Clifford); a run beyond nearly all of them gets its p "
            "from their generalized Pareto tail (SPEC 13). Default: 99, or --twins if more.",
            show_default=False,
        ),
    ] = None,
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
    person: Annotated[
        str | None,
        typer.Option(
            "--person",
            help="The factor naming people, whose conditions a whole experiment combines (single-input "
            "trials, swapped lines; SPEC 12). Default: subject, if the data set has it.",
            show_default=False,
        ),
    ] = None,
    compare: Annotated[
        str | None,
        typer.Option(
            "--compare",
            help="A factor whose levels are compared across people (subjects as repeated measures: a "
            "mixed model, the paired or rank test, Holm's correction; SPEC 13), written to the run's "
            "study_effects.parquet.",
            show_default=False,
        ),
    ] = None,
    skip_unreadable: Annotated[
        bool,
        typer.Option(
            "--skip-unreadable",
            help="Set aside files that cannot be read (each listed with its reason in the answer, the "
            "report and RUN/set_aside.parquet) instead of refusing the data set.",
        ),
    ] = False,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    worker_timeout: TimeoutOpt = 60.0,
    force: ForceOpt = False,
    quiet: QuietOpt = False,
):
    """Analyse a measured study end to end: identify every run, calibrate W per condition on twins of
    the condition's own fitted model, select every run there and fit its parameters; writes
    RUN/analysis.parquet, analysis.csv, analysis_groups.parquet and the report RUN/report/report.html."""
    from hcid.pipeline.analyse import AnalysisOptions
    from hcid.pipeline.analyse import analyse as analyse_

    execution = _execution(jobs, backend, scheduler, worker_timeout, quiet)
    options = AnalysisOptions(by, twins, max_fb_twins, ff_twin, alpha, fdr, person, compare)
    result = analyse_(config, data, run, options, execution=execution,
                      skip_unreadable=skip_unreadable, force=force)  # fmt: skip
    answers.print_analysis(result)
    from hcid.report import build_report

    typer.echo(f"report: {build_report(result.run_dir).html}")


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
    worker_timeout: TimeoutOpt = 60.0,
    force: ForceOpt = False,
    quiet: QuietOpt = False,
):
    """Fit the parametric HC model to every selected model, describe its loop and remnant and
    analyse its residuals; writes RUN/hc_parameters.parquet, hc_loop.parquet,
    remnant_spectrum.parquet and residuals.parquet."""
    from hcid.pipeline import fit_hc_study

    execution = _execution(jobs, backend, scheduler, worker_timeout, quiet)
    cfg, run_dir = _load(config, run, reopen=True)
    result = fit_hc_study(cfg, run_dir, _methods(method), w, target=target, execution=execution, force=force)
    answers.print_hc_fit(result)


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
        if "unexpected extra argument" in message and "--data" in sys.argv:
            message += (
                " (a glob the shell expanded? quote it, --data 'trials/*.csv', or give --data once per file)"
            )
        typer.echo(f"hcid: error: {' '.join(message.split())}", err=True)
        code = getattr(exc, "exit_code", 2)
    except typer.Abort:
        typer.echo("hcid: aborted", err=True)
        code = 130
    sys.exit(code if isinstance(code, int) else 0)
