"""Benchmark of hcid.arx.fit_grid against its old kernel and the slow reference (``make bench``).

On one paper record (FF, seed 1), on one core, side by side in one run:
the engine (pruned, 16 candidates per batch of vector lanes, fused
multiply-adds in its search, as hcid runs it), the engine unfused, the old
kernel (one candidate at a time, every candidate simulated in full,
unfused; the engine's twin in the tests) and the reference loop (lstsq +
lfilter + roots) on a random sample of the same grid; then the stage-1 grid
and stage 2 (the direct grid with stage 1's output e_r), whose rates per
candidate the issue compares, timed alternately; and stage 1 as the indirect
method runs it (``best_only``) against the whole frontier's search. Repeats alternate between
the configurations so that load from other work on the machine hits them
alike. Both engines' frontiers must equal the old kernel's bit for bit, and the
engine must agree with the reference loop on the sample, and ``best_only``'s
best row must equal the whole search's; the script exits with code 1 where
one does not.

``--smoke``: small grids, one repeat, a small sample; every path of this
script in a few seconds, no figure worth keeping.

Run: ``.venv/bin/python benchmarks/arx_engine.py [--smoke]``.
"""

import os

# One core for BLAS too, before numpy is imported.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402
from _paper_record import paper_record  # noqa: E402
from naive import fit_reference  # noqa: E402 (the tests' slow twin)

from hcid.arx import Grid, candidates  # noqa: E402
from hcid.arx.engine import _fit_grid, best  # noqa: E402
from hcid.arx.simulation import simulate  # noqa: E402

# SPEC section 3.
DIRECT_GRID = Grid(na=(1, 7), nb1=(0, 7), nb2=(0, 7), nk1=(1, 50), nk2=(1, 10))
STAGE1_GRID = Grid(na=(1, 10), nb1=(0, 25), nb2=(0, 10), nk1=(1, 5), nk2=(1, 5))
DIRECT_ROWS = (slice(128, 1088), slice(1088, 2048))
STAGE1_ROWS = (slice(29, 2048), slice(29, 2048))
#: The largest relative difference in V between the engine and the reference loop taken as
#: agreement (their sums of squares differ in rounding only).
REFERENCE_RTOL = 1e-8


@dataclass(frozen=True)
class Settings:
    """The grids, the repeats (best of) and the reference loop's sample of one benchmark run."""

    direct_grid: Grid
    stage1_grid: Grid
    repeats: int
    rate_repeats: int
    reference_sample: int


FULL = Settings(DIRECT_GRID, STAGE1_GRID, repeats=3, rate_repeats=5, reference_sample=1000)
SMOKE = Settings(
    Grid(na=(1, 2), nb1=(0, 2), nb2=(0, 2), nk1=(1, 3), nk2=(1, 2)),
    Grid(na=(1, 2), nb1=(0, 3), nb2=(0, 2), nk1=(1, 2), nk2=(1, 2)),
    repeats=1,
    rate_repeats=1,
    reference_sample=50,
)


def _fit(signals, grid, rows, unpruned, *, fused, keep=False):
    return _fit_grid(*signals, grid, *rows, 1, keep, unpruned=unpruned, fused=fused)


def _same_frontier(one, two) -> bool:
    names = ("na", "nb1", "nb2", "nk1", "nk2", "v", "vaf_estimation", "vaf_validation", "n_unstable")
    same = all(np.array_equal(getattr(one, n), getattr(two, n), equal_nan=True) for n in names)
    for name in ("a", "b1", "b2"):
        same &= all(np.array_equal(x, y) for x, y in zip(getattr(one, name), getattr(two, name), strict=True))
    return bool(same and one.n_unstable_total == two.n_unstable_total)


