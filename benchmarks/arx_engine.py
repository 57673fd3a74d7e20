"""Benchmark of hcid.arx.fit_grid against the slow reference (``make bench``).

On one paper record (FF, seed 1): the full direct grid (174,447 candidates)
with threads=1, the reference loop (lstsq + lfilter + roots) on a random
sample of the same grid, then threads=2 and the stage-1 grid. Targets: the
direct grid in <= 2 s on one core, >= 25x the reference per candidate.
"""

import os

# One core for BLAS too, before numpy is imported.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _paper_record import paper_record  # noqa: E402

from hcid.arx import Grid, candidates, fit_grid  # noqa: E402
from hcid.arx.reference import fit_reference  # noqa: E402

# SPEC section 3.
DIRECT_GRID = Grid(na=(1, 7), nb1=(0, 7), nb2=(0, 7), nk1=(1, 50), nk2=(1, 10))
STAGE1_GRID = Grid(na=(1, 10), nb1=(0, 25), nb2=(0, 10), nk1=(1, 5), nk2=(1, 5))
DIRECT_ROWS = (slice(128, 1088), slice(1088, 2048))
STAGE1_ROWS = (slice(29, 2048), slice(29, 2048))
REPEATS = 3
REFERENCE_SAMPLE = 2000


def _time(function, repeats=REPEATS):
    """Seconds of each of ``repeats`` calls, and the last result."""
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        seconds.append(time.perf_counter() - start)
    return seconds, result


def _report(label, seconds, n):
    best, median = min(seconds), statistics.median(seconds)
    print(
        f"{label:<34} best {best:7.3f} s  median {median:7.3f} s  "
        f"{n / best:12,.0f} candidates/s  ({n:,} candidates)"
    )
    return n / best


def main():
    record = paper_record()
    direct = (record["ft_s"], record["e"], record["u"])
    stage1 = (record["ft_s"], record["fd"], record["e"])

    # Warm-up: compile (or load from the cache) both kernels.
    small = Grid(na=(1, 2), nb1=(0, 2), nb2=(0, 2), nk1=(1, 2), nk2=(1, 2))
    for threads in (1, 2):
        fit_grid(*direct, small, *DIRECT_ROWS, threads=threads)

    seconds, fit = _time(
        lambda: fit_grid(*direct, DIRECT_GRID, *DIRECT_ROWS, threads=1, keep_candidates=True)
    )
    engine_rate = _report("fit_grid direct, threads=1", seconds, fit.n_candidates)

    columns = candidates(DIRECT_GRID)
    pick = np.random.default_rng(0).choice(columns[0].size, REFERENCE_SAMPLE, replace=False)
    ref_seconds, ref = _time(
        lambda: fit_reference(*direct, *(c[pick] for c in columns), *DIRECT_ROWS), repeats=1
    )
    reference_rate = _report("reference loop, direct sample", ref_seconds, REFERENCE_SAMPLE)
    print(f"{'speed-up per candidate':<34} {engine_rate / reference_rate:7.1f} x")

    v = fit.candidates["v"].to_numpy()[pick]
    both = np.isfinite(v) & ~ref.unstable
    rel = np.abs(v[both] - ref.v[both]) / ref.v[both]
    print(
        f"{'agreement on the sample':<34} unstable flags equal: "
        f"{bool(np.array_equal(np.isinf(v), ref.unstable))}, max relative V difference "
        f"{rel.max():.1e}"
    )

    seconds, _ = _time(lambda: fit_grid(*direct, DIRECT_GRID, *DIRECT_ROWS, threads=2))
    _report("fit_grid direct, threads=2", seconds, fit.n_candidates)
    for threads in (1, 2):
        seconds, fit1 = _time(
            lambda threads=threads: fit_grid(*stage1, STAGE1_GRID, *STAGE1_ROWS, threads=threads)
        )
        _report(f"fit_grid stage 1, threads={threads}", seconds, fit1.n_candidates)
    print(f"{'stage-1 unstable candidates':<34} {fit1.n_unstable_total:,} of {fit1.n_candidates:,}")


if __name__ == "__main__":
    main()
