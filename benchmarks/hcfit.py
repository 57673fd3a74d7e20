"""Benchmark of the parametric HC fit (hcid.hcfit) and the residual analysis.

1. Noise-free FF model, default settings: one frequency-domain fit (the true
   paths of SPEC 1 on the band grid) and one time-domain fit (the noise-free
   closed-loop record of hcid.loop.simulate), median wall time of 5 runs each, and
   the recovery error of every parameter.
2. A realistic record (paper config, FF, seed 1, with remnant): the direct
   method's grid, the model selected at W_BIC, then both fits and a residual
   analysis of the time fit on the validation rows. Estimates are printed next
   to the true values; with remnant they are not expected to be exact.

Run: ``.venv/bin/python benchmarks/hcfit.py``.
"""

import os

# One core for BLAS too, before numpy is imported.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _paper_record import PAPER_CONFIG, paper_record  # noqa: E402

from hcid import hcfit  # noqa: E402
from hcid.analysis.residuals import analyse_residuals  # noqa: E402
from hcid.arx import Grid, fit_grid  # noqa: E402
from hcid.arx.response import path_response  # noqa: E402
from hcid.arx.simulation import simulate  # noqa: E402
from hcid.assembly.resolve import load_config  # noqa: E402
from hcid.loop.hcmodel import plant, true_response  # noqa: E402
from hcid.loop.simulate import simulate_realization  # noqa: E402
from hcid.selection.criteria import w_bic  # noqa: E402
from hcid.selection.over_w import select_at  # noqa: E402

REPEATS = 5
ESTIMATION, VALIDATION = slice(128, 1088), slice(1088, 2048)  # SPEC 3, direct
DIRECT_GRID = Grid(na=(1, 7), nb1=(0, 7), nb2=(0, 7), nk1=(1, 50), nk2=(1, 10))
TRUE = {
    "Kpe": 0.75,
    "TL": 0.4,
    "tau_pe": 0.24,
    "w_nms": 10.1,
    "zeta_nms": 0.35,
    "Kpt": 0.8,
    "TI": 0.25,
    "tau_pt": 0.35,
}


def _timed(function):
    seconds, result = [], None
    for _ in range(REPEATS):
        start = time.perf_counter()
        result = function()
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), result


def _errors(fit):
    parts = []
    for name, value in fit.values.items():
        if name.startswith("tau"):
            parts.append(f"{name} {1e3 * (value - TRUE[name]):+.2f} ms")
        else:
            parts.append(f"{name} {100 * (value / TRUE[name] - 1):+.4f}%")
    return ", ".join(parts)


def _estimates(fit):
    return ", ".join(
        f"{n} {v:.3f}{'*' if hit else ''}"
        for n, v, hit in zip(fit.names, fit.estimates, fit.at_bound, strict=True)
    )


def main():
    config = load_config(PAPER_CONFIG)
    yc = plant(config.loop)
    model = config.model("FF")
    omega = hcfit.band_grid(config.disturbance.band)

    print("1. noise-free FF, default settings")
    hft, he = true_response(model, config.loop, omega)
    seconds, fit = _timed(lambda: hcfit.fit_frequency(omega, he, hft, yc))
    print(f"  frequency fit: median {seconds:.3f} s;  {_errors(fit)}")
    r = simulate_realization(config, model, seed=1, kn=0.0)
    record = hcfit.TrackingRecord(r.ft, r.e, r.u, 25.0, ESTIMATION, VALIDATION)
    seconds, fit = _timed(lambda: hcfit.fit_time(record, yc, True))
    print(f"  time fit:      median {seconds:.3f} s;  {_errors(fit)}")
    for oversample in (1, 2):
        settings = hcfit.FitSettings(oversample=oversample)
        start = time.perf_counter()
        fit = hcfit.fit_time(record, yc, True, settings)
        print(f"  time fit, oversample {oversample}: {time.perf_counter() - start:.3f} s;  {_errors(fit)}")

    print("2. paper record FF, seed 1, with remnant; direct method at W_BIC")
    data = paper_record("FF", 1)
    clean = simulate_realization(config, model, seed=1, kn=0.0)  # ft unshifted (remnant-free)
    grid = fit_grid(data["ft_s"], data["e"], data["u"], DIRECT_GRID, ESTIMATION, VALIDATION)
    orders = np.column_stack([grid.na, grid.nb1, grid.nb2, grid.nk1, grid.nk2])
    row = int(select_at(grid.d, grid.v, orders, np.array([w_bic(960)]))[0])
    a, b1, b2 = grid.a[row], grid.b1[row], grid.b2[row]
    print(f"  selected (na, nb_ft, nb_e, nk_ft, nk_e) = {tuple(int(x) for x in orders[row])}")
    dt = 1 / 25.0
    h_ft = path_response(a, b1, int(grid.nk1[row]), omega, dt, advance=1.0) if b1.size else None
    h_e = path_response(a, b2, int(grid.nk2[row]), omega, dt)
    record = hcfit.TrackingRecord(clean.ft, data["e"], data["u"], 25.0, ESTIMATION, VALIDATION)
    seconds, fit = _timed(lambda: hcfit.fit_frequency(omega, h_e, h_ft, yc, record=record))
    print(f"  frequency fit: median {seconds:.3f} s, VAF_val {fit.vaf_validation:.2f}%: {_estimates(fit)}")
    seconds, fit = _timed(lambda: hcfit.fit_time(record, yc, h_ft is not None))
    print(f"  time fit:      median {seconds:.3f} s, VAF_val {fit.vaf_validation:.2f}%: {_estimates(fit)}")
    u_arx = simulate(a, b1, b2, int(grid.nk1[row]), int(grid.nk2[row]), data["ft_s"], data["e"])
    print(f"  ARX VAF_val {grid.vaf_validation[row]:.2f}%   (* = at a bound)")
    for label, u_hat in (("ARX", u_arx), ("time fit", hcfit.simulate_hc(fit.values, yc, record))):
        start = time.perf_counter()
        res = analyse_residuals(
            data["u"] - u_hat, {"ft": clean.ft, "e": data["e"]}, VALIDATION, 25, rate=25.0
        )
        took = time.perf_counter() - start
        shares = ", ".join(f"{s['signal']} {100 * s['share_outside']:.0f}%" for s in res.summary_rows())
        print(f"  residuals of {label} ({1e3 * took:.1f} ms): lags outside the 99% band: {shares}")


if __name__ == "__main__":
    main()
