"""Fit every candidate of an ARX grid to one record (SPEC sections 3 and 4).

:func:`fit_grid` estimates, stability-tests and simulates every candidate of
a :class:`~hcid.arx.grid.Grid` and keeps the frontier: the best candidate of
each order triple ``(na, nb1, nb2)``, the only ones model selection can ever
pick (SPEC section 4). :func:`simulate` and :func:`best` complete the public
interface; the kernels live in :mod:`hcid.arx._kernels` (fitting) and
:mod:`hcid.arx._lanes` (simulating many candidates side by side), the frontier's
outputs in :mod:`hcid.arx._frontier`.
"""

from __future__ import annotations

import functools
import operator

import numpy as np

from hcid.arx import _blocks, _frontier, _kernels, _lanes
from hcid.arx.grid import Grid, candidates, max_lag, order_blocks
from hcid.arx.gridfit import GridFit
from hcid.arx.simulation import checked_rows, checked_signal, padded, simulate
from hcid.errors import IdentificationError

__all__ = ["KERNEL_PARTS", "GridFit", "best", "compile_kernels", "fit_grid", "simulate"]


def _tap_vectors(xp: np.ndarray) -> np.ndarray:
    """The padded input as the vector steps read it (:func:`hcid.arx._lanes.tap_vectors`); empty
    without the JIT, whose plain path reads the input itself."""
    return _lanes.tap_vectors(xp) if _lanes._WIDE else np.empty(0)


def _record_factor(i1p, i2p, o, grid: Grid, pad: int, start: int, stop: int) -> np.ndarray:
    """Transposed R and c = Q^T o of the full lagged matrix (see _kernels)."""
    k = np.arange(start, stop)
    columns = []
    if grid.nb1[1] > 0:
        lags = np.arange(grid.nk1[0], grid.nk1[1] + grid.nb1[1])
        columns.append(i1p[pad + k[:, None] - lags])
    if grid.nb2[1] > 0:
        lags = np.arange(grid.nk2[0], grid.nk2[1] + grid.nb2[1])
        columns.append(i2p[pad + k[:, None] - lags])
    op = padded(o, pad)
    columns.append(-op[pad + k[:, None] - np.arange(1, grid.na[1] + 1)])
    columns.append(o[start:stop, None])
    # R of [Phi, o]: its last column holds c = Q^T o, so Q is never formed.
    r = np.linalg.qr(np.concatenate(columns, axis=1), mode="r")
    p = r.shape[1] - 1
    rt = np.zeros((p + 1, p))
    rows = min(r.shape[0], p)
    rt[:p, :rows] = r[:rows, :p].T
    rt[p, :rows] = r[:rows, p]
    return rt


@functools.lru_cache(maxsize=8)
def _layout(grid: Grid):
    """``(units, order_blocks(grid), candidates(grid))`` of a grid, made once per process for the
    grids a study fits again and again (every record and twin): they depend on the grid alone.
    Nothing writes into them: the kernels read them, and a :class:`GridFit` gets copies
    (``tests/test_arx_engine.py`` checks both)."""
    return _units(grid), order_blocks(grid), candidates(grid)


def _units(grid: Grid) -> np.ndarray:
    """Work units (k1, k2), -1 for a dropped input; heavy pair units first."""
    k1 = range(grid.nk1[0], grid.nk1[1] + 1)
    k2 = range(grid.nk2[0], grid.nk2[1] + 1)
    units = []
    if grid.nb1[1] > 0 and grid.nb2[1] > 0:
        units += [(a, b) for a in k1 for b in k2]
    if grid.nb1[0] == 0 and grid.nb2[1] > 0:
        units += [(-1, b) for b in k2]
    if grid.nb2[0] == 0 and grid.nb1[1] > 0:
        units += [(a, -1) for a in k1]
    if grid.nb1[0] == 0 and grid.nb2[0] == 0:
        units.append((-1, -1))
    return np.array(units, dtype=np.int64).reshape(-1, 2)


