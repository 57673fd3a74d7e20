"""Command-line interface: thin commands over the library.

Each command loads the config, calls one library function, and prints a short
summary. A user's mistake (:class:`hcid.errors.HcidError`) becomes one line on
stderr and exit code 2, here and nowhere else.
"""

from __future__ import annotations

import functools
import os
import sys
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


@app.callback()
def _root() -> None:
    """hcid: identify human-controller models from closed-loop manual-control data."""


ConfigArg = Annotated[Path, typer.Argument(help="Study config (YAML).", show_default=False)]
RunOpt = Annotated[Path | None, typer.Option("--run", help="Run directory [default: runs/<config name>].")]
JobsOpt = Annotated[int, typer.Option("--jobs", min=1, max=256, help="Worker processes.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", help="No progress bar.")]
ForceOpt = Annotated[bool, typer.Option("--force", help="Recompute what is already done.")]
MethodOpt = Annotated[str, typer.Option("--method", help="direct, indirect or both.")]
BackendOpt = Annotated[str, typer.Option("--backend", help="loky (local processes) or dask.")]
SchedulerOpt = Annotated[
    str | None,
    typer.Option("--scheduler", help="dask scheduler address tcp://host:port [default: a local cluster]."),
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


def _check_backend(backend: str) -> None:
    from hcid.errors import HcidError
    from hcid.pipeline import BACKENDS

    if backend not in BACKENDS:
        raise HcidError(f"--backend: must be one of {', '.join(BACKENDS)}, got {backend!r}")


def _run_dir(run: Path | None, config) -> Path:
    return run if run is not None else Path("runs") / config.name


@app.command()
@_user_errors
def simulate(
    config: ConfigArg, run: RunOpt = None, jobs: JobsOpt = 2, quiet: QuietOpt = False, force: ForceOpt = False
):
    """Simulate every model x seed of CONFIG and write RUN/simulations.parquet."""
    from hcid.config import load_config
    from hcid.pipeline import simulate_study

    cfg = load_config(config)
    result = simulate_study(cfg, _run_dir(run, cfg), jobs=jobs, show_progress=not quiet, force=force)
    _print_simulation_summary(result)


def _methods(method: str) -> tuple[str, ...]:
    from hcid.errors import HcidError

    choices = {"direct": ("direct",), "indirect": ("indirect",), "both": ("direct", "indirect")}
    try:
        return choices[method]
    except KeyError:
        raise HcidError(f"--method: must be one of direct, indirect, both; got {method!r}") from None


@app.command()
@_user_errors
def identify(
    config: ConfigArg,
    method: MethodOpt = "both",
    run: RunOpt = None,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    force: ForceOpt = False,
    quiet: QuietOpt = False,
    data: Annotated[
        Path | None,
        typer.Option(
            "--data",
            help="Measured data (.csv, .parquet or .mat) to identify instead of "
            "simulations; columns mapped by the config's data section.",
        ),
    ] = None,
):
    """Identify every model x seed of CONFIG (or every run of --data); writes RUN/frontier.parquet."""
    from hcid.config import load_config
    from hcid.pipeline import identify_study, import_data, simulate_study

    cfg = load_config(config)
    methods = _methods(method)
    _check_backend(backend)
    run_dir = _run_dir(run, cfg)
    records = None
    if data is not None:
        records = import_data(cfg, run_dir, data)
        typer.echo(f"read {len(records)} run(s) of {cfg.data.name} from {data}")
    elif not (run_dir / "simulations.parquet").exists():
        _print_simulation_summary(simulate_study(cfg, run_dir, jobs=jobs, show_progress=not quiet))
    result = identify_study(
        cfg,
        run_dir,
        methods,
        data=records,
        jobs=jobs,
        force=force,
        backend=backend,
        scheduler=scheduler,
        show_progress=not quiet,
    )
    _print_identify_summary(result)


def _print_identify_summary(result) -> None:
    log = result.log.to_pydict()
    typer.echo(
        f"identified {result.computed} realization-methods, reused {result.reused}; "
        f"{sum(log['n_candidates']) + sum(log['stage1_candidates']):,} candidates in the tables, "
        f"{sum(log['n_unstable']) + sum(log['stage1_unstable']):,} unstable"
    )
    typer.echo(f"wrote {result.run_dir / 'frontier.parquet'}")


@app.command("sweep-w")
@_user_errors
def sweep_w(config: ConfigArg, run: RunOpt = None):
    """Select models over the W grid; writes selection, breakpoints and thresholds tables."""
    from hcid.config import load_config
    from hcid.pipeline import sweep_study

    cfg = load_config(config)
    result = sweep_study(cfg, _run_dir(run, cfg))
    _print_thresholds(result.thresholds)
    typer.echo(f"wrote {result.run_dir / 'thresholds.parquet'}")


def _print_thresholds(thresholds) -> None:
    from hcid import paper as PAPER

    typer.echo(f"{'method':<10}{'model':<8}{'threshold':<11}{'this run':>12}{'paper':>10}")
    for row in thresholds.to_pylist():
        for name in ("w_fp", "w_fn"):
            if row[name] is None:
                continue
            paper = PAPER.W_FP.get(row["method"]) if name == "w_fp" else PAPER.W_FN
            paper_text = f"{paper:.2g}" if paper is not None else "-"
            typer.echo(
                f"{row['method']:<10}{row['model']:<8}{name.upper():<11}{row[name]:>12.4g}{paper_text:>10}"
            )
    first = thresholds.to_pylist()[0] if thresholds.num_rows else None
    if first:
        typer.echo(f"W_AIC = {first['w_aic']:.4g}, W_BIC = {first['w_bic']:.4g} (Nf = {first['nf']})")


@app.command("run")
@_user_errors
def run_all(
    config: ConfigArg,
    run: RunOpt = None,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    quiet: QuietOpt = False,
):
    """Simulate, identify both methods and sweep W, skipping what is already done."""
    import time

    from hcid.config import load_config
    from hcid.pipeline import identify_study, simulate_study, sweep_study

    cfg = load_config(config)
    _check_backend(backend)
    run_dir = _run_dir(run, cfg)
    start = time.perf_counter()
    if not (run_dir / "simulations.parquet").exists():
        _print_simulation_summary(simulate_study(cfg, run_dir, jobs=jobs, show_progress=not quiet))
    _print_identify_summary(
        identify_study(cfg, run_dir, jobs=jobs, backend=backend, scheduler=scheduler, show_progress=not quiet)
    )
    _print_thresholds(sweep_study(cfg, run_dir).thresholds)
    typer.echo(f"done in {time.perf_counter() - start:.1f} s; tables in {run_dir}")


def _print_simulation_summary(result) -> None:
    import numpy as np

    from hcid import paper as PAPER

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
        paper = PAPER.RMS_E_DEG.get(m)
        paper_text = f"{paper:.2f}" if paper is not None else "-"
        typer.echo(
            f"{m:<8}{len(rows):>6}{rms.mean():>15.3f} +- {rms.std(ddof=1) if len(rows) > 1 else 0.0:.3f}"
            f"{paper_text:>8}{ratio.mean():>26.4f}"
        )
    typer.echo(f"wrote {result.run_dir / 'simulations.parquet'}")


@app.command("calibrate-w")
@_user_errors
def calibrate_w(
    config: ConfigArg,
    run: RunOpt = None,
    jobs: JobsOpt = 2,
    backend: BackendOpt = "loky",
    scheduler: SchedulerOpt = None,
    quiet: QuietOpt = False,
):
    """Calibrate W on simulations of the config's FB and FF twins: rates, safe interval, recommended W."""
    from hcid.config import load_config
    from hcid.pipeline import calibrate_study, sweep_study

    cfg = load_config(config)
    _check_backend(backend)
    run_dir = _run_dir(run, cfg)
    result = calibrate_study(
        cfg, run_dir, jobs=jobs, backend=backend, scheduler=scheduler, show_progress=not quiet
    )
    sweep_study(cfg, run_dir)
    typer.echo(f"target rate {cfg.target_rate:g} for false positives (FB twin) and false negatives (FF twin)")
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
def report(
    run_dir: Annotated[Path, typer.Argument(help="Run directory.", show_default=False)],
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory [default: RUN_DIR/report].")
    ] = None,
):
    """Write RUN_DIR/report/report.md and report.html with the paper's figures and verdicts."""
    from hcid.report import build_report

    result = build_report(run_dir, out)
    if result.missing:
        typer.echo(f"missing stages: {', '.join(result.missing)} (reported what is there)")
    width = max((len(v.claim) for v in result.verdicts), default=10)
    for v in result.verdicts:
        mark = {True: "holds", False: "DOES NOT HOLD", None: "not evaluated"}[v.holds]
        typer.echo(f"{v.claim:<{width}}  {mark:<14} {v.this_run}")
    typer.echo(f"report: {result.html}")


def main() -> None:
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
