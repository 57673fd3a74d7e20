"""How much of a twin's identification depends on its forcing functions alone (issue 47, item 2).

Twins of one forcing set share ft and fd; only their remnant differs. What could be computed once
per set instead of once per twin is what reads ft and fd alone: in the indirect method's stage 1
(inputs ft and fd, output e) the inputs' padding, their tap vectors and the QR of their lag
columns (the first block of the stage's record factor; the output's lag columns and every
candidate's fit and simulation depend on the twin's e); in the direct method only ft's padding
and tap vectors (its second input is e). This script times both methods' whole identification of
one twin-like record (configs/integrator_example.yaml's loop simulated by hcid, 800 samples at
20 Hz: the lab example's twins) and that forcing-only work, single-threaded as hcid's workers
run (BLAS pinned to one thread), best of ``--repeat``.

Run: ``.venv/bin/python benchmarks/forcing_share.py [--repeat 5] [--smoke]`` (``--smoke``: one repeat)
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from cold_start import _cpu  # the machine, named as every benchmark names it
from threadpoolctl import threadpool_limits

import hcid
from hcid.arx.engine import _record_factor, _tap_vectors, fit_grid
from hcid.arx.grid import max_lag
from hcid.arx.simulation import padded
from hcid.assembly.resolve import load_config
from hcid.loop.simulate import remnant_gain, simulate_realization
from hcid.methods.indirect import _stage1_rows

ROOT = Path(__file__).resolve().parents[1]
RATE, SAMPLES = 20.0, 800


def twin_record() -> hcid.Record:
    config = load_config(ROOT / "configs" / "integrator_example.yaml")
    timing = dataclasses.replace(
        config.timing, sim_rate=100.0, output_rate=RATE, run_in=10.0, window=80.0, periods=1
    )
    config = dataclasses.replace(config, timing=timing)
    r = simulate_realization(config, config.models[-1], 1, remnant_gain(config))
    last = slice(r.t.size - SAMPLES, None)
    return hcid.Record(1, RATE, r.t[last] - r.t[last][0], r.ft[last], r.fd[last], r.e[last], r.u[last])


def best(func, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--smoke", action="store_true", help="one repeat (a test)")
    args = parser.parse_args()
    if args.smoke:
        args.repeat = 1
    record = twin_record()
    settings = hcid.identification_settings(RATE, SAMPLES)
    stage = settings.stage("stage1")
    est, _ = _stage1_rows(settings, SAMPLES)
    pad = max_lag(stage.grid)
    ft, fd, e = record.ft, record.fd, record.e

    def forcing_only() -> None:
        i1p, i2p = padded(ft, pad), padded(fd, pad)
        _tap_vectors(i1p), _tap_vectors(i2p)
        k, g = np.arange(est.start, est.stop), stage.grid
        lags = [
            i1p[pad + k[:, None] - np.arange(g.nk1[0], g.nk1[1] + g.nb1[1])],
            i2p[pad + k[:, None] - np.arange(g.nk2[0], g.nk2[1] + g.nb2[1])],
        ]
        np.linalg.qr(np.concatenate(lags, axis=1), mode="r")

    with threadpool_limits(limits=1, user_api="blas"):
        for method in ("direct", "indirect"):
            hcid.identify(record, method, settings)  # compiled before timing
        whole = {
            m: best(lambda m=m: hcid.identify(record, m, settings), args.repeat)
            for m in ("direct", "indirect")
        }
        stage1 = best(lambda: fit_grid(ft, fd, e, stage.grid, *_stage1_rows(settings, SAMPLES)), args.repeat)
        shared = best(forcing_only, args.repeat)
        factor = best(
            lambda: _record_factor(padded(ft, pad), padded(fd, pad), e, stage.grid, pad, est.start, est.stop),
            args.repeat,
        )
    total = whole["direct"] + whole["indirect"]
    print(f"machine: {_cpu()}; one twin-like record, {SAMPLES} samples at {RATE:g} Hz, best of {args.repeat}")
    direct, indirect, first = (1000 * t for t in (whole["direct"], whole["indirect"], stage1))
    print(f"identification: direct {direct:.1f} ms, indirect {indirect:.1f} ms (stage 1 {first:.1f} ms)")
    print(f"stage 1's whole record factor (QR with the output's lags): {1000 * factor:.2f} ms")
    print(
        f"forcing-only work (padding, tap vectors, QR of ft's and fd's lag columns): {1000 * shared:.2f} ms, "
        f"{100 * shared / total:.2f}% of both methods' identification: what computing it once per set "
        "could save"
    )


if __name__ == "__main__":
    main()
