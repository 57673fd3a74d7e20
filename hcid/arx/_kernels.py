"""Numba kernels of the ARX grid engine (private; see :mod:`hcid.arx.engine`).

Storage convention: a triangular factor is kept *transposed*, one row per
column of R, so that a column is contiguous: ``f[j, i] = R[i, j]``. The
right-hand side ``c = Q^T o`` is stored as one more row, ``f[n_cols, :]``.

Column layout of the record factor (built by the wrapper): first the i1 lags
``nk1_lo .. nk1_hi + nb1_hi - 1``, then the i2 lags ``nk2_lo .. nk2_hi +
nb2_hi - 1`` (an input with ``nb_hi = 0`` has none), then the output lags
``1 .. na_hi`` (columns ``-o(k - i)``, so their coefficients are ``a_i``).

A work unit is one delay pair ``(k1, k2)``; ``-1`` marks a dropped input.
Unit ``(k1, k2)`` owns every candidate with those delays and
``nb1 > 0`` (``k1 >= 0``) or ``nb1 = 0`` (``k1 = -1``), likewise for input
2, so every candidate belongs to exactly one unit and units write disjoint
rows of the outputs.

``bounds`` is an int64 array of shape (5, 2): the inclusive ranges of na,
nb1, nb2, nk1, nk2 in that order.

:func:`_fit_unit` is one kernel of about 125 lines: the QR steps of one delay
pair, the back substitutions of every na and the stability tests share the
pair's factor in registers and cache; split into calls, numba would pass the
factor's slices through memory on every step.
"""

import numba
import numpy as np
from numba import njit, prange

from hcid.arx import _cache  # noqa: F401 (first: the kernels' cache locator, hcid.arx._cache)
from hcid.arx._lane_ir import _prefetch_rows

# Samples simulated between two finiteness checks.
_BLOCK = 256


@njit(cache=True)
def select_qr(src, n_src, cols, n_cols, dst):
    """Triangular factor of a column subset of a triangular factor.

    ``src`` (transposed, rhs at row ``n_src``) holds R_src and c_src;
    ``cols`` (increasing, length >= n_cols) picks columns. On return
    ``dst[:n_cols]`` holds the transposed triangular factor of
    ``R_src[:, cols]`` and ``dst[n_cols, :n_cols]`` the transformed rhs, so
    that ``min ||R_src[:, cols] th - c_src||`` has the same minimiser as
    ``min ||R_dst th - c_dst||``. Column j of the subset is zero below row
    ``cols[j]``, so its Householder reflector spans rows ``j .. cols[j]``
    only: removing columns from a QR factor costs little.
    """
    top = cols[n_cols - 1] + 1
    for j in range(n_cols):
        cj = cols[j]
        for i in range(cj + 1):
            dst[j, i] = src[cj, i]
    for i in range(top):
        dst[n_cols, i] = src[n_src, i]
    for j in range(n_cols):
        _reflect(dst, j, cols[j], j + 1, n_cols + 1)


@njit(cache=True)
def _reflect(f, j, last, k_lo, k_hi):
    """Householder step of column j (row ``j`` of the transposed ``f``, rows ``j .. last``)
    applied to the later columns ``k_lo .. k_hi - 1`` (rows of ``f``).

    The step of :func:`select_qr` at column j. Each later column is
    reflected on its own, its dot product summed in row order, so which
    later columns share a call changes none of their values.
    """
    s = 0.0
    for i in range(j + 1, last + 1):
        s += f[j, i] * f[j, i]
    if s == 0.0:
        return
    alpha = f[j, j]
    beta = -np.copysign(np.sqrt(alpha * alpha + s), alpha)
    tau = (beta - alpha) / beta
    scale = 1.0 / (alpha - beta)
    for i in range(j + 1, last + 1):
        f[j, i] *= scale
    f[j, j] = beta
    # Reflect the later columns (and the rhs) four at a time: each one's
    # dot product is still summed in row order, but four independent
    # sums keep the adder busy (one alone waits on each add: 1.3x on
    # stage 1's fits).
    k = k_lo
    while k + 4 <= k_hi:
        w0 = f[k, j]
        w1 = f[k + 1, j]
        w2 = f[k + 2, j]
        w3 = f[k + 3, j]
        for i in range(j + 1, last + 1):
            h = f[j, i]
            w0 += h * f[k, i]
            w1 += h * f[k + 1, i]
            w2 += h * f[k + 2, i]
            w3 += h * f[k + 3, i]
        w0 *= tau
        w1 *= tau
        w2 *= tau
        w3 *= tau
        f[k, j] -= w0
        f[k + 1, j] -= w1
        f[k + 2, j] -= w2
        f[k + 3, j] -= w3
        for i in range(j + 1, last + 1):
            h = f[j, i]
            f[k, i] -= w0 * h
            f[k + 1, i] -= w1 * h
            f[k + 2, i] -= w2 * h
            f[k + 3, i] -= w3 * h
        k += 4
    for rest in range(k, k_hi):
        w = f[rest, j]
        for i in range(j + 1, last + 1):
            w += f[j, i] * f[rest, i]
        w *= tau
        f[rest, j] -= w
        for i in range(j + 1, last + 1):
            f[rest, i] -= w * f[j, i]


