"""How many samples pruning could save at most, on the paper's grids (issues 14 and 47).

The engine stops a candidate once its partial V exceeds the best V of its
order triple found so far, checked at the end of each 128-sample chunk, and a
batch of lanes runs until its last lane stops. This script bounds what any
pruning of that kind could reach: it gives every candidate a *final* best V as
the bound from the start and stops it at the very sample its partial V passes
that bound (and, for comparison, at the end of that chunk). Two bounds:

- its order triple's final best (what the frontier needs: the engine's rule);
- the final best of every candidate that could replace it in what a stage
  uses (issue 47): on stage 1's grid, whose choice is the smallest V of the
  whole grid (SPEC 3), the grid's best; on the direct grid, where the selection
  over W reads only the smallest V of each number of parameters d with and
  without feedforward (SPEC 4), the best of its (d, nb_ft > 0).

On a random sample of the stable candidates of one paper record (FF, seed 1),
coefficients from the least-squares reference, simulated from rest over the
2048 samples (SPEC 3). Samples before the validation rows cannot be skipped
(1088 on the direct grid, 29 on stage 1's). Prints the mean samples per
candidate under each rule, beside the engine's own count.
"""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import numpy as np  # noqa: E402
from _paper_record import paper_record  # noqa: E402
from naive import fit_reference  # noqa: E402 (the tests' slow twin)

from hcid.arx import Grid  # noqa: E402
from hcid.arx.engine import _fit_grid  # noqa: E402
from hcid.arx.grid import n_parameters  # noqa: E402
from hcid.arx.simulation import simulate  # noqa: E402

CHUNK = 128  # hcid.arx._lanes._CHUNK: the engine checks its bound once per chunk
SAMPLE = 3000
#: (name, grid, inputs and output from the record, estimation rows, validation rows,
#: what the stage needs of each candidate: the key of the candidates whose best it must know)
GRIDS = (
    (
        "direct",
        Grid(na=(1, 7), nb1=(0, 7), nb2=(0, 7), nk1=(1, 50), nk2=(1, 10)),
        ("ft_s", "e", "u"),
        slice(128, 1088),
        slice(1088, 2048),
        lambda na, nb1, nb2: (int(n_parameters(na, nb1, nb2)), nb1 > 0),
        "the best of its (d, nb_ft > 0)",
    ),
    (
        "stage 1",
        Grid(na=(1, 10), nb1=(0, 25), nb2=(0, 10), nk1=(1, 5), nk2=(1, 5)),
        ("ft_s", "fd", "e"),
        slice(29, 2048),
        slice(29, 2048),
        lambda na, nb1, nb2: 0,
        "the grid's best",
    ),
)


def ceiling(r, name, grid, names, estimation, validation, needed, label) -> None:
    i1, i2, o = (r[signal] for signal in names)
    n, first = o.size, validation.start
    # Every V, then the engine as it runs.
    fit, _ = _fit_grid(i1, i2, o, grid, estimation, validation, 1, True, unpruned=False, fused=True)
    _, counts = _fit_grid(i1, i2, o, grid, estimation, validation, 1, False, unpruned=False, fused=True)
    cand = fit.candidates.to_pydict()
    na, nb1, nb2, nk1, nk2, v = (np.asarray(cand[c]) for c in ("na", "nb1", "nb2", "nk1", "nk2", "v"))
    stable = np.flatnonzero(np.isfinite(v))
    # The final bests from the search's V (fused, as the engine prunes against; they differ
    # from the frontier's unfused V by rounding: hcid.arx.fit_grid, fused).
    triple, shared = {}, {}
    for c in stable:
        key = (na[c], nb1[c], nb2[c])
        triple[key] = min(triple.get(key, np.inf), v[c])
        group = needed(*key)
        shared[group] = min(shared.get(group, np.inf), v[c])
    pick = np.random.default_rng(1).choice(stable, min(SAMPLE, stable.size), replace=False)
    orders = (na[pick], nb1[pick], nb2[pick], nk1[pick], nk2[pick])
    ref = fit_reference(i1, i2, o, *orders, estimation, validation)
    samples = {"triple": ([], []), "shared": ([], [])}
    for j, c in enumerate(pick):
        y = simulate(ref.a[j], ref.b1[j], ref.b2[j], nk1[c], nk2[c], i1, i2)
        partial = np.cumsum((y[first:] - o[first:]) ** 2) / (validation.stop - first)
        key = (na[c], nb1[c], nb2[c])
        for rule, bound in (("triple", triple[key]), ("shared", shared[needed(*key)])):
            over = np.flatnonzero(partial > bound)
            exact, chunked = samples[rule]
            if over.size == 0:  # the best (or a tie): simulated in full
                exact.append(n)
                chunked.append(n)
            else:
                exact.append(first + over[0] + 1)
                chunked.append(min(first + (over[0] // CHUNK + 1) * CHUNK, n))
    print(f"{name}: {pick.size:,} of {stable.size:,} stable candidates, {n:,} samples each in full")
    print("  samples per stable candidate:")
    print(f"  engine (this commit)                          {counts[:, 2].sum() / stable.size:7,.0f}")
    for rule, what in (("triple", "its triple's final best"), ("shared", label)):
        exact, chunked = samples[rule]
        print(f"  bound {what + ',':32} per chunk  {np.mean(chunked):7,.0f}")
        print(f"  bound {what + ',':32} per sample {np.mean(exact):7,.0f}")
    print(f"  before the validation rows (no pruning)       {first:7,}")


def main() -> None:
    r = paper_record()
    for spec in GRIDS:
        ceiling(r, *spec)


if __name__ == "__main__":
    main()