def fit_grid(
    i1,
    i2,
    o,
    grid: Grid,
    estimation_rows: slice,
    validation_rows: slice,
    *,
    threads: int = 1,
    keep_candidates: bool = False,
    fused: bool | None = None,
    best_only: bool = False,
) -> GridFit:
    """Fit every candidate of ``grid`` to one record and keep the frontier.

    Each candidate ``A o(k) = B1 i1(k - nk1) + B2 i2(k - nk2) + eps`` is
    estimated by least squares on ``estimation_rows`` (regressors before
    the record are 0), tested for stability (Schur-Cohn step-down on A:
    unstable iff a root has ``|z| >= 1``), simulated over the whole record
    from rest, and scored by ``V = mean((o_hat - o)^2)`` over
    ``validation_rows``. Unstable candidates, those whose simulation is not
    finite and those whose regression matrix is exactly rank deficient get
    ``V = inf`` and are counted in ``n_unstable``.

    Parameters
    ----------
    i1, i2 : array_like of float, shape (n,)
        Inputs (for hcid: rad; i1 is the shifted target ft_s).
    o : array_like of float, shape (n,)
        Output (rad).
    grid : Grid
        Candidate ranges.
    estimation_rows, validation_rows : slice
        Rows (0-based sample indices, step 1) of the least-squares fit and
        of V. The paper's direct windows are ``slice(128, 1088)`` and
        ``slice(1088, 2048)``.
    threads : int, default 1
        Threads of the candidate loop. 1 runs a serial kernel on the
        calling thread (what joblib workers need); more run work units (delay
        pairs) round-robin on that many numba threads, capped at
        ``numba.config.NUMBA_NUM_THREADS``. The result is bit-identical
        whatever ``threads``.
    keep_candidates : bool, default False
        Also return every candidate's orders, delays and V as
        ``GridFit.candidates``.
    fused : bool or None, default None
        Let the search's simulations round each multiply-add once (fused
        multiply-add). None: fused if the CPU numba compiles for has FMA units.
        The frontier does not depend on it: its V and VAF are recomputed from
        its rows' unfused outputs, and a triple whose search is in doubt (a
        near tie, an overflow, a recomputed V off the search's) is searched
        again unfused (docs/engine.md).
    best_only : bool, default False
        Search only for the grid's smallest V (what stage 1 of the indirect
        method keeps, SPEC 3): candidates also stop once their partial V
        exceeds a V already reached in another triple, so a triple that
        cannot hold the grid's best is not searched to its end and its row
        has ``v = NaN``, ``nk1 = nk2 = -1``, NaN VAFs and no coefficients.
        The rows that could (the best and any within the tie margin) are
        searched as without it, and so are the four triples searched first:
        :func:`best` gives the same row, bit for bit. ``n_unstable`` is the
        same unless a stable candidate's output overflows (inputs near
        1e150), which the whole search may reach where this one stops it
        earlier.

    Returns
    -------
    GridFit

    Raises
    ------
    hcid.errors.DataError
        If a signal is not 1-D, finite, and as long as ``i1``.
    hcid.errors.IdentificationError
        If a window is not a slice ``start:stop`` with ``0 <= start < stop <= n``,
        the estimation window has fewer rows than the largest candidate has
        coefficients, ``threads < 1``, or ``best_only`` with ``keep_candidates``
        (which keeps every V).

    Notes
    -----
    Least squares through shared Householder QRs (one of every lagged column,
    one per delay pair, one per ``(nb1, nb2)`` with the output lags last, so
    every ``na`` is a prefix): backward stable, a candidate's coefficients
    carry a relative error of about ``cond(Phi_S) * eps`` like
    :func:`numpy.linalg.lstsq`. The best of an order triple is the smallest V,
    ties to the smaller nk1, then nk2; its coefficients, V and VAF are what
    :func:`simulate` gives bit for bit. Stable candidates are simulated 16 at a
    time in SIMD lanes, and a candidate stops once its partial V exceeds its
    triple's best so far (V only grows), which cannot change the frontier.
    The design, its accuracy against ``lstsq`` + ``lfilter`` and its speed:
    docs/engine.md and docs/benchmarks.md.
    """
    fit, _ = _fit_grid(
        i1,
        i2,
        o,
        grid,
        estimation_rows,
        validation_rows,
        threads,
        keep_candidates,
        unpruned=False,
        fused=fused,
        best_only=best_only,
    )
    return fit


def _fused(fused) -> bool:
    if fused is None:
        return _kernels.has_fma()
    if not isinstance(fused, bool | np.bool_):
        raise IdentificationError(f"fused: must be True, False or None, got {fused!r}")
    return bool(fused)


#: The engine's kernels in two parts of about equal compile time, which two processes can
#: compile at once on a cold cache (:func:`compile_kernels`; docs/engine.md, "Compile time").
KERNEL_PARTS = ("vector", "rest")