@njit(cache=True)
def branch_start(unit, m1, m2, na_hi, g1, branch, group):
    """Start the groups ``(g1, g2)`` of a unit factor (every g2 in turn).

    A group's factor is :func:`select_qr` of the unit's columns ``[i1 lags
    1..g1, i2 lags 1..g2, o lags 1..na_hi]`` (unit column order: m1 i1
    lags, m2 i2 lags, na_hi o lags). The groups of one g1 share the steps
    of their first g1 + g2 columns, so instead of one select_qr each:
    ``branch_start``, then :func:`branch_step` for i2 lags 0, 1, .. and
    :func:`branch_finish` for each g2 once its g2 i2 lags are stepped.
    The steps and their order per column are select_qr's, so ``group``
    holds the same bits (the tests compare them).

    Writes the i1 rows of ``group`` and the later columns, not yet
    reflected, into ``branch`` (rows ``g1 + jj``: i2 lag jj; ``g1 + m2 +
    i``: o lag i; ``g1 + m2 + na_hi``: the rhs; the same shape as
    ``group``). The i1 lags are a triangular prefix: their steps do
    nothing.
    """
    m_u = m1 + m2 + na_hi
    for j in range(g1):
        for i in range(j + 1):
            group[j, i] = unit[j, i]
    for c in range(m2 + na_hi):
        for i in range(m1 + c + 1):
            branch[g1 + c, i] = unit[m1 + c, i]
    for i in range(m_u):
        branch[g1 + m2 + na_hi, i] = unit[m_u, i]


@njit(cache=True)
def branch_step(branch, group, m1, m2, na_hi, g1, jj):
    """Step i2 lag ``jj`` (column ``g1 + jj`` of every group with g2 > jj) and copy its
    final row into ``group``; i2 lags ``0 .. jj - 1`` must be stepped already (by this
    function, after :func:`branch_start`)."""
    j = g1 + jj
    _reflect(branch, j, m1 + jj, j + 1, g1 + m2 + na_hi + 1)
    for i in range(m1 + jj + 1):
        group[j, i] = branch[j, i]


@njit(cache=True)
def branch_finish(branch, group, m1, m2, na_hi, g1, g2):
    """The factor of group (g1, g2) in ``group`` (as :func:`select_qr` writes it), once i2
    lags ``0 .. g2 - 1`` are stepped (:func:`branch_step`); ``branch`` is left as it was."""
    m_g = g1 + g2 + na_hi
    for c in range(na_hi):
        for i in range(m1 + m2 + c + 1):
            group[g1 + g2 + c, i] = branch[g1 + m2 + c, i]
    for i in range(m1 + m2 + na_hi):
        group[m_g, i] = branch[g1 + m2 + na_hi, i]
    for c in range(na_hi):
        j = g1 + g2 + c
        _reflect(group, j, m1 + m2 + c, j + 1, m_g + 1)


@njit(cache=True)
def back_steps(f, stop, lo, theta, tmp):
    """Unknowns ``stop - 1`` down to ``lo`` of a back substitution in ``f`` (transposed factor).

    ``tmp[:stop]`` holds the rhs less the terms of the unknowns solved so
    far (the rhs itself to start); writes ``theta[lo:stop]`` and updates
    ``tmp[:lo]``. ``back_steps(f, k, 0, ...)`` solves the leading k x k
    block; ``back_steps(f, k, m, ...)`` then ``back_steps(f, m, 0, ...)``
    does the same operations in the same order. Returns False (theta
    undefined) if a diagonal entry is exactly zero.
    """
    for j in range(stop - 1, lo - 1, -1):
        diag = f[j, j]
        if diag == 0.0:
            return False
        t = tmp[j] / diag
        theta[j] = t
        for i in range(j):
            tmp[i] -= t * f[j, i]
    return True