def _side_by_side(label, signals, grid, rows, repeats, failures):
    """Best of ``repeats`` for the engine (fused, as hcid runs it, and unfused) and the old kernel,
    alternating; their frontiers compared (a difference appended to ``failures``). Returns the
    candidate rates of the fused engine and the old kernel."""
    configs = {"engine, fused": (False, True), "engine, unfused": (False, False), "old kernel": (True, False)}
    seconds = {name: [] for name in configs}
    fits = {}
    for _ in range(repeats):
        for name, (unpruned, fuse) in configs.items():
            start = time.perf_counter()
            fits[name] = _fit(signals, grid, rows, unpruned, fused=fuse)
            seconds[name].append(time.perf_counter() - start)
    engine = "engine, fused"
    new, new_counts = fits[engine]
    old = fits["old kernel"][0]
    n = new.n_candidates
    for name, values in seconds.items():
        best = min(values)
        print(f"{label + ', ' + name:<34} best {best:7.3f} s  {best / n * 1e6:6.2f} us/candidate  "
              f"({n:,} candidates)")  # fmt: skip
    for name in configs:
        if name != "old kernel":
            ratio = min(seconds["old kernel"]) / min(seconds[name])
            same = _same_frontier(fits[name][0], old)
            print(f"{label + ', ' + name + ' vs old':<34} {ratio:7.2f} x   frontier identical: {same}")
            if not same:
                failures.append(f"{label}: the frontier of the {name} differs from the old kernel's")
    ratio = min(seconds["engine, unfused"]) / min(seconds["engine, fused"])
    print(f"{label + ', fused vs unfused':<34} {ratio:7.2f} x")
    full, pruned, samples = new_counts.sum(axis=0)
    stable = n - new.n_unstable_total
    print(f"{label + ', simulated':<34} {full:,} in full, {pruned:,} pruned of {stable:,} stable; "
          f"{samples / stable:,.0f} samples per stable candidate (old: {len(signals[0]):,})")  # fmt: skip
    return n / min(seconds[engine]), n / min(seconds["old kernel"])


