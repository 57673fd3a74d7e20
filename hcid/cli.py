"""Command-line interface: thin commands over the library.

Each command loads the config, calls one library function, and prints a short
summary. A user's mistake (:class:`hcid.errors.HcidError`) becomes one line on
stderr and exit code 2, here and nowhere else.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import Annotated

import typer

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="hcid: identify human-controller models from closed-loop manual-control data.",
)



@app.callback()
def _root() -> None:
    """hcid: identify human-controller models from closed-loop manual-control data."""


ConfigArg = Annotated[Path, typer.Argument(help="Study config (YAML).", show_default=False)]
RunOpt = Annotated[
    Path | None, typer.Option("--run", help="Run directory [default: runs/<config name>].")
]
JobsOpt = Annotated[int, typer.Option("--jobs", min=1, max=256, help="Worker processes.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", help="No progress bar.")]


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


def _run_dir(run: Path | None, config) -> Path:
    return run if run is not None else Path("runs") / config.name


# Paper Table 2, RMS(e) in deg, for the summary only.
_PAPER_RMS_E = {"FB": 2.43, "FF": 1.22}


@app.command()
@_user_errors
def simulate(config: ConfigArg, run: RunOpt = None, jobs: JobsOpt = 2, quiet: QuietOpt = False):
    """Simulate every model x seed of CONFIG and write RUN/simulations.parquet."""
    from hcid.config import load_config
    from hcid.pipeline import simulate_study

    cfg = load_config(config)
    result = simulate_study(cfg, _run_dir(run, cfg), jobs=jobs, show_progress=not quiet)
    _print_simulation_summary(result)


def _print_simulation_summary(result) -> None:
    import numpy as np

    summary = result.summary.to_pydict()
    models = list(dict.fromkeys(summary["model"]))
    typer.echo(f"Kn = {result.kn:.6g} (remnant gain, from var(n)/var(u) in the disturbance-only task)")
    typer.echo(f"{'model':<8}{'seeds':>6}{'RMS(e) deg mean +- sd':>24}{'paper':>8}{'var(n)/var(u) dist-only':>26}")
    for m in models:
        rows = [i for i, name in enumerate(summary["model"]) if name == m]
        rms = np.array([summary["rms_e_deg"][i] for i in rows])
        ratio = np.array([summary["noise_ratio_disturbance_only"][i] for i in rows])
        paper = _PAPER_RMS_E.get(m)
        paper_text = f"{paper:.2f}" if paper is not None else "-"
        typer.echo(
            f"{m:<8}{len(rows):>6}{rms.mean():>15.3f} +- {rms.std(ddof=1) if len(rows) > 1 else 0.0:.3f}"
            f"{paper_text:>8}{ratio.mean():>26.4f}"
        )
    typer.echo(f"wrote {result.run_dir / 'simulations.parquet'}")


def main() -> None:
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
