"""The order triples of a grid walked by the lane kernels: pruning order, affine groups, threads (private).

For each order triple its stable candidates wait with V = NaN; :func:`simulate_blocks`
simulates them best prediction error first, as affine groups where eight candidates
share a triple's consecutive nk1 (:func:`_simulate_affine_groups`) and in general
lanes otherwise (:func:`_simulate_run`), pruning each against the triple's best V
so far, on the vector steps (fused); :func:`simulate_blocks_plain` does the same four lanes
at a time, unfused, for the triples searched again unfused, ``fused=False``, na above
``MAX_NA`` and without the JIT; :func:`squared_errors_wide` gives the frontier's squared
errors. The two drivers are kernels of their own, each compiled when first taken; the
walkers below them are inlined (docs/engine.md, "Compile time").
"""

import numpy as np
from numba import njit, prange

from hcid.arx import _cache  # noqa: F401 (first: the kernels' cache locator, hcid.arx._cache)
from hcid.arx._lane_ir import (
    _AFFINE_MIN,
    _CHUNK,
    _GROUPS,
    _WIDE,
    _WIDTH,
    LANES,
    MAX_NA,
    SAMPLES,
    TAIL,
    lane_inputs,
    lane_recursion,
)
from hcid.arx._lanes import _aligned_zeros, _check_lanes, simulate_affine, simulate_lanes, simulate_wide


@njit(cache=True)
def _n_d2(bounds, nb2):
    """Delays nk2 per nk1 in a block of ``nb2`` (1 without input 2): the candidate order of
    :func:`hcid.arx.grid.candidates`, nk1 outer and nk2 inner."""
    return bounds[4, 1] - bounds[4, 0] + 1 if nb2 > 0 else 1