@njit(cache=True)
def is_stable(a, na, work):
    """Schur-Cohn step-down test of A = a[0] + ... + a[na] z^-na, a[0] = 1.

    True iff every root of A lies strictly inside the unit circle, i.e.
    every reflection coefficient has magnitude < 1. NaN coefficients give
    False.
    """
    for i in range(na + 1):
        work[i] = a[i]
    for m in range(na, 0, -1):
        k = work[m]
        if not abs(k) < 1.0:
            return False
        den = 1.0 - k * k
        for j in range(1, m // 2 + 1):
            lo = work[j]
            hi = work[m - j]
            work[j] = (lo - k * hi) / den
            work[m - j] = (hi - k * lo) / den
    return True


@njit(cache=True)
def simulate_into(a, na, b1, nb1, nk1, b2, nb2, nk2, i1p, i2p, pad, x, yp, ypad):
    """Simulate ``A o_hat = B1 i1(k - nk1) + B2 i2(k - nk2)`` from rest.

    ``i1p``/``i2p`` are the inputs with ``pad`` leading zeros (``pad`` at
    least the largest input lag), ``x`` (length n) is scratch for the input
    part, ``yp`` receives ``o_hat`` at ``yp[ypad:ypad + n]`` and must hold
    zeros in ``yp[:ypad]`` (``ypad >= na``). Checks finiteness every
    ``_BLOCK`` samples and returns the number of samples simulated; the
    simulation is finite iff that is n and ``yp[ypad + n - 1]`` is finite
    (a non-finite output value stays non-finite in the recursion).
    """
    n = x.shape[0]
    for k in range(n):
        x[k] = 0.0
    # Slices indexed by range() variables: numba then knows the indices are
    # non-negative and drops its negative-index wraparound, which would keep
    # LLVM from vectorising (3x slower).
    for j in range(nb1):
        c = b1[j]
        base = pad - nk1 - j
        src = i1p[base : base + n]
        for k in range(n):
            x[k] += c * src[k]
    for j in range(nb2):
        c = b2[j]
        base = pad - nk2 - j
        src = i2p[base : base + n]
        for k in range(n):
            x[k] += c * src[k]
    # Lags 1 and 2 are kept in registers (y1, y2): read back from memory
    # they would add a store-to-load delay to the loop-carried path.
    a1 = a[1]
    a2 = a[2] if na >= 2 else 0.0
    y1 = 0.0
    y2 = 0.0
    for start in range(0, n, _BLOCK):
        stop = min(start + _BLOCK, n)
        for k in range(start, stop):
            # Older lags first, in two interleaved partial sums (two short
            # add chains instead of one long one), so the y(k-1) term, the
            # only one on the shortest loop-carried path, comes last.
            # Unsigned indices: no wraparound code either (1.5x at na = 7).
            base = np.uint64(ypad + k)
            s0 = 0.0
            s1 = 0.0
            i = na
            while i > 3:
                s0 += a[i] * yp[base - np.uint64(i)]
                s1 += a[i - 1] * yp[base - np.uint64(i - 1)]
                i -= 2
            if i == 3:
                s0 += a[3] * yp[base - np.uint64(3)]
            y = ((x[k] - (s0 + s1)) - a2 * y2) - a1 * y1
            yp[base] = y
            y2 = y1
            y1 = y
        if not abs(y1) < np.inf:
            return stop
    return n


@njit(cache=True)
def squared_errors(theta, na, nb1, nb2, nk1, nk2, i1p, i2p, pad, o, est_start, val_start, err_est, err_val):
    """Squared simulation errors of many models on two windows, for their VAF.

    Row r is the model ``theta[r] = [a1..a_na, b1_0.., b2_0..]`` (orders
    ``na[r]``, ``nb1[r]``, ``nb2[r]``; delays ``nk1[r]``, ``nk2[r]``),
    simulated by :func:`simulate_into` as :func:`hcid.arx.engine.simulate`
    does (NaN from the end of the first block that is not finite on);
    ``err_est[r, i] = (o[k] - o_hat[k])^2`` for ``k = est_start + i``, and
    ``err_val`` likewise from ``val_start``: the elements numpy's
    ``(o - o_hat) ** 2`` would give, bit for bit.
    """
    n = o.shape[0]
    x = np.empty(n)
    y = np.empty(n)
    most = 2
    for r in range(theta.shape[0]):
        most = max(most, na[r])
    yp = np.empty(most + n)
    a = np.empty(most + 1)
    for r in range(theta.shape[0]):
        k = na[r]
        a[0] = 1.0
        a[2] = 0.0
        for i in range(k):
            a[i + 1] = theta[r, i]
        b1 = theta[r, k : k + max(nb1[r], 1)]
        b2 = theta[r, k + nb1[r] : k + nb1[r] + max(nb2[r], 1)]
        for i in range(k):
            yp[i] = 0.0
        done = simulate_into(a, k, b1, nb1[r], nk1[r], b2, nb2[r], nk2[r], i1p, i2p, pad, x, yp, k)
        for i in range(n):
            y[i] = yp[k + i] if i < done else np.nan
        for i in range(err_est.shape[1]):
            d = o[est_start + i] - y[est_start + i]
            err_est[r, i] = d * d
        for i in range(err_val.shape[1]):
            d = o[val_start + i] - y[val_start + i]
            err_val[r, i] = d * d


@njit(cache=True)
def mse_of_squares(err, v):
    """``v[r]``: the mean of row ``r`` of squared errors, summed as :func:`_validation_mse`
    sums them (four partial sums over whole quadruples, the rest into the first).

    Given the squared errors of an output on the validation rows (as
    :func:`squared_errors` computes them: ``(o - y)^2`` is ``(y - o)^2``
    exactly), the V that :func:`_validation_mse` gives for that output, bit
    for bit.
    """
    n = err.shape[1]
    for r in range(err.shape[0]):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        k = 0
        while k + 4 <= n:
            s0 += err[r, k]
            s1 += err[r, k + 1]
            s2 += err[r, k + 2]
            s3 += err[r, k + 3]
            k += 4
        while k < n:
            s0 += err[r, k]
            k += 1
        v[r] = ((s0 + s1) + (s2 + s3)) / n


@njit(cache=True)
def _validation_mse(yp, ypad, o, start, stop):
    # Four partial sums: a fixed order of additions, so the same result on
    # every call, and shorter add latency chains.
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    k = start
    while k + 4 <= stop:
        e0 = yp[ypad + k] - o[k]
        e1 = yp[ypad + k + 1] - o[k + 1]
        e2 = yp[ypad + k + 2] - o[k + 2]
        e3 = yp[ypad + k + 3] - o[k + 3]
        s0 += e0 * e0
        s1 += e1 * e1
        s2 += e2 * e2
        s3 += e3 * e3
        k += 4
    while k < stop:
        e0 = yp[ypad + k] - o[k]
        s0 += e0 * e0
        k += 1
    return ((s0 + s1) + (s2 + s3)) / (stop - start)


@njit(cache=True)
def _fit_unit(
    k1, k2, rt, bounds, i1p, i2p, pad, o, val_start, val_stop, offset, v_out, theta_out, score_out, simulate
):
    """Fit and test every candidate of work unit (k1, k2); simulate it if ``simulate``.

    With ``simulate`` False a stable candidate gets ``v_out = NaN`` (to be
    simulated by :func:`hcid.arx._blocks.simulate_blocks` or ``simulate_blocks_plain``) and
    ``score_out`` its explained sum of squares on the estimation rows, ``||c[:k]||^2``
    (larger = smaller prediction error); unstable and singular ones get ``inf``.
    """
    na_lo, na_hi = bounds[0, 0], bounds[0, 1]
    nb1_lo, nb1_hi = bounds[1, 0], bounds[1, 1]
    nb2_lo, nb2_hi = bounds[2, 0], bounds[2, 1]
    nk1_lo, nk1_hi = bounds[3, 0], bounds[3, 1]
    nk2_lo, nk2_hi = bounds[4, 0], bounds[4, 1]
    n1 = nk1_hi - nk1_lo + nb1_hi if nb1_hi > 0 else 0
    n2 = nk2_hi - nk2_lo + nb2_hi if nb2_hi > 0 else 0
    p = n1 + n2 + na_hi
    n = o.shape[0]

    m1 = nb1_hi if k1 >= 0 else 0
    m2 = nb2_hi if k2 >= 0 else 0
    m_u = m1 + m2 + na_hi
    cols = np.empty(m_u, dtype=np.int64)
    for j in range(m1):
        cols[j] = k1 - nk1_lo + j
    for j in range(m2):
        cols[m1 + j] = n1 + k2 - nk2_lo + j
    for i in range(na_hi):
        cols[m1 + m2 + i] = n1 + n2 + i

    if k1 >= 0 and k2 >= 0:
        within = (k1 - nk1_lo) * (nk2_hi - nk2_lo + 1) + (k2 - nk2_lo)
    elif k1 >= 0:
        within = k1 - nk1_lo
    elif k2 >= 0:
        within = k2 - nk2_lo
    else:
        within = 0
    g1_lo, g1_hi = (max(nb1_lo, 1), nb1_hi) if k1 >= 0 else (0, 0)
    g2_lo, g2_hi = (max(nb2_lo, 1), nb2_hi) if k2 >= 0 else (0, 0)
    nk1 = k1 if k1 >= 0 else 0
    nk2 = k2 if k2 >= 0 else 0

    _prefetch_rows(offset, g1_lo - nb1_lo, g2_lo - nb2_lo, within, v_out, theta_out, score_out)
    unit = np.empty((m_u + 1, p))
    select_qr(rt, p, cols, m_u, unit)

    group = np.empty((m_u + 1, m_u))
    branch = np.empty((m_u + 1, m_u))
    theta = np.empty(m_u)
    tmp = np.empty(m_u)
    a = np.empty(na_hi + 1)
    a[0] = 1.0
    jury = np.empty(na_hi + 1)
    b1 = np.empty(max(nb1_hi, 1))
    b2 = np.empty(max(nb2_hi, 1))
    x = np.empty(n)
    yp = np.zeros(na_hi + n)

    for g1 in range(g1_lo, g1_hi + 1):
        branch_start(unit, m1, m2, na_hi, g1, branch, group)
        stepped = np.int64(0)  # not a literal 0: a callee would be compiled for Literal[int](0) too
        for g2 in range(g2_lo, g2_hi + 1):
            # Subset [i1 lags 1..g1, i2 lags 1..g2, o lags 1..na_hi]: every
            # na of the range is a prefix of this one factorisation.
            m_g = g1 + g2 + na_hi
            # The next group's rows, while this one is fitted.
            if g2 < g2_hi:
                _prefetch_rows(offset, g1 - nb1_lo, g2 + 1 - nb2_lo, within, v_out, theta_out, score_out)
            elif g1 < g1_hi:
                _prefetch_rows(offset, g1 + 1 - nb1_lo, g2_lo - nb2_lo, within, v_out, theta_out, score_out)
            while stepped < g2:
                branch_step(branch, group, m1, m2, na_hi, g1, stepped)
                stepped += 1
            branch_finish(branch, group, m1, m2, na_hi, g1, g2)
            explained = 0.0
            for i in range(g1 + g2 + na_lo - 1):
                explained += group[m_g, i] * group[m_g, i]
            for na in range(na_lo, na_hi + 1):
                k = g1 + g2 + na
                idx = offset[na - na_lo, g1 - nb1_lo, g2 - nb2_lo] + within
                explained += group[m_g, k - 1] * group[m_g, k - 1]
                score_out[idx] = explained
                # The output lags come last, so back substitution solves A
                # first; B is solved for a stable A only (most of stage 1's
                # candidates are unstable).
                g = g1 + g2
                for i in range(k):
                    tmp[i] = group[m_g, i]
                finite = back_steps(group, k, g, theta, tmp)
                for i in range(na):
                    a[i + 1] = theta[g + i]
                    finite = finite and abs(a[i + 1]) < np.inf
                if finite and not is_stable(a, na, jury):
                    v_out[idx] = np.inf
                    continue
                finite = finite and back_steps(group, g, 0, theta, tmp)
                for j in range(g):
                    finite = finite and abs(theta[j]) < np.inf
                if not finite:
                    for j in range(k):
                        theta_out[idx, j] = np.nan
                    v_out[idx] = np.inf
                    continue
                for j in range(g1):
                    b1[j] = theta[j]
                for j in range(g2):
                    b2[j] = theta[g1 + j]
                for i in range(na):
                    theta_out[idx, i] = a[i + 1]
                for j in range(g1):
                    theta_out[idx, na + j] = b1[j]
                for j in range(g2):
                    theta_out[idx, na + g1 + j] = b2[j]
                v = np.inf
                if not simulate:
                    v = np.nan
                else:
                    done = simulate_into(a, na, b1, g1, nk1, b2, g2, nk2, i1p, i2p, pad, x, yp, na_hi)
                    if done == n and abs(yp[na_hi + n - 1]) < np.inf:
                        v = _validation_mse(yp, na_hi, o, val_start, val_stop)
                        if not v < np.inf:
                            v = np.inf
                v_out[idx] = v


@njit(cache=True)
def fit_units(
    units, rt, bounds, i1p, i2p, pad, o, val_start, val_stop, offset, v_out, theta_out, score_out, simulate
):
    """Serial driver: every work unit, in order, on the calling thread.

    Parameters
    ----------
    units : int64 array, shape (n_units, 2)
        Work units ``(k1, k2)``, -1 for a dropped input.
    rt : float64 array, shape (p + 1, p)
        Transposed R and rhs c of the record's lagged matrix (module doc).
    bounds : int64 array, shape (5, 2)
        Grid ranges of na, nb1, nb2, nk1, nk2.
    i1p, i2p : float64 arrays, shape (pad + n,)
        Inputs after ``pad`` zeros (pad = the grid's largest lag).
    pad : int
    o : float64 array, shape (n,)
        Output.
    val_start, val_stop : int
        Validation rows of V.
    offset : int64 array, shape (n_na, n_nb1, n_nb2)
        Index of each order triple's first candidate in the candidate order
        of :func:`hcid.arx.grid.candidates`; a unit adds its delay position.
    v_out : float64 array, shape (n_candidates,)
        Out: V per candidate, inf if unstable.
    theta_out : float64 array, shape (n_candidates, na_hi + nb1_hi + nb2_hi)
        Out: ``[a1..a_na, b1_0.., b2_0..]`` per candidate, zero-padded
        (NaN if the regression was singular); the rows of unstable
        candidates are not written (their B is never solved).
    """
    for u in range(units.shape[0]):
        _fit_unit(
            units[u, 0], units[u, 1], rt, bounds, i1p, i2p, pad, o,
            val_start, val_stop, offset, v_out, theta_out, score_out, simulate,
        )  # fmt: skip


@njit(cache=True, parallel=True)
def fit_units_parallel(
    units, rt, bounds, i1p, i2p, pad, o, val_start, val_stop, offset, v_out, theta_out, score_out, simulate,
    n_threads,
):  # fmt: skip
    """Parallel driver: thread t takes units t, t + n_threads, ...

    Every unit writes only its own candidates' rows of v_out and theta_out,
    and computes them exactly as :func:`fit_units` does.
    """
    n_units = units.shape[0]
    for t in prange(n_threads):
        for u in range(t, n_units, n_threads):
            _fit_unit(
                units[u, 0], units[u, 1], rt, bounds, i1p, i2p, pad, o,
                val_start, val_stop, offset, v_out, theta_out, score_out, simulate,
            )  # fmt: skip


def has_fma() -> bool:
    """Whether numba compiles for a CPU with fused multiply-add units: the features it
    compiles with (``NUMBA_CPU_FEATURES`` if set, else the host's). Without them
    ``llvm.fma`` is a library call per element, many times slower than a multiply and an
    add."""
    features = numba.config.CPU_FEATURES
    if features is None:
        from llvmlite import binding

        return bool(binding.get_host_cpu_features().get("fma", False))
    flags = {f[1:]: f[0] == "+" for f in features.split(",") if f}
    return flags.get("fma", False)


def max_threads() -> int:
    """Most threads the parallel kernel can use (numba's pool size)."""
    return numba.config.NUMBA_NUM_THREADS


def run_parallel(kernel, args, threads: int) -> None:
    """Run a parallel driver on ``threads`` numba threads, restoring the pool size after."""
    previous = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        kernel(*args, threads)
    finally:
        numba.set_num_threads(previous)