def compile_kernels(part: str) -> None:
    """Compile one part of the kernels :func:`fit_grid` runs, or load it from numba's cache,
    with the argument types of every fit, on a record of 64 samples.

    ``vector``: the vector steps (:func:`hcid.arx._blocks.simulate_blocks`, the largest kernel;
    not on a CPU without FMA units, where the default fit never takes them); ``rest``: every
    other kernel a single-threaded fit of na up to 12, or :func:`simulate`, runs (a fit of na
    above 12 and ``threads > 1`` compile theirs when taken). Does nothing without the JIT.
    Compiling ahead changes no result; it lets a caller compile the two parts in two processes
    at once and fork its workers after (:func:`hcid.pipeline.parallel.compile_before_fork`).
    """
    if part not in KERNEL_PARTS:
        raise ValueError(f"part: one of {KERNEL_PARTS}, got {part!r}")
    if not _lanes._WIDE or (part == "vector" and not _kernels.has_fma()):
        return
    x = np.sin(0.3 * np.arange(64.0))
    grid = Grid((1, 1), (1, 1), (1, 1), (1, 1), (1, 1))
    if part == "rest":
        fit = fit_grid(x, np.cos(x), np.roll(x, 1), grid, slice(8, 32), slice(32, 64), fused=False)
        simulate(fit.a[0], fit.b1[0], fit.b2[0], 1, 1, x, x)
        return
    pad = max_lag(grid)
    i1p = padded(x, pad)
    tv = _tap_vectors(i1p)
    block_na, block_nb1, block_nb2, start, size = order_blocks(grid)
    _, v_all, theta_all, score, _ = _outputs(grid, start, size)
    v_all[:] = np.nan
    theta_all[:, 0] = 0.5
    orders = np.stack((block_na, block_nb1, block_nb2), axis=1)
    bounds = np.array([grid.na, grid.nb1, grid.nb2, grid.nk1, grid.nk2], dtype=np.int64)
    blocks = np.arange(start.size)
    ceiling = np.full(start.size, np.inf)
    _simulate_part(True, blocks, orders, start, size, ceiling, bounds, theta_all, score, i1p, i1p, tv, tv,
                   pad, x, 32, 64, True, v_all)  # fmt: skip


def _vector_blocks(block_na: np.ndarray, fuse: bool) -> np.ndarray:
    """Which blocks take the vector steps (fused, na up to ``MAX_NA``, with the JIT); the
    others take the plain path (unfused)."""
    return np.asarray(block_na <= _lanes.MAX_NA) & bool(fuse and _lanes._WIDE)


def _simulate_part(vector, blocks, orders, start, size, ceiling, bounds, theta_all, score, i1p, i2p, tv1,
                   tv2, pad, o, val_start, val_stop, prune, v_all) -> np.ndarray:  # fmt: skip
    """``blocks`` simulated on the vector steps (:func:`hcid.arx._blocks.simulate_blocks`) or
    the plain path (``simulate_blocks_plain``), each block's pruning from its ``ceiling``: their
    counts."""
    done = np.zeros((blocks.size, 3), dtype=np.int64)
    common = (orders[blocks], start[blocks], size[blocks], ceiling[blocks], bounds, theta_all, score, i1p,
              i2p)  # fmt: skip
    if vector:
        _blocks.simulate_blocks(*common, tv1, tv2, pad, o, val_start, val_stop, prune, v_all, done)
    else:
        _blocks.simulate_blocks_plain(*common, pad, o, val_start, val_stop, prune, v_all, done)
    return done


def _checked(i1, i2, o, grid, estimation_rows, validation_rows):
    """The signals as float64 vectors of one length and the windows as ``(start, stop)``, checked."""
    if not isinstance(grid, Grid):
        raise IdentificationError(f"grid: must be a hcid.arx.Grid, got {type(grid).__name__}")
    i1 = checked_signal("i1", i1)
    n = i1.size
    i2 = checked_signal("i2", i2, n)
    o = checked_signal("o", o, n)
    est_start, est_stop = checked_rows("estimation_rows", estimation_rows, n)
    validation = checked_rows("validation_rows", validation_rows, n)
    most = grid.na[1] + grid.nb1[1] + grid.nb2[1]
    if est_stop - est_start < most:
        raise IdentificationError(
            f"estimation_rows: must hold at least {most} rows (the largest candidate's "
            f"coefficients), got {est_stop - est_start}"
        )
    return i1, i2, o, (est_start, est_stop), validation