@njit(cache=True)
def _delays(within, nb1, nb2, bounds):
    """(nk1, nk2) of candidate ``within`` of its block (0 for a dropped input)."""
    n_d2 = _n_d2(bounds, nb2)
    return (bounds[3, 0] + within // n_d2 if nb1 > 0 else 0), (bounds[4, 0] + within % n_d2 if nb2 > 0 else 0)


@njit(cache=True)
def _put_lane(theta, na, nb1, nb2, lane, width, coef, b1, b2):
    """Lane ``lane`` of ``width`` holds the model ``theta = [a1..a_na, b1_0.., b2_0..]``:
    ``coef[i * width + lane] = a_i`` (a_0 = 1), ``b1[lane]``, ``b2[lane]``."""
    coef[lane] = 1.0
    for i in range(na):
        coef[(i + 1) * width + lane] = theta[i]
    for j in range(nb1):
        b1[lane, j] = theta[na + j]
    for j in range(nb2):
        b2[lane, j] = theta[na + nb1 + j]


@njit(cache=True)
def _waiting_by_score(v_all, score, start, size):
    """The block's candidates waiting with V = NaN, best prediction error first."""
    waiting = np.empty(size, dtype=np.int64)
    keys = np.empty(size)
    m = 0
    for c in range(start, start + size):
        if np.isnan(v_all[c]):
            waiting[m] = c
            keys[m] = -score[c]
            m += 1
    return waiting[np.argsort(keys[:m], kind="mergesort")]


@njit(cache=True, inline="always")
def _simulate_block(
    row, block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score, i1p, i2p, pad, o,
    val_start, val_stop, prune, v_all, counts,
):  # fmt: skip
    """Simulate the stable candidates of one order triple four at a time (:func:`simulate_lanes`).

    The plain path: without the JIT, and above ``MAX_NA``. Candidates
    waiting with ``v_all = NaN`` (stable, see
    :func:`hcid.arx._kernels.fit_units`) run best prediction error first:
    the first four in full, which makes ``bound``, the best V so far, tight
    at once; the others stop as soon as their partial V exceeds it
    (``prune``). ``counts[row]`` receives the numbers simulated in full and
    pruned, and the work done.
    """
    na, nb1, nb2 = block_orders[row, 0], block_orders[row, 1], block_orders[row, 2]
    start = block_start[row]
    n = o.shape[0]
    waiting = _waiting_by_score(v_all, score, start, block_size[row])
    m = waiting.shape[0]
    coef = np.zeros((max(na, 2) + 1) * 4)
    b1 = np.zeros((4, max(nb1, 1)))
    b2 = np.zeros((4, max(nb2, 1)))
    nk1 = np.zeros(4, dtype=np.int64)
    nk2 = np.zeros(4, dtype=np.int64)
    lanes = np.empty(4, dtype=np.int64)
    xs = np.empty((4, _CHUNK))
    yh = np.empty((na + n) * 4)
    v4 = np.empty(4)
    pruned = np.empty(4, dtype=np.bool_)
    bound = block_ceiling[row]
    for first in range(0, m, 4):
        for lane in range(4):
            # A short last batch repeats its first candidate in the idle lanes.
            c = waiting[first + lane if first + lane < m else first]
            lanes[lane] = c
            nk1[lane], nk2[lane] = _delays(c - start, nb1, nb2, bounds)
            _put_lane(theta_all[c], na, nb1, nb2, lane, 4, coef, b1, b2)
        done = simulate_lanes(
            coef, na, b1, nb1, nk1, b2, nb2, nk2, i1p, i2p, pad, o, val_start, val_stop,
            bound, xs, yh, v4, pruned,
        )  # fmt: skip
        used = min(4, m - first)
        counts[row, 2] += done * used
        for lane in range(used):
            v_all[lanes[lane]] = v4[lane]
            counts[row, 1 if pruned[lane] else 0] += 1
            if prune and v4[lane] < bound:
                bound = v4[lane]


@njit(cache=True)
def _affine_groups(first_row, stop_row, block_orders, block_start, bounds, v_all, score):
    """Affine groups of blocks ``first_row .. stop_row - 1``: ``_WIDTH`` candidates of one
    block with consecutive nk1 at one nk2, at least ``_AFFINE_MIN`` of them waiting.

    Returns ``(rows, firsts)``: each group's block and the candidate of its
    lane 0 (lane w is ``first + w * n_d2``), block after block, each block's
    groups by their best prediction error (the best of their waiting lanes).
    """
    nb1 = block_orders[first_row, 1]
    n_d1 = bounds[3, 1] - bounds[3, 0] + 1
    per_d2 = n_d1 // _WIDTH if nb1 > 0 else 0
    total = 0
    for row in range(first_row, stop_row):
        total += per_d2 * _n_d2(bounds, block_orders[row, 2])
    rows = np.empty(total, dtype=np.int64)
    firsts = np.empty(total, dtype=np.int64)
    m = 0
    for row in range(first_row, stop_row):
        n_d2 = _n_d2(bounds, block_orders[row, 2])
        keys = np.empty(per_d2 * n_d2)
        here = np.empty(per_d2 * n_d2, dtype=np.int64)
        found = 0
        for d2 in range(n_d2):
            for g1 in range(per_d2):
                first = block_start[row] + g1 * _WIDTH * n_d2 + d2
                waiting = 0
                key = np.inf
                for w in range(_WIDTH):
                    c = first + w * n_d2
                    if np.isnan(v_all[c]):
                        waiting += 1
                        key = min(key, -score[c])
                if waiting >= _AFFINE_MIN:
                    keys[found] = key
                    here[found] = first
                    found += 1
        for i in np.argsort(keys[:found], kind="mergesort"):
            rows[m] = row
            firsts[m] = here[i]
            m += 1
    return rows[:m], firsts[:m]


@njit(cache=True, inline="always")
def _simulate_affine_groups(
    first_row, stop_row, block_orders, block_start, bounds, theta_all, score, i1p, i2p, pad, o,
    val_start, val_stop, prune, v_all, counts, best,
):  # fmt: skip
    """Simulate the affine groups of one run (:func:`_affine_groups`), ``_GROUPS`` per batch
    (:func:`simulate_affine`); ``best`` (per block of the run) as in :func:`_simulate_run`."""
    rows, firsts = _affine_groups(first_row, stop_row, block_orders, block_start, bounds, v_all, score)
    if rows.shape[0] == 0:
        return
    na, nb1 = block_orders[first_row, 0], block_orders[first_row, 1]
    m2 = 0
    for row in range(first_row, stop_row):
        m2 = max(m2, block_orders[row, 2])
    h = max(na, 2)
    r1 = i1p[::-1].copy()
    coef = _aligned_zeros((h + 1) * LANES)
    b1t = _aligned_zeros(max(nb1, 1) * LANES).reshape((max(nb1, 1), LANES))
    b2t = _aligned_zeros(max(m2, 1) * LANES).reshape((max(m2, 1), LANES))
    c1 = np.zeros(_GROUPS, dtype=np.int64)
    c2 = np.zeros(_GROUPS, dtype=np.int64)
    used = np.zeros(LANES, dtype=np.bool_)
    lane_bound = np.full(LANES, np.inf)
    who = np.zeros(LANES, dtype=np.int64)
    v = np.empty(LANES)
    pruned = np.empty(LANES, dtype=np.bool_)
    xt = _aligned_zeros(_CHUNK * LANES)
    yh = _aligned_zeros((h + _CHUNK) * LANES)
    eacc = _aligned_zeros(4 * LANES)
    for at in range(0, rows.shape[0], _GROUPS):
        coef[:] = 0.0
        b1t[:, :] = 0.0
        b2t[:, :] = 0.0
        used[:] = False
        batch_nb2 = np.int64(0)  # not a literal 0: a callee would be compiled for Literal[int](0) too
        for g in range(_GROUPS):
            # A short last batch repeats its first group's delays in the idle group.
            i = at + g if at + g < rows.shape[0] else at
            row, first = rows[i], firsts[i]
            nb2 = block_orders[row, 2]
            n_d2 = _n_d2(bounds, nb2)
            c1[g], c2[g] = _delays(first - block_start[row], nb1, nb2, bounds)
            for w in range(_WIDTH):
                lane = g * _WIDTH + w
                coef[lane] = 1.0
                c = first + w * n_d2
                if at + g < rows.shape[0] and np.isnan(v_all[c]):
                    batch_nb2 = max(batch_nb2, nb2)
                    _put_lane(theta_all[c], na, nb1, nb2, lane, LANES, coef, b1t.T, b2t.T)
                    used[lane] = True
                    who[lane] = c
                    lane_bound[lane] = best[row - first_row]
        done = simulate_affine(
            coef, na, b1t, nb1, c1, b2t, batch_nb2, c2, used, r1, i1p, i2p, pad, o, val_start,
            val_stop, lane_bound, xt, yh, eacc, v, pruned, True,
        )  # fmt: skip
        for g in range(_GROUPS):
            if at + g >= rows.shape[0]:
                continue
            row = rows[at + g]
            for w in range(_WIDTH):
                lane = g * _WIDTH + w
                if used[lane]:
                    v_all[who[lane]] = v[lane]
                    counts[row, 1 if pruned[lane] else 0] += 1
                    counts[row, 2] += done
                    if prune and v[lane] < best[row - first_row]:
                        best[row - first_row] = v[lane]


@njit(cache=True, inline="always")
def _simulate_run(
    first_row, stop_row, block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score,
    i1p, i2p, tv1, tv2, pad, o, val_start, val_stop, prune, v_all, counts,
):  # fmt: skip
    """Simulate the stable candidates of blocks ``first_row .. stop_row - 1`` (one na and
    nb1), ``LANES`` at a time on the vector steps.

    First the affine groups (:func:`_simulate_affine_groups`), then the
    candidates still waiting, on :func:`simulate_wide`: they form one
    queue, block after block, each block's best prediction error first,
    cut into batches of ``LANES``: a
    block's last candidates share a batch with the next block's first, so
    few lanes idle (stage 1's blocks hold 25 candidates). A lane stops once
    its partial V exceeds the best V of its own block so far (``prune``;
    the block's ceiling until it has one), which cannot change the frontier. A
    batch that spans two blocks pads B with zero coefficients to its longer
    nb2: ``x + 0.0 * i`` is ``x``, the same value bit for bit but for a zero's sign, which
    V's squares do not keep, so every V is what the block alone would give.
    ``counts`` as in :func:`_simulate_block`; the inputs as in
    :func:`simulate_blocks` (``i1p``, ``i2p`` for the affine groups, their
    tap vectors ``tv1``, ``tv2`` for the rest).
    """
    na, nb1 = block_orders[first_row, 0], block_orders[first_row, 1]
    best = block_ceiling[first_row:stop_row].copy()
    _simulate_affine_groups(
        first_row, stop_row, block_orders, block_start, bounds, theta_all, score, i1p, i2p, pad, o,
        val_start, val_stop, prune, v_all, counts, best,
    )  # fmt: skip
    total = 0
    m2 = 0
    for row in range(first_row, stop_row):
        m2 = max(m2, block_orders[row, 2])
        total += block_size[row]
    queue = np.empty(total, dtype=np.int64)
    owner = np.empty(total, dtype=np.int64)
    m = 0
    for row in range(first_row, stop_row):
        waiting = _waiting_by_score(v_all, score, block_start[row], block_size[row])
        for c in waiting:
            queue[m] = c
            owner[m] = row
            m += 1
    h = max(na, 2)
    coef = _aligned_zeros((h + 1) * LANES)
    b1 = np.zeros((LANES, max(nb1, 1)))
    b2 = np.zeros((LANES, max(m2, 1)))
    nk1 = np.zeros(LANES, dtype=np.int64)
    nk2 = np.zeros(LANES, dtype=np.int64)
    lane_bound = np.empty(LANES)
    v = np.empty(LANES)
    pruned = np.empty(LANES, dtype=np.bool_)
    off1 = np.empty(LANES, dtype=np.int64)
    off2 = np.empty(LANES, dtype=np.int64)
    xt = _aligned_zeros(_CHUNK * LANES)
    yh = _aligned_zeros((h + _CHUNK) * LANES)
    eacc = _aligned_zeros(4 * LANES)
    for first in range(0, m, LANES):
        used = min(LANES, m - first)
        batch_nb2 = np.int64(0)  # not a literal 0: a callee would be compiled for Literal[int](0) too
        for lane in range(used):
            batch_nb2 = max(batch_nb2, block_orders[owner[first + lane], 2])
        coef[:] = 0.0
        b1[:, :] = 0.0
        b2[:, :] = 0.0  # a lane's next candidate may have a shorter B2
        nk1[:] = 0
        nk2[:] = 0
        for lane in range(LANES):
            coef[lane] = 1.0  # an idle lane: a = [1, 0, ...], no input; ignored
        for lane in range(used):
            c = queue[first + lane]
            row = owner[first + lane]
            nb2 = block_orders[row, 2]
            nk1[lane], nk2[lane] = _delays(c - block_start[row], nb1, nb2, bounds)
            _put_lane(theta_all[c], na, nb1, nb2, lane, LANES, coef, b1, b2)
            lane_bound[lane] = best[row - first_row]
        done = simulate_wide(
            coef, na, b1, nb1, nk1, b2, batch_nb2, nk2, used, tv1, tv2, pad, o, val_start, val_stop,
            lane_bound, off1, off2, xt, yh, eacc, v, pruned, True,
        )  # fmt: skip
        for lane in range(used):
            c = queue[first + lane]
            row = owner[first + lane]
            v_all[c] = v[lane]
            counts[row, 1 if pruned[lane] else 0] += 1
            counts[row, 2] += done
            if prune and v[lane] < best[row - first_row]:
                best[row - first_row] = v[lane]


@njit(cache=True)
def _runs(block_orders):
    """First block of each run of blocks taken at once (:func:`simulate_blocks`,
    :func:`simulate_blocks_parallel`), then the number of blocks: consecutive blocks of one
    (na, nb1) up to ``MAX_NA`` with the JIT, any other block alone."""
    n_blocks = block_orders.shape[0]
    firsts = np.empty(n_blocks + 1, dtype=np.int64)
    g = 0
    for row in range(n_blocks):
        na, nb1 = block_orders[row, 0], block_orders[row, 1]
        same = row > 0 and na == block_orders[row - 1, 0] and nb1 == block_orders[row - 1, 1]
        if not (same and _WIDE and na <= MAX_NA):
            firsts[g] = row
            g += 1
    firsts[g] = n_blocks
    return firsts[: g + 1]


@njit(cache=True)  # not inlined: a prange body with one call and one exit runs in parallel
def _simulate_group(
    g, firsts, block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score, i1p, i2p,
    tv1, tv2, pad, o, val_start, val_stop, prune, fused, v_all, counts,
):  # fmt: skip
    first_row, stop_row = firsts[g], firsts[g + 1]
    if _WIDE and fused and block_orders[first_row, 0] <= MAX_NA:
        _simulate_run(
            first_row, stop_row, block_orders, block_start, block_size, block_ceiling, bounds, theta_all,
            score, i1p, i2p, tv1, tv2, pad, o, val_start, val_stop, prune, v_all, counts,
        )  # fmt: skip
    else:  # each block alone (a run of the vector steps' blocks when not fused)
        for row in range(first_row, stop_row):
            _simulate_block(
                row, block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score, i1p, i2p,
                pad, o, val_start, val_stop, prune, v_all, counts,
            )  # fmt: skip


@njit(cache=True)
def simulate_blocks(
    block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score, i1p, i2p, tv1, tv2,
    pad, o, val_start, val_stop, prune, v_all, counts,
):  # fmt: skip
    """Serial driver of the vector steps: the runs of blocks of one (na, nb1), each by
    :func:`_simulate_run`, every multiply-add fused. Every block's na is at most ``MAX_NA``
    (the caller's choice, ``hcid.arx.engine._vector_blocks``); the plain path is
    :func:`simulate_blocks_plain`, a kernel of its own so that each is compiled only when
    taken (docs/engine.md, "Compile time").

    Parameters
    ----------
    block_orders : int64 array, shape (n_blocks, 3)
        ``(na, nb1, nb2)`` of each candidate block.
    block_start, block_size : int64 arrays, shape (n_blocks,)
        Where each block starts in the candidate order, and its length.
    block_ceiling : float64 array, shape (n_blocks,)
        The bound each block's pruning starts from (``inf``: none, the
        frontier's search): a lane stops once its partial V exceeds the
        smaller of it and the block's best V so far. A V known to be reached
        elsewhere (:func:`hcid.arx.engine.fit_grid`, ``best_only``) prunes
        candidates that cannot be the grid's best.
    i1p, i2p : float64 arrays
        The inputs after ``pad`` zeros and with ``TAIL`` zeros after the
        record (the affine and plain steps read them).
    tv1, tv2 : float64 arrays
        ``tap_vectors(i1p)`` and ``tap_vectors(i2p)`` for the general vector
        step (empty without the JIT, which never takes it).
    theta_all, score, v_all :
        As written by :func:`fit_units` with ``simulate`` False; v_all's
        NaN entries are replaced by V (or a pruned lower bound above the
        block's best V).
    prune : bool
        False: every stable candidate is simulated in full.
    counts : int64 array, shape (n_blocks, 3), zeros
        Out per block: candidates simulated in full, candidates pruned, and
        candidate-samples simulated (lanes times samples).
    """
    firsts = _runs(block_orders)
    for g in range(firsts.shape[0] - 1):
        _simulate_run(
            firsts[g], firsts[g + 1], block_orders, block_start, block_size, block_ceiling, bounds,
            theta_all, score, i1p, i2p, tv1, tv2, pad, o, val_start, val_stop, prune, v_all, counts,
        )  # fmt: skip


@njit(cache=True)
def simulate_blocks_plain(
    block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score, i1p, i2p, pad, o,
    val_start, val_stop, prune, v_all, counts,
):  # fmt: skip
    """Serial driver of the plain path: each block alone by :func:`_simulate_block` (four
    lanes, unfused; each V bit-identical to the vector steps' unfused). The path without the
    JIT, above ``MAX_NA``, for ``fit_grid(fused=False)`` and for the triples searched again
    unfused. Arguments as in :func:`simulate_blocks`."""
    for row in range(block_orders.shape[0]):
        _simulate_block(
            row, block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score, i1p, i2p,
            pad, o, val_start, val_stop, prune, v_all, counts,
        )  # fmt: skip


@njit(cache=True, parallel=True)
def simulate_blocks_parallel(
    block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score, i1p, i2p, tv1, tv2,
    pad, o, val_start, val_stop, prune, fused, v_all, counts, n_threads,
):  # fmt: skip
    """Parallel driver: thread t takes runs t, t + n_threads, ... (:func:`_runs`): the vector
    steps (:func:`simulate_blocks`) if ``fused`` and na is at most ``MAX_NA``, else the plain
    path (:func:`simulate_blocks_plain`); each run alone decides its pruning, so the result is
    bit-identical to theirs."""
    firsts = _runs(block_orders)
    n_groups = firsts.shape[0] - 1
    for t in prange(n_threads):
        for g in range(t, n_groups, n_threads):
            _simulate_group(
                g, firsts, block_orders, block_start, block_size, block_ceiling, bounds, theta_all, score,
                i1p, i2p, tv1, tv2, pad, o, val_start, val_stop, prune, fused, v_all, counts,
            )  # fmt: skip


@njit(cache=True)
def squared_errors_wide(
    theta, na, nb1, nb2, nk1, nk2, tv1, tv2, pad, o, est_start, val_start, err_est, err_val, done
):
    """:func:`hcid.arx._kernels.squared_errors` on the vector steps, ``LANES`` models at a time.

    Consecutive rows of the same na share a batch, their B padded with zero
    coefficients to the batch's longest (``x + 0.0 * i`` is ``x``: the same
    values, bit for bit but for a zero's sign, which no square keeps), so
    every element equals the plain kernel's. The inputs come as tap
    vectors (``tv1 = tap_vectors(i1p)``, ``tv2``). ``done[r]`` is False for a
    model whose output is not finite at the end of the record; its rows
    are left for the plain kernel (whose NaN-from-the-block rule they need).
    """
    n = o.shape[0]
    rows = theta.shape[0]
    off1 = np.empty(LANES, dtype=np.int64)
    off2 = np.empty(LANES, dtype=np.int64)
    xt = _aligned_zeros(_CHUNK * LANES)
    eacc = _aligned_zeros(4 * LANES)
    first = 0
    while first < rows:
        k = na[first]
        last = first
        while last + 1 < rows and last + 1 - first < LANES and na[last + 1] == k:
            last += 1
        used = last - first + 1
        if k > MAX_NA:  # no vector recursion: done stays False, the plain kernel takes them
            first = last + 1
            continue
        m1 = 0
        m2 = 0
        for r in range(first, last + 1):
            m1 = max(m1, nb1[r])
            m2 = max(m2, nb2[r])
        h = max(k, 2)
        coef = _aligned_zeros((h + 1) * LANES)
        b1 = np.zeros((LANES, max(m1, 1)))
        b2 = np.zeros((LANES, max(m2, 1)))
        _check_lanes(tv1, tv2, pad, n, _WIDTH, b1, m1, b2, m2)
        lane_nk1 = np.zeros(LANES, dtype=np.int64)
        lane_nk2 = np.zeros(LANES, dtype=np.int64)
        for lane in range(LANES):
            coef[lane] = 1.0
        for lane in range(used):
            r = first + lane
            _put_lane(theta[r], k, nb1[r], nb2[r], lane, LANES, coef, b1, b2)
            lane_nk1[lane] = nk1[r]
            lane_nk2[lane] = nk2[r]
        yh = _aligned_zeros((h + _CHUNK) * LANES)
        for k0 in range(0, n, _CHUNK):
            k1 = min(k0 + _CHUNK, n)
            m = k1 - k0
            for lane in range(LANES):
                off1[lane] = pad - lane_nk1[lane] + k0
                off2[lane] = pad - lane_nk2[lane] + k0
            steps = (m + TAIL) // SAMPLES * SAMPLES
            lane_inputs(b1, m1, off1, tv1, b2, m2, off2, tv2, steps, xt, False)
            # No validation rows (start = stop = n): no squared-error sums.
            if not lane_recursion(coef, k, xt, m, yh, h, o, k0, n, n, n, eacc, False):
                raise ValueError("squared_errors_wide: na above MAX_NA")
            for lane in range(used):
                _errors_into(err_est[first + lane], est_start, yh, h, lane, o, k0, k1)
                _errors_into(err_val[first + lane], val_start, yh, h, lane, o, k0, k1)
            if k1 == n:
                for lane in range(used):
                    done[first + lane] = abs(yh[(h + m - 1) * LANES + lane]) < np.inf
            for i in range(h * LANES):
                yh[i] = yh[m * LANES + i]
        first = last + 1


@njit(cache=True)
def _errors_into(err, start, yh, h, lane, o, k0, k1):
    """``err[k - start] = (o[k] - y)^2`` for the chunk's samples k0 <= k < k1 in err's window."""
    for k in range(max(k0, start), min(k1, start + err.shape[0])):
        d = o[k] - yh[(h + k - k0) * LANES + lane]
        err[k - start] = d * d


@njit(cache=True)
def block_best(v_all, start, size):
    """Each block's smallest V: the first of equal ones in candidate order, NaN last.

    The order ``np.lexsort((v_all, block))`` gives (stable, NaN sorted
    last), in one pass instead of a sort of every candidate.
    """
    first = np.empty(start.shape[0], dtype=np.int64)
    for b in range(start.shape[0]):
        best = start[b]
        for c in range(start[b] + 1, start[b] + size[b]):
            if v_all[c] < v_all[best] or (np.isnan(v_all[best]) and not np.isnan(v_all[c])):
                best = c
        first[b] = best
    return first
