"""How many samples pruning could save at most, on the paper's direct grid (issue 14).

The engine stops a candidate once its partial V exceeds the best V of its
order triple found so far, checked at the end of each 128-sample chunk, and a
batch of lanes runs until its last lane stops. This script bounds what any
pruning of that kind could reach: it gives every candidate the *final* best V
of its triple as the bound from the start and stops it at the very sample its
partial V passes that bound (and, for comparison, at the end of that chunk).

On a random sample of the stable candidates of one paper record (FF, seed 1),
coefficients from the least-squares reference, simulated from rest over the
2048 samples (SPEC 3). The first 1088 samples come before the validation
rows, so no pruning can skip them. Prints the mean samples per candidate
under each rule, beside the engine's own count.
"""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import numpy as np  # noqa: E402
from _paper_record import paper_record  # noqa: E402
from naive import fit_reference  # noqa: E402 (the tests' slow twin)

from hcid.arx import Grid  # noqa: E402
from hcid.arx.engine import _fit_grid  # noqa: E402
from hcid.arx.simulation import simulate  # noqa: E402

GRID = Grid(na=(1, 7), nb1=(0, 7), nb2=(0, 7), nk1=(1, 50), nk2=(1, 10))  # SPEC 3, direct
ESTIMATION, VALIDATION = slice(128, 1088), slice(1088, 2048)
CHUNK = 128  # hcid.arx._lanes._CHUNK: the engine checks its bound once per chunk
SAMPLE = 3000


def main() -> None:
    r = paper_record()
    i1, i2, o = r["ft_s"], r["e"], r["u"]
    n, first = o.size, VALIDATION.start
    fit, _ = _fit_grid(
        i1, i2, o, GRID, ESTIMATION, VALIDATION, 1, True, unpruned=False, fused=True
    )  # every V
    _, counts = _fit_grid(
        i1, i2, o, GRID, ESTIMATION, VALIDATION, 1, False, unpruned=False, fused=True
    )  # pruned
    cand = fit.candidates.to_pydict()
    na, nb1, nb2, nk1, nk2, v = (np.asarray(cand[c]) for c in ("na", "nb1", "nb2", "nk1", "nk2", "v"))
    # Each triple's final best V: the frontier's (recomputed unfused), where the engine prunes
    # against the fused search's; they differ by rounding (hcid.arx.fit_grid, fused).
    best = {(a, b, c): x for a, b, c, x in zip(fit.na, fit.nb1, fit.nb2, fit.v, strict=True)}
    stable = np.flatnonzero(np.isfinite(v))
    pick = np.random.default_rng(1).choice(stable, min(SAMPLE, stable.size), replace=False)
    orders = (na[pick], nb1[pick], nb2[pick], nk1[pick], nk2[pick])
    ref = fit_reference(i1, i2, o, *orders, ESTIMATION, VALIDATION)
    exact, chunked = [], []
    for j, c in enumerate(pick):
        y = simulate(ref.a[j], ref.b1[j], ref.b2[j], nk1[c], nk2[c], i1, i2)
        partial = np.cumsum((y[first:] - o[first:]) ** 2) / (n - first)
        over = np.flatnonzero(partial > best[(na[c], nb1[c], nb2[c])])
        if over.size == 0:  # the triple's best (or a tie): simulated in full
            exact.append(n)
            chunked.append(n)
        else:
            exact.append(first + over[0] + 1)
            chunked.append(min(first + (over[0] // CHUNK + 1) * CHUNK, n))
    _, _, samples = counts.sum(axis=0)
    print(f"direct grid, {pick.size:,} of {stable.size:,} stable candidates, {n:,} samples each in full")
    print("  samples per stable candidate:")
    print(f"  engine (this commit)                      {samples / stable.size:7,.0f}")
    print(f"  final best as the bound, per chunk        {np.mean(chunked):7,.0f}")
    print(f"  final best as the bound, per sample       {np.mean(exact):7,.0f}")
    print(f"  before the validation rows (no pruning)   {first:7,}")


if __name__ == "__main__":
    main()