def _outputs(grid: Grid, start: np.ndarray, size: np.ndarray):
    """The kernels' outputs, preallocated: each (na, nb1, nb2)'s first candidate row, then per
    candidate V, coefficients and prediction-error score, and per triple the simulation counts."""
    shape = tuple(hi - lo + 1 for lo, hi in (grid.na, grid.nb1, grid.nb2))
    offset = np.ascontiguousarray(start.reshape(shape))
    n_cand = int(size.sum())
    most = grid.na[1] + grid.nb1[1] + grid.nb2[1]
    counts = np.zeros((start.size, 3), dtype=np.int64)
    return offset, np.empty(n_cand), np.zeros((n_cand, most)), np.zeros(n_cand), counts


def _fit_grid(
    i1, i2, o, grid, estimation_rows, validation_rows, threads, keep_candidates, *, unpruned, fused,
    best_only=False,
):  # fmt: skip
    """:func:`fit_grid`, also returning the simulation counts; ``unpruned``
    runs the one-candidate-at-a-time kernel (no pruning, unfused
    whatever ``fused``), the twin the tests and the benchmark compare with.

    Returns
    -------
    GridFit
    counts : numpy.ndarray of int64, shape (n_blocks, 3)
        Per order triple: candidates simulated in full, pruned, and
        candidate-samples simulated (all zero for ``unpruned``).
    """
    i1, i2, o, (est_start, est_stop), (val_start, val_stop) = _checked(
        i1, i2, o, grid, estimation_rows, validation_rows
    )
    threads = _threads(threads)
    fused = _fused(fused)
    if best_only and (keep_candidates or unpruned):
        raise IdentificationError("best_only: not with keep_candidates, which keeps every candidate's V")
    pad = max_lag(grid)
    i1p, i2p = padded(i1, pad), padded(i2, pad)
    tv1, tv2 = _tap_vectors(i1p), _tap_vectors(i2p)
    rt = _record_factor(i1p, i2p, o, grid, pad, est_start, est_stop)
    units, blocks, candidate_orders = _layout(grid)
    bounds = np.array([grid.na, grid.nb1, grid.nb2, grid.nk1, grid.nk2], dtype=np.int64)
    block_na, block_nb1, block_nb2, start, size = blocks
    offset, v_all, theta_all, score, counts = _outputs(grid, start, size)

    args = (
        units,
        rt,
        bounds,
        i1p,
        i2p,
        pad,
        o,
        val_start,
        val_stop,
        offset,
        v_all,
        theta_all,
        score,
        unpruned,
    )
    # errstate: unstable simulations overflow by design; only matters when
    # the kernels run as Python (NUMBA_DISABLE_JIT=1).
    searched = np.ones(start.size, dtype=bool)  # the triples searched to their end (all but best_only's)
    with np.errstate(over="ignore", invalid="ignore"):
        if threads == 1:
            _kernels.fit_units(*args)
        else:
            _kernels.run_parallel(_kernels.fit_units_parallel, args, threads)
        if not unpruned:
            # Stable candidates wait with V = NaN; simulate them per order
            # triple, pruning unless every V is wanted.
            orders = np.stack((block_na, block_nb1, block_nb2), axis=1)
            waiting = np.isnan(v_all)
            ceiling = np.full(start.size, np.inf)  # where each block's pruning starts

            def simulate_blocks(blocks, fuse):
                if threads > 1:
                    args = (orders[blocks], start[blocks], size[blocks], ceiling[blocks], bounds, theta_all,
                            score, i1p, i2p, tv1, tv2, pad, o, val_start, val_stop, not keep_candidates,
                            fuse, v_all)  # fmt: skip
                    done = np.zeros((blocks.size, 3), dtype=np.int64)
                    _kernels.run_parallel(_blocks.simulate_blocks_parallel, (*args, done), threads)
                    parts = [(blocks, done)]
                else:  # the vector steps (fused) and the plain path: each a kernel of its own
                    vector = _vector_blocks(block_na[blocks], fuse)
                    parts = [
                        (part, _simulate_part(wide, part, orders, start, size, ceiling, bounds,
                                              theta_all, score, i1p, i2p, tv1, tv2, pad, o, val_start,
                                              val_stop, not keep_candidates, v_all))
                        for part, wide in ((blocks[vector], True), (blocks[~vector], False))
                        if part.size
                    ]  # fmt: skip
                for part, done in parts:
                    counts[part, :2] = done[:, :2]  # each candidate once: its last simulation
                    counts[part, 2] += done[:, 2]  # the work: every simulation

            def search_again(again, fuse=False):
                """The stable candidates of the blocks ``again`` (a mask) simulated anew, each
                block's pruning from its ceiling (unfused by default)."""
                v_all[np.repeat(again, size) & waiting] = np.nan
                with np.errstate(over="ignore", invalid="ignore"):
                    simulate_blocks(np.flatnonzero(again), fuse)

            if best_only:
                searched = _search_for_best(
                    simulate_blocks, search_again, ceiling, v_all, score, waiting, start, size, fused
                )
            else:
                simulate_blocks(np.arange(start.size), fused)
            # Triples searched fused but whose choice fused rounding could have changed
            # are searched again unfused (fit_grid, ``fused``); not those that ran
            # unfused anyway (no JIT, na above the vector recursion's).
            fused_blocks = fused & _lanes._WIDE & (block_na <= _lanes.MAX_NA) & searched
            again = fused_blocks & _near_ties(v_all, start, size)
            # A stable candidate whose fused output overflowed might not overflow unfused.
            again |= fused_blocks & _overflowed(v_all, waiting, start)
            if again.any():
                search_again(again)

    # Frontier: equal V keep the candidate order, in which nk1 and then nk2
    # increase inside a block. Its V and VAF come from the frontier rows' outputs:
    # the values simulate() gives, bit for bit, whatever arithmetic the search used.
    cand_na, cand_nb1, cand_nb2, cand_nk1, cand_nk2 = candidate_orders
    layout = (block_na, block_nb1, block_nb2, cand_nk1, cand_nk2)
    windows = ((est_start, est_stop), (val_start, val_stop))
    first = _blocks.block_best(v_all, start, size)
    v, vaf_est, vaf_val = _frontier.outputs(
        first, searched, v_all, theta_all, layout, i1p, i2p, tv1, tv2, pad, o, windows
    )
    if not unpruned and fused:
        # A row whose unfused V is not finite, or further from the search's than the
        # tie margin assumes (never seen): its triple is searched again unfused.
        search = v_all[first]
        with np.errstate(invalid="ignore"):  # inf - inf where the triple has no stable candidate
            moved = ~(np.abs(v - search) <= 0.25 * _TIE_RTOL * np.abs(v))
        off = fused_blocks & np.isfinite(search) & moved  # fused_blocks: searched ones only
        if off.any() and best_only:
            # best_only's choice of the triples to finish rests on that margin too (V at
            # rounding, as on a noise-free record, can break it): the whole search instead.
            return _fit_grid(i1, i2, o, grid, estimation_rows, validation_rows, threads, keep_candidates,
                             unpruned=unpruned, fused=fused)  # fmt: skip
        if off.any():
            search_again(off)
            first = _blocks.block_best(v_all, start, size)
            v, vaf_est, vaf_val = _frontier.outputs(
                first, searched, v_all, theta_all, layout, i1p, i2p, tv1, tv2, pad, o, windows
            )
    blocks = (block_na, block_nb1, block_nb2, start)
    candidate_orders = (cand_na, cand_nb1, cand_nb2, cand_nk1, cand_nk2)
    fit = _frontier.grid_fit(
        grid, blocks, candidate_orders, first, searched, v_all, theta_all, (v, vaf_est, vaf_val),
        keep_candidates,
    )  # fmt: skip
    return fit, counts


