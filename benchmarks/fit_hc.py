"""Benchmark of one ``hcid fit-hc`` task (``make bench``): wall time per record and method.

Paper config, default fit settings, one core. For 3 seeds of each model
(FB, FF) and each method, the record is identified on the paper grids (not
timed) and the model selected at W_BIC. Then, for each estimator
(``closed_loop``, ``time``, ``frequency``), side by side on the same selected
models: the parametric fit alone (:func:`hcid.analysis.selected.fit_selected`) and the
whole task, fit plus loop descriptors plus residual analysis
(:func:`hcid.analysis.selected.analyse_selected`, what one fit-hc task does per W).
Prints the median wall times per estimator, and per model and method for the
config's own estimator.

Run: ``.venv/bin/python benchmarks/fit_hc.py``.
"""

import os

# One core for BLAS too, before numpy is imported.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import dataclasses  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _paper_record import PAPER_CONFIG  # noqa: E402

import hcid  # noqa: E402
from hcid import methods  # noqa: E402
from hcid.analysis.selected import analyse_selected, fit_selected  # noqa: E402
from hcid.hcfit import TARGETS  # noqa: E402
from hcid.io.resolve import load_config  # noqa: E402
from hcid.loop.hcmodel import plant  # noqa: E402
from hcid.loop.simulate import remnant_gain, simulate_realization  # noqa: E402
from hcid.selection.criteria import w_bic  # noqa: E402

SEEDS = (1, 2, 3)


def main() -> None:
    config = load_config(PAPER_CONFIG)
    kn = remnant_gain(config)
    rate = config.timing.output_rate
    yc = plant(config.loop)
    cases = []  # (model, method name, method, selected model, record, choices)
    for model in config.models:
        for seed in SEEDS:
            r = simulate_realization(config, model, seed, kn)
            record = {"ft": r.ft, "fd": r.fd, "e": r.e, "u": r.u}
            t = np.arange(r.u.size) / rate
            for name, method in methods.METHODS.items():
                result = hcid.identify(hcid.Record(seed, rate, t, **record), name, config.identify)
                selected = result.select(w_bic(method.nf(config.identify)))
                cases.append((model.name, name, method, selected, record, result.choices))
    print(f"fit-hc task per record and method, one core, W = W_BIC, {len(cases)} selected models")
    print(f"{'estimator':<12}{'fit median s':>13}{'fit max s':>10}{'task median s':>14}")
    per_case = {}
    for target in TARGETS:
        settings = dataclasses.replace(config.fit_hc, target=target)
        cfg = dataclasses.replace(config, fit_hc=settings)
        fits, tasks = [], []
        for model, name, method, sel, record, choices in cases:
            start = time.perf_counter()
            fit_selected(sel, record, yc, settings, config.loop.disturbance_at)
            fits.append(time.perf_counter() - start)
            start = time.perf_counter()
            analyse_selected(sel, record, cfg, method, choices)
            tasks.append(time.perf_counter() - start)
            if target == config.fit_hc.target:
                per_case.setdefault((model, name), []).append((tasks[-1], sel.orders))
        print(
            f"{target:<12}{statistics.median(fits):>13.3f}{max(fits):>10.3f}{statistics.median(tasks):>14.3f}"
        )
    print(f"\nthe config's estimator ({config.fit_hc.target}), whole task per model and method:")
    print(f"{'model':<6}{'method':<10}{'median s':>10}{'max s':>8}   selected (na, nb_ft, nb_e, nk_ft, nk_e)")
    for (model, name), found in per_case.items():
        seconds = [s for s, _ in found]
        print(
            f"{model:<6}{name:<10}{statistics.median(seconds):>10.2f}{max(seconds):>8.2f}   "
            + ", ".join(str(o) for _, o in found)
        )


if __name__ == "__main__":
    main()
