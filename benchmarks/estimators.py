"""The parametric fit's estimators compared (issue 26): bias, sd, RMSE, standard errors, coverage.

For a run directory that holds identification results (``hcid run CONFIG``),
fits every selected model at W_BIC by each estimator (``closed_loop``, ``time``,
``frequency``) and, for the time-domain ones, with both covariances
(``sandwich``, ``gauss_newton``), and prints per model, method and parameter:
bias, sd and RMSE (% of the true value), the RMS standard error over the
empirical sd, and the 95% intervals' coverage of the true value with its exact
band; then per estimator the mean RMSE % over the parameters (the default's
rule: the lowest) and the fit's median time per record.

Each fit runs through ``hcid.pipeline.fit_hc_study`` as ``hcid fit-hc`` would,
with ``--jobs 2``; the tables of each variant are kept in ``OUT`` as
``<target>_<covariance>.parquet``.

Run: ``.venv/bin/python benchmarks/estimators.py RUN_DIR CONFIG OUT [--targets a,b]``
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from hcid.assembly.resolve import load_config
from hcid.hcfit import parse_fit_settings
from hcid.pipeline import Execution, fit_hc_study
from hcid.pipeline.summary import summarise_fits

VARIANTS = [
    ("closed_loop", "sandwich"),
    ("closed_loop", "gauss_newton"),
    ("time", "sandwich"),
    ("time", "gauss_newton"),
    ("frequency", "gauss_newton"),
]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("config", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--targets", default="closed_loop,time,frequency")
    parser.add_argument("--covariances", default="sandwich,gauss_newton")
    parser.add_argument("--lag", type=float, default=None, help="the sandwich's lag window (s)")
    args = parser.parse_args()
    targets = args.targets.split(",")
    config = load_config(args.config)
    base = config.fit_hc or parse_fit_settings(None, default_band=config.disturbance.band)
    if base.band is None:
        base = dataclasses.replace(base, band=config.disturbance.band)
    if args.lag is not None:
        base = dataclasses.replace(base, lag=args.lag)
    args.out.mkdir(parents=True, exist_ok=True)
    summary = []
    for target, cov in VARIANTS:
        if target not in targets or (target != "frequency" and cov not in args.covariances.split(",")):
            continue
        settings = dataclasses.replace(base, target=target, covariance=cov)
        start = time.perf_counter()
        run = fit_hc_study(
            dataclasses.replace(config, fit_hc=settings), args.run_dir, execution=Execution(2, progress=False)
        )
        wall = time.perf_counter() - start
        pq.write_table(run.parameters, args.out / f"{target}_{cov}.parquet")
        pq.write_table(run.loop, args.out / f"{target}_{cov}_loop.parquet")
        found = {k: f for k, f in summarise_fits(run.parameters).items() if f.scored}
        print(f"\n== {target}, standard errors {cov}: {run.computed} record-methods in {wall:.1f} s (2 jobs)")
        print(
            f"{'model':<6}{'method':<10}{'parameter':<10}{'true':>7}{'bias%':>8}{'sd%':>7}{'RMSE%':>7}"
            f"{'se/sd':>7}{'covered':>9}{'bound':>6}"
        )
        rmse = []
        for (model, method, _w, name), f in found.items():
            print(
                f"{model:<6}{method:<10}{name:<10}{f.true:>7.3g}{f.percent(f.bias):>+8.1f}"
                f"{f.percent(f.sd):>7.1f}{f.percent(f.rmse):>7.1f}{f.se_ratio:>7.2f}"
                f"{f.covered:>5}/{f.n_se:<3}{f.at_bound:>6}"
            )
            if math.isfinite(f.percent(f.rmse)):
                rmse.append(f.percent(f.rmse))
        summary.append((target, cov, float(np.mean(rmse)), wall, run.computed))
    print("\n== per estimator: mean RMSE % over (model, method, parameter) with a nonzero true value")
    for target, cov, rmse, wall, n in summary:
        print(f"{target:<12}{cov:<14} mean RMSE {rmse:6.2f} %   {wall:6.1f} s for {n} record-methods")
    if summary:
        best = min(summary, key=lambda s: s[2])
        print(f"lowest mean RMSE: {best[0]} ({best[1]})")


if __name__ == "__main__":
    main()
