"""Benchmark of one ``hcid fit-hc`` task (``make bench``): wall time per record and method.

Paper config, default fit settings, one core. For 3 seeds of each model
(FB, FF) and each method, the record is identified on the paper grids (not
timed), the model selected at W_BIC, and then timed: the parametric fit and
the residual analysis of that model (:func:`hcid.selected.analyse_selected`,
what one fit-hc task does per W). Prints the median wall time per model and
method, and over all, with the estimates' spread.

Run: ``.venv/bin/python benchmarks/fit_hc.py``.
"""

import os

# One core for BLAS too, before numpy is imported.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _paper_record import PAPER_CONFIG  # noqa: E402

import hcid  # noqa: E402
from hcid import methods  # noqa: E402
from hcid.criteria import w_bic  # noqa: E402
from hcid.resolve import load_config  # noqa: E402
from hcid.selected import analyse_selected  # noqa: E402
from hcid.simulate import remnant_gain, simulate_realization  # noqa: E402

SEEDS = (1, 2, 3)


def main() -> None:
    config = load_config(PAPER_CONFIG)
    kn = remnant_gain(config)
    rate = config.timing.output_rate
    print(f"fit-hc task (fit target {config.fit_hc.target}, default settings), one core, W = W_BIC")
    print(f"{'model':<6}{'method':<10}{'median s':>10}{'max s':>8}   selected (na, nb_ft, nb_e, nk_ft, nk_e)")
    everything = []
    for model in config.models:
        records = {}
        for seed in SEEDS:
            r = simulate_realization(config, model, seed, kn)
            records[seed] = {"ft": r.ft, "fd": r.fd, "e": r.e, "u": r.u}
        for name, method in methods.METHODS.items():
            w = w_bic(method.nf(config.identify))
            seconds, structures = [], []
            for seed, record in records.items():
                t = np.arange(record["u"].size) / rate
                result = hcid.identify(hcid.Record(seed, rate, t, **record), name, config.identify)
                sel = result.select(w)
                start = time.perf_counter()
                analyse_selected(sel, record, config, method, result.choices)
                seconds.append(time.perf_counter() - start)
                structures.append(sel.orders)
            everything += seconds
            print(
                f"{model.name:<6}{name:<10}{statistics.median(seconds):>10.2f}{max(seconds):>8.2f}   "
                + ", ".join(str(s) for s in structures)
            )
    print(f"all: median {statistics.median(everything):.2f} s per record and method")


if __name__ == "__main__":
    main()