#: best_only: the triples of the best prediction errors, searched first for a V to prune the
#: others against (what it saves, and the most a bound could: benchmarks/arx_engine.py and
#: benchmarks/pruning_ceiling.py, docs/engine.md).
_SEED_BLOCKS = 4
#: best_only: the other triples in this many rounds, each pruned against the best V before it.
_ROUNDS = 8


def _search_for_best(
    simulate_blocks, search_again, ceiling, v_all, score, waiting, start, size, fused
) -> np.ndarray:
    """:func:`fit_grid`'s ``best_only`` search; which triples it searched to their end.

    The seed triples (:data:`_SEED_BLOCKS`) are searched as the frontier's search does; their
    best V is every other triple's ceiling, so that a candidate stops once its partial V exceeds
    it. A triple whose smallest V (a pruned candidate's lower bound counts) comes within the tie
    margin of the grid's smallest, or one with a candidate whose output overflowed, is then
    searched again as the frontier's search does, so that the grid's best, and the unfused search
    of a near tie, are what the frontier would give. Every other triple's true best V is above
    the grid's best by more than the margin, so it cannot be chosen as long as fused and unfused
    V differ by less than the margin; where the frontier's check sees that fail (V at rounding,
    as on a noise-free record), :func:`_fit_grid` runs the whole search instead. Returns the
    triples with rows: the seeds, the contenders and those without a stable candidate.
    """
    stable = np.logical_or.reduceat(waiting, start)  # the triples with a candidate to simulate
    block_key = np.maximum.reduceat(np.where(waiting, score, -np.inf), start)
    seeds = np.zeros(start.size, dtype=bool)
    seeds[np.argsort(-block_key, kind="stable")[:_SEED_BLOCKS]] = True
    seeds &= stable
    simulate_blocks(np.flatnonzero(seeds), fused)
    done = seeds.copy()
    for part in np.array_split(np.flatnonzero(stable & ~seeds), _ROUNDS):
        if part.size:
            ceiling[part] = np.min(v_all[np.repeat(done, size)], initial=np.inf)  # the best so far
            simulate_blocks(part, fused)
            done[part] = True
    ceiling[:] = np.inf
    block_min = np.minimum.reduceat(v_all, start)  # every candidate has its V or a lower bound now
    contenders = _within_margin(block_min, block_min.min()) | _overflowed(v_all, waiting, start)
    again = contenders & stable & ~seeds
    if again.any():
        search_again(again, fused)
    return contenders | seeds | ~stable