def _best_only(label, signals, grid, rows, repeats, failures):
    """Stage 1 as the indirect method runs it (``best_only``: its choice is the grid's smallest V)
    against the whole frontier's search, alternating, best of ``repeats``; their best rows
    compared (a difference appended to ``failures``)."""
    seconds = {False: [], True: []}
    fits = {}
    for _ in range(repeats):
        for best_only in (False, True):
            start = time.perf_counter()
            fits[best_only] = _fit_grid(*signals, grid, *rows, 1, False, unpruned=False, fused=None,
                                        best_only=best_only)  # fmt: skip
            seconds[best_only].append(time.perf_counter() - start)
    (whole, whole_counts), (found, counts) = fits[False], fits[True]
    a, b = best(whole), best(found)
    same = a == b and all(
        np.array_equal(getattr(whole, n)[a], getattr(found, n)[b])
        for n in ("nk1", "nk2", "v", "vaf_estimation", "a", "b1", "b2")
    )
    ratio = min(seconds[False]) / min(seconds[True])
    stable = whole.n_candidates - whole.n_unstable_total
    print(f"{label + ', best_only vs whole':<34} {ratio:7.2f} x   best row identical: {same}   "
          f"({min(seconds[True]):.3f} vs {min(seconds[False]):.3f} s; {counts[:, 2].sum() / stable:,.0f} "
          f"vs {whole_counts[:, 2].sum() / stable:,.0f} samples per stable candidate)")  # fmt: skip
    if not same:
        failures.append(f"{label}: best_only's best row differs from the whole search's")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="small grids, one repeat: seconds")
    args = parser.parse_args()
    settings = SMOKE if args.smoke else FULL
    if args.smoke:
        print("smoke run: every path of the benchmark on small grids, figures not worth keeping")
    direct_grid, stage1_grid, repeats = settings.direct_grid, settings.stage1_grid, settings.repeats
    failures = []
    record = paper_record()
    direct = (record["ft_s"], record["e"], record["u"])
    stage1 = (record["ft_s"], record["fd"], record["e"])

    # Warm-up: compile (or load from the cache) every kernel.
    small = Grid(na=(1, 2), nb1=(0, 2), nb2=(0, 2), nk1=(1, 2), nk2=(1, 2))
    for unpruned in (False, True):
        _fit(direct, small, DIRECT_ROWS, unpruned, fused=True)

    engine_rate, old_rate = _side_by_side("direct", direct, direct_grid, DIRECT_ROWS, repeats, failures)

    columns = candidates(direct_grid)
    sample = settings.reference_sample
    pick = np.random.default_rng(0).choice(columns[0].size, sample, replace=False)
    seconds = []
    for _ in range(repeats):  # best of repeats, like the engine: the ratio below is not flattered by noise
        start = time.perf_counter()
        ref = fit_reference(*direct, *(c[pick] for c in columns), *DIRECT_ROWS)
        seconds.append(time.perf_counter() - start)
    reference_rate = sample / min(seconds)
    print(f"{'direct, reference loop (sample)':<34} best {1e6 / reference_rate:7.1f} us/candidate  "
          f"({sample:,} candidates)")  # fmt: skip
    print(f"{'per candidate vs reference loop':<34} engine {engine_rate / reference_rate:6.1f} x   "
          f"old kernel {old_rate / reference_rate:6.1f} x")  # fmt: skip

    full, _ = _fit(direct, direct_grid, DIRECT_ROWS, False, keep=True, fused=True)
    v = full.candidates["v"].to_numpy()[pick]
    both = np.isfinite(v) & ~ref.unstable
    rel = np.abs(v[both] - ref.v[both]) / ref.v[both]
    flags_equal = bool(np.array_equal(np.isinf(v), ref.unstable))
    worst = rel.max() if rel.size else np.nan
    print(
        f"{'agreement on the sample':<34} unstable flags equal: {flags_equal}, max relative V difference "
        f"{worst:.1e} ({both.sum():,} stable candidates)"
    )
    if not (flags_equal and rel.size and worst <= REFERENCE_RTOL):
        failures.append(
            f"direct: the engine disagrees with the reference loop on the sample (rtol {REFERENCE_RTOL})"
        )

    _side_by_side("stage 1", stage1, stage1_grid, STAGE1_ROWS, repeats, failures)
    _best_only("stage 1", stage1, stage1_grid, STAGE1_ROWS, repeats, failures)
    # Stage 2 as the indirect method runs it: the direct grid with e_r, stage 1's best output.
    fit, _ = _fit(stage1, stage1_grid, STAGE1_ROWS, False, fused=True)
    row = best(fit)
    e_r = simulate(fit.a[row], fit.b1[row], fit.b2[row], fit.nk1[row], fit.nk2[row], *stage1[:2])
    stage2 = (record["ft_s"], e_r, record["u"])
    _side_by_side("stage 2", stage2, direct_grid, DIRECT_ROWS, repeats, failures)
    # The comparison of rates, from engine runs that alternate between the
    # two grids: the machine's speed drifts within a run, and the blocks above
    # are timed minutes apart.
    seconds = {"stage 1": [], "stage 2": []}
    for _ in range(settings.rate_repeats):
        for name, signals, grid, rows in (
            ("stage 1", stage1, stage1_grid, STAGE1_ROWS),
            ("stage 2", stage2, direct_grid, DIRECT_ROWS),
        ):
            start = time.perf_counter()
            fit, _ = _fit(signals, grid, rows, False, fused=True)
            seconds[name].append((time.perf_counter() - start) / fit.n_candidates)
    one, two = min(seconds["stage 1"]), min(seconds["stage 2"])
    print(f"{'stage 1 vs stage 2 per candidate':<34} {two / one:7.2f} x the stage-2 rate   (alternating, "
          f"best of {settings.rate_repeats}: {one * 1e6:.2f} vs {two * 1e6:.2f} us/candidate)")  # fmt: skip
    for failure in failures:
        print(f"FAILED: {failure}", file=sys.stderr)
    if failures:
        sys.exit(1)


if __name__ == "__main__":
    main()
