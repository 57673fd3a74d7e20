"""The generalized Pareto tail's p-values on real twins (issue 47; SPEC 13): level and power
against plain Monte Carlo, from the FB and FF twins of analysed studies.

    .venv/bin/python benchmarks/tail_calibration.py RUN_DIR [RUN_DIR ...] [--seed 1]

From each run directory's ``evidence_twins.parquet``, every group, method and forcing set with at
least 99 FB twins: each FB twin in turn stands for a run without feedforward, its null ``N`` other
FB twins of the same set drawn at random (N = 19, 39, 98), and its p-value is made by Monte Carlo
(``(1 + k) / (1 + N)``) and as ``hcid analyse`` makes it ("tail" below:
:func:`hcid.pipeline.evidence.run_p_value`, sequential, and the generalized Pareto tail beyond
every twin); each FF twin stands for a run with the group's feedforward (the power).
Under the null every p-value is uniform, so P(p <= a) must be a (within its binomial band); the
held-out twins of a set share their nulls, so the p-values are not independent and the bands are
indicative, not exact. Both statistics (W* and the Fourier size) are used. The KS test is of
hcid's p with each Monte Carlo p spread uniformly over its step (a discrete p is never uniform;
the spread one is, where exact).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from scipy import stats

from hcid.selection.calibration import run_p_value

NULLS = (19, 39, 98)
LEVELS = (0.01, 0.05)


def pools(run_dirs: list[Path]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(method, FB values, FF values) per run directory, group, method, set and statistic, on the
    log scale, where at least 99 FB values are finite and positive."""
    out = []
    for run in run_dirs:
        rows = pq.read_table(run / "evidence_twins.parquet").to_pylist()
        keys = sorted({(r["group"], r["method"], r["forcing_set"]) for r in rows})
        for key in keys:
            for stat in ("w_star", "fourier_size"):
                vals = {
                    twin: np.array(
                        [
                            r[stat]
                            for r in rows
                            if (r["group"], r["method"], r["forcing_set"]) == key and r["twin"] == twin
                        ]
                    )  # fmt: skip
                    for twin in ("FB", "FF")
                }
                fb, ff = (v[np.isfinite(v) & (v > 0)] for v in (vals["FB"], vals["FF"]))
                if fb.size >= 99:
                    out.append((key[1], np.log(fb), np.log(ff)))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    sets = pools(args.runs)
    if not sets:
        sys.exit("no set with 99 FB twins in these run directories")
    print(f"{len(sets)} sets of 99+ FB twins (with their 20 FF twins) from {len(args.runs)} run directories")
    ways = [(m, n, how) for m in ("direct", "indirect") for n in NULLS for how in ("monte carlo", "tail")]
    null, power = {w: [] for w in ways}, {w: [] for w in ways}
    spread = {(m, n): [] for m in ("direct", "indirect") for n in NULLS}
    methods_used = {n: [] for n in NULLS}
    for method, fb, ff in sets:
        for n in NULLS:
            for i in range(fb.size):
                others = np.delete(fb, i)
                nulls = rng.choice(others, size=min(n, others.size), replace=False)
                k = np.count_nonzero(nulls >= fb[i])
                null[(method, n, "monte carlo")].append((1 + k) / (1 + nulls.size))
                p, used, how = run_p_value(float(np.exp(fb[i])), np.exp(nulls))
                null[(method, n, "tail")].append(p)
                methods_used[n].append(how)
                if how == "monte carlo":  # spread over its step, for the KS test of a discrete p
                    low = 5 / (used + 1) if used < nulls.size else p - 1 / (nulls.size + 1)
                    p = low + rng.random() * (p - low)
                spread[(method, n)].append(p)
            for x in ff:
                nulls = rng.choice(fb, size=min(n, fb.size), replace=False)
                k = np.count_nonzero(nulls >= x)
                power[(method, n, "monte carlo")].append((1 + k) / (1 + nulls.size))
                power[(method, n, "tail")].append(run_p_value(float(np.exp(x)), np.exp(nulls))[0])
    print("\n| method | N null | p made by | null runs | P(p <= 0.01) [99% band] | P(p <= 0.05) [99% band] "
          "| KS p | FF twins | power at 0.01 | power at 0.05 |\n" + "|---" * 10 + "|")  # fmt: skip
    for (method, n, how), p in null.items():
        p = np.array(p)
        cells = []
        for a in LEVELS:
            lo, hi = stats.binom.ppf([0.005, 0.995], p.size, a) / p.size
            cells.append(f"{np.mean(p <= a):.4f} [{lo:.4f}, {hi:.4f}]")
        ks = stats.kstest(spread[(method, n)], "uniform").pvalue if how == "tail" else math.nan
        q = np.array(power[(method, n, how)])
        print(f"| {method} | {n} | {how} | {p.size} | {cells[0]} | {cells[1]} | {ks:.3g} | {q.size} | "
              f"{np.mean(q <= 0.01):.3f} | {np.mean(q <= 0.05):.3f} |")  # fmt: skip
    for n in NULLS:
        used = np.array(methods_used[n])
        print(f"N = {n}: the tail made {np.mean(used == 'gpd tail'):.1%} of the null runs' p-values")


if __name__ == "__main__":
    main()