#: Triples whose two smallest search V are within this relative distance are simulated
#: again unfused (fit_grid, ``fused``): about 700 times the largest difference fused
#: arithmetic made on a paper record (6.9e-10; both V of a pair can move). There no two
#: full V are closer than 2.6e-6, but a pruned candidate's lower bound can be: 1 of 2,860
#: stage-1 triples, 1 of 448 direct and 2 of 448 stage-2 triples are simulated again (0.3
#: to 0.6% of each grid's candidates).
_TIE_RTOL = 1e-6


def _within_margin(v: np.ndarray, best: float | np.ndarray) -> np.ndarray:
    """Whether ``v`` is within the tie margin (``_TIE_RTOL`` relative) above ``best``."""
    return v <= best * (1.0 + _TIE_RTOL)


def _overflowed(v_all: np.ndarray, waiting: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Per block: whether a stable candidate's output overflowed in the search (its V inf)."""
    return np.logical_or.reduceat(waiting & np.isinf(v_all), start)


def _near_ties(v_all: np.ndarray, start: np.ndarray, size: np.ndarray) -> np.ndarray:
    """Per block: whether its smallest V has another within ``_TIE_RTOL`` relative (a pruned
    candidate's V is a lower bound of its own, so this misses none)."""
    first = _blocks.block_best(v_all, start, size)
    best = v_all[first]
    rest = v_all.copy()
    rest[first] = np.inf
    with np.errstate(invalid="ignore"):
        second = np.minimum.reduceat(rest, start)
        return np.isfinite(best) & _within_margin(second, best)


def _threads(threads) -> int:
    try:
        if isinstance(threads, bool):
            raise TypeError
        threads = operator.index(threads)
    except TypeError as exc:
        raise IdentificationError(f"threads: must be an integer >= 1, got {threads!r}") from exc
    if threads < 1:
        raise IdentificationError(f"threads: must be an integer >= 1, got {threads}")
    return min(threads, _kernels.max_threads())


def best(fit: GridFit) -> int:
    """Frontier row of the overall smallest V.

    Ties go to the smaller ``d``, then the smaller ``(na, nb1, nb2, nk1,
    nk2)`` (SPEC section 4).

    Parameters
    ----------
    fit : GridFit

    Returns
    -------
    int
        Row index into the frontier arrays of ``fit``.

    Raises
    ------
    hcid.errors.IdentificationError
        If every candidate of the grid is unstable.
    """
    order = np.lexsort((fit.nk2, fit.nk1, fit.nb2, fit.nb1, fit.na, fit.d, fit.v))
    row = int(order[0])
    if not np.isfinite(fit.v[row]):
        raise IdentificationError(f"every one of the {fit.n_candidates} candidates of the grid is unstable")
    return row
