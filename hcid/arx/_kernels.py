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
"""

import numba
import numpy as np
from numba import njit, prange

from hcid.arx import _simd

# Samples simulated between two finiteness checks.
_BLOCK = 256
# Samples of one step of simulate_lanes: input part, recursion, then a
# pruning check on the validation rows.
_CHUNK = 128
# Lanes of simulate_wide, and the values past the record its input step
# reads (a chunk's input part is computed in whole quadruples of samples).
LANES = _simd.LANES
TAIL = _simd.SAMPLES - 1
# The vector steps are LLVM IR: without the JIT, every block takes the
# plain four-lane path (simulate_lanes), the vector path's twin.
_WIDE = not numba.config.DISABLE_JIT


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
        last = cols[j]
        s = 0.0
        for i in range(j + 1, last + 1):
            s += dst[j, i] * dst[j, i]
        if s == 0.0:
            continue
        alpha = dst[j, j]
        beta = -np.copysign(np.sqrt(alpha * alpha + s), alpha)
        tau = (beta - alpha) / beta
        scale = 1.0 / (alpha - beta)
        for i in range(j + 1, last + 1):
            dst[j, i] *= scale
        dst[j, j] = beta
        for k in range(j + 1, n_cols + 1):
            w = dst[k, j]
            for i in range(j + 1, last + 1):
                w += dst[j, i] * dst[k, i]
            w *= tau
            dst[k, j] -= w
            for i in range(j + 1, last + 1):
                dst[k, i] -= w * dst[j, i]


@njit(cache=True)
def back_substitute(f, n_f, k, theta, tmp):
    """Solve the leading k x k block of a transposed triangular factor.

    ``f[:n_f]`` is the factor, ``f[n_f]`` the rhs. Writes ``theta[:k]``.
    Returns False (theta undefined) if a diagonal entry is exactly zero.
    """
    for i in range(k):
        tmp[i] = f[n_f, i]
    for j in range(k - 1, -1, -1):
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
    simulated by :func:`simulate_blocks`) and ``score_out`` its explained
    sum of squares on the estimation rows, ``||c[:k]||^2`` (larger = smaller
    prediction error); unstable and singular ones get ``inf`` as before.
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
    unit = np.empty((m_u + 1, p))
    select_qr(rt, p, cols, m_u, unit)

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

    group = np.empty((m_u + 1, m_u))
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
        for g2 in range(g2_lo, g2_hi + 1):
            # Subset [i1 lags 1..g1, i2 lags 1..g2, o lags 1..na_hi]: every
            # na of the range is a prefix of this one factorisation.
            m_g = g1 + g2 + na_hi
            for j in range(g1):
                cols[j] = j
            for j in range(g2):
                cols[g1 + j] = m1 + j
            for i in range(na_hi):
                cols[g1 + g2 + i] = m1 + m2 + i
            select_qr(unit, m_u, cols, m_g, group)
            explained = 0.0
            for i in range(g1 + g2 + na_lo - 1):
                explained += group[m_g, i] * group[m_g, i]
            for na in range(na_lo, na_hi + 1):
                k = g1 + g2 + na
                idx = offset[na - na_lo, g1 - nb1_lo, g2 - nb2_lo] + within
                explained += group[m_g, k - 1] * group[m_g, k - 1]
                score_out[idx] = explained
                solved = back_substitute(group, m_g, k, theta, tmp)
                finite = solved
                if solved:
                    for j in range(k):
                        if not abs(theta[j]) < np.inf:
                            finite = False
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
                    a[i + 1] = theta[g1 + g2 + i]
                for i in range(na):
                    theta_out[idx, i] = a[i + 1]
                for j in range(g1):
                    theta_out[idx, na + j] = b1[j]
                for j in range(g2):
                    theta_out[idx, na + g1 + j] = b2[j]
                v = np.inf
                if not is_stable(a, na, jury):
                    pass
                elif not simulate:
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
        (NaN if the regression was singular).
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


@njit(cache=True)
def inputs_into(b, nb, nk, ip, pad, k0, k1, x):
    """Add ``B i(k - nk)`` to ``x[k - k0]`` for ``k0 <= k < k1``, term after term.

    The order of :func:`simulate_into`'s input part (``x`` starts at 0, then
    ``b[0]``, ``b[1]``, ... of input 1, then of input 2), so each ``x[k]``
    is the same sum of the same products, bit for bit.
    """
    m = k1 - k0
    for j in range(nb):
        c = b[j]
        base = pad - nk - j + k0
        src = ip[base : base + m]
        for k in range(m):
            x[k] += c * src[k]


@njit(cache=True)
def simulate_lanes(
    coef, na, b1, nb1, nk1, b2, nb2, nk2, i1p, i2p, pad, o, val_start, val_stop, bound, xs, yh, v_out,
    pruned,
):  # fmt: skip
    """Simulate four candidates of one order triple side by side, pruning on V.

    Lane l is the candidate ``a = coef[l::4]`` (``coef[i * 4 + l]`` holds
    a_i, length ``(na + 1) * 4``, ``a_2 = 0`` padded when na = 1),
    ``b1[l, :nb1]``, ``b2[l, :nb2]``, delays ``nk1[l]``, ``nk2[l]``. Each
    lane does exactly the arithmetic of :func:`simulate_into` and
    :func:`_validation_mse` (same operations, same order), so an unpruned
    lane's V is bit-identical to theirs; the four lanes are independent
    chains that keep the floating-point units busy while one waits on its
    loop-carried multiply-add (``y(k-1)``).

    Pruning: at the end of each ``_CHUNK`` of validation rows a lane whose
    partial V, ``((s0 + s1) + (s2 + s3)) / n_val`` over the rows so far,
    exceeds ``bound`` stops: its final V could only be larger (sums of
    squares grow, rounding is monotone), so ``v_out[l]`` receives that
    partial V, a lower bound strictly above ``bound``. A lane whose output
    stops being finite gets ``inf``, as in :func:`simulate_into`. The batch
    ends when every lane has stopped or the record ends.

    Parameters
    ----------
    xs : float64 array, shape (4, _CHUNK)
        Scratch for the input part.
    yh : float64 array, shape ((na + n) * 4,)
        Scratch: the outputs, interleaved by lane after ``na`` rows of zeros.
    v_out : float64 array, shape (4,)
        Out: V, a pruned lane's lower bound, or inf.
    pruned : bool array, shape (4,)
        Out: which lanes were pruned.

    Returns
    -------
    int
        Number of samples simulated (the same for every lane).
    """
    n = o.shape[0]
    n_val = val_stop - val_start
    quad_end = val_start + 4 * (n_val // 4)
    for k in range(na * 4):
        yh[k] = 0.0
    # a_1, a_2 in registers, like simulate_into.
    a1_0, a1_1, a1_2, a1_3 = coef[4], coef[5], coef[6], coef[7]
    a2_0, a2_1, a2_2, a2_3 = coef[8], coef[9], coef[10], coef[11]
    y1_0 = y1_1 = y1_2 = y1_3 = 0.0
    y2_0 = y2_1 = y2_2 = y2_3 = 0.0
    # Validation sums per lane: four partial sums, as in _validation_mse.
    e00 = e01 = e02 = e03 = 0.0
    e10 = e11 = e12 = e13 = 0.0
    e20 = e21 = e22 = e23 = 0.0
    e30 = e31 = e32 = e33 = 0.0
    live0 = live1 = live2 = live3 = True
    for lane in range(4):
        v_out[lane] = np.inf
        pruned[lane] = False
    k0 = 0
    while k0 < n:
        # Chunks end on val_start + multiples of _CHUNK, so the pruning
        # checks fall on whole quadruples of validation rows.
        r = (val_start - k0) % _CHUNK
        k1 = min(k0 + (r if r > 0 else _CHUNK), n)
        m = k1 - k0
        for lane in range(4):
            for k in range(m):
                xs[lane, k] = 0.0
            inputs_into(b1[lane], nb1, nk1[lane], i1p, pad, k0, k1, xs[lane])
            inputs_into(b2[lane], nb2, nk2[lane], i2p, pad, k0, k1, xs[lane])
        for k in range(k0, k1):
            q = np.uint64(k - k0)
            base = np.uint64((na + k) * 4)
            s00 = s01 = s02 = s03 = 0.0
            s10 = s11 = s12 = s13 = 0.0
            i = na
            while i > 3:
                c0 = np.uint64(i * 4)
                c1 = np.uint64((i - 1) * 4)
                s00 += coef[c0] * yh[base - c0]
                s01 += coef[c0 + np.uint64(1)] * yh[base - c0 + np.uint64(1)]
                s02 += coef[c0 + np.uint64(2)] * yh[base - c0 + np.uint64(2)]
                s03 += coef[c0 + np.uint64(3)] * yh[base - c0 + np.uint64(3)]
                s10 += coef[c1] * yh[base - c1]
                s11 += coef[c1 + np.uint64(1)] * yh[base - c1 + np.uint64(1)]
                s12 += coef[c1 + np.uint64(2)] * yh[base - c1 + np.uint64(2)]
                s13 += coef[c1 + np.uint64(3)] * yh[base - c1 + np.uint64(3)]
                i -= 2
            if i == 3:
                s00 += coef[12] * yh[base - np.uint64(12)]
                s01 += coef[13] * yh[base - np.uint64(11)]
                s02 += coef[14] * yh[base - np.uint64(10)]
                s03 += coef[15] * yh[base - np.uint64(9)]
            y_0 = ((xs[0, q] - (s00 + s10)) - a2_0 * y2_0) - a1_0 * y1_0
            y_1 = ((xs[1, q] - (s01 + s11)) - a2_1 * y2_1) - a1_1 * y1_1
            y_2 = ((xs[2, q] - (s02 + s12)) - a2_2 * y2_2) - a1_2 * y1_2
            y_3 = ((xs[3, q] - (s03 + s13)) - a2_3 * y2_3) - a1_3 * y1_3
            yh[base] = y_0
            yh[base + np.uint64(1)] = y_1
            yh[base + np.uint64(2)] = y_2
            yh[base + np.uint64(3)] = y_3
            y2_0, y2_1, y2_2, y2_3 = y1_0, y1_1, y1_2, y1_3
            y1_0, y1_1, y1_2, y1_3 = y_0, y_1, y_2, y_3
        # Validation rows of this chunk: whole quadruples, then the tail
        # (rows from quad_end on) into the first partial sum.
        k = max(k0, val_start)
        stop = min(k1, val_stop)
        while k + 4 <= min(stop, quad_end):
            b = (na + k) * 4
            d = yh[b] - o[k]
            e00 += d * d
            d = yh[b + 4] - o[k + 1]
            e01 += d * d
            d = yh[b + 8] - o[k + 2]
            e02 += d * d
            d = yh[b + 12] - o[k + 3]
            e03 += d * d
            d = yh[b + 1] - o[k]
            e10 += d * d
            d = yh[b + 5] - o[k + 1]
            e11 += d * d
            d = yh[b + 9] - o[k + 2]
            e12 += d * d
            d = yh[b + 13] - o[k + 3]
            e13 += d * d
            d = yh[b + 2] - o[k]
            e20 += d * d
            d = yh[b + 6] - o[k + 1]
            e21 += d * d
            d = yh[b + 10] - o[k + 2]
            e22 += d * d
            d = yh[b + 14] - o[k + 3]
            e23 += d * d
            d = yh[b + 3] - o[k]
            e30 += d * d
            d = yh[b + 7] - o[k + 1]
            e31 += d * d
            d = yh[b + 11] - o[k + 2]
            e32 += d * d
            d = yh[b + 15] - o[k + 3]
            e33 += d * d
            k += 4
        while k < stop:
            b = (na + k) * 4
            d = yh[b] - o[k]
            e00 += d * d
            d = yh[b + 1] - o[k]
            e10 += d * d
            d = yh[b + 2] - o[k]
            e20 += d * d
            d = yh[b + 3] - o[k]
            e30 += d * d
            k += 1
        # A non-finite output stays non-finite (module doc of
        # simulate_into): such a lane is unstable, V = inf.
        if live0 and not abs(y1_0) < np.inf:
            live0 = False
        if live1 and not abs(y1_1) < np.inf:
            live1 = False
        if live2 and not abs(y1_2) < np.inf:
            live2 = False
        if live3 and not abs(y1_3) < np.inf:
            live3 = False
        if k1 > val_start and k1 < n:
            # Partial V: finite and above the bound means pruned.
            if live0:
                p = ((e00 + e01) + (e02 + e03)) / n_val
                if p < np.inf and p > bound:
                    v_out[0] = p
                    pruned[0] = True
                    live0 = False
            if live1:
                p = ((e10 + e11) + (e12 + e13)) / n_val
                if p < np.inf and p > bound:
                    v_out[1] = p
                    pruned[1] = True
                    live1 = False
            if live2:
                p = ((e20 + e21) + (e22 + e23)) / n_val
                if p < np.inf and p > bound:
                    v_out[2] = p
                    pruned[2] = True
                    live2 = False
            if live3:
                p = ((e30 + e31) + (e32 + e33)) / n_val
                if p < np.inf and p > bound:
                    v_out[3] = p
                    pruned[3] = True
                    live3 = False
            if not (live0 or live1 or live2 or live3):
                return k1
        k0 = k1
    if live0:
        v_out[0] = _finite_or_inf(((e00 + e01) + (e02 + e03)) / n_val)
    if live1:
        v_out[1] = _finite_or_inf(((e10 + e11) + (e12 + e13)) / n_val)
    if live2:
        v_out[2] = _finite_or_inf(((e20 + e21) + (e22 + e23)) / n_val)
    if live3:
        v_out[3] = _finite_or_inf(((e30 + e31) + (e32 + e33)) / n_val)
    return n


@njit(cache=True)
def _finite_or_inf(v):
    return v if v < np.inf else np.inf


@njit(cache=True)
def simulate_wide(
    coef, na, b1, nb1, nk1, b2, nb2, nk2, n_lanes, i1p, i2p, pad, o, val_start, val_stop, bound,
    off1, off2, xt, yh, eacc, v_out, pruned,
):  # fmt: skip
    """:func:`simulate_lanes` for ``LANES`` lanes, on explicit vectors (:mod:`hcid.arx._simd`).

    Lanes ``0 .. n_lanes - 1`` are candidates laid out as in
    :func:`simulate_lanes` with ``LANES`` for 4 (``coef[i * LANES + l]``,
    ``b1[l]``, ``nk1[l]``, ...); the others must hold ``a = [1, 0, ...]``,
    zero B and zero delays and are ignored. Same arithmetic per lane, same
    pruning rule and chunks, so V (or a pruned lane's lower bound) is
    bit-identical to :func:`simulate_lanes`'. Requires ``na <= _simd.MAX_NA``
    and inputs with ``TAIL`` readable values after the record.

    Scratch: ``off1``, ``off2`` int64 (LANES,); ``xt`` (_CHUNK * LANES,);
    ``yh`` ((max(na, 2) + _CHUNK) * LANES,), the last rows of one chunk
    moved to its top for the next; ``eacc`` (4 * LANES,).
    """
    n = o.shape[0]
    n_val = val_stop - val_start
    quad_end = val_start + 4 * (n_val // 4)
    h = max(na, 2)
    for k in range(h * LANES):
        yh[k] = 0.0
    for k in range(4 * LANES):
        eacc[k] = 0.0
    live = np.zeros(LANES, dtype=np.bool_)
    for lane in range(n_lanes):
        live[lane] = True
        v_out[lane] = np.inf
        pruned[lane] = False
    n_live = n_lanes
    k0 = 0
    while k0 < n:
        r = (val_start - k0) % _CHUNK
        k1 = min(k0 + (r if r > 0 else _CHUNK), n)
        m = k1 - k0
        for lane in range(LANES):
            off1[lane] = pad - nk1[lane] + k0
            off2[lane] = pad - nk2[lane] + k0
        steps = (m + TAIL) // _simd.SAMPLES * _simd.SAMPLES
        _simd.lane_inputs(b1, nb1, off1, i1p, b2, nb2, off2, i2p, steps, xt)
        _simd.lane_recursion(coef, na, xt, m, yh, h, o, k0, val_start, val_stop, quad_end, eacc)
        last = (h + m - 1) * LANES
        for lane in range(n_lanes):
            if live[lane] and not abs(yh[last + lane]) < np.inf:
                live[lane] = False
                n_live -= 1
        if k1 > val_start and k1 < n:
            for lane in range(n_lanes):
                if live[lane]:
                    p = _partial_v(eacc, lane, n_val)
                    if p < np.inf and p > bound:
                        v_out[lane] = p
                        pruned[lane] = True
                        live[lane] = False
                        n_live -= 1
            if n_live == 0:
                return k1
        for k in range(h * LANES):
            yh[k] = yh[m * LANES + k]
        k0 = k1
    for lane in range(n_lanes):
        if live[lane]:
            v_out[lane] = _finite_or_inf(_partial_v(eacc, lane, n_val))
    return n


@njit(cache=True)
def _partial_v(eacc, lane, n_val):
    return ((eacc[lane] + eacc[LANES + lane]) + (eacc[2 * LANES + lane] + eacc[3 * LANES + lane])) / n_val


@njit(cache=True)
def _simulate_block(
    row, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, pad, o,
    val_start, val_stop, prune, v_all, counts,
):  # fmt: skip
    """Simulate the stable candidates of one order triple (one candidate block).

    Candidates waiting with ``v_all = NaN`` (stable, see :func:`_fit_unit`)
    run ``LANES`` at a time (:func:`simulate_wide`; four at a time with
    :func:`simulate_lanes` without the JIT or above ``_simd.MAX_NA``), best
    prediction error first: the first batch (the remainder of the division
    into batches) in full, which makes ``bound``, the best V so far, tight
    at once; the others stop as soon as their partial V exceeds it
    (``prune``). ``counts[row]`` receives the numbers
    simulated in full and pruned, and the work done.
    """
    na, nb1, nb2 = block_orders[row, 0], block_orders[row, 1], block_orders[row, 2]
    start, size = block_start[row], block_size[row]
    nk1_lo, nk2_lo = bounds[3, 0], bounds[4, 0]
    n_d2 = bounds[4, 1] - bounds[4, 0] + 1 if nb2 > 0 else 1
    n = o.shape[0]
    waiting = np.empty(size, dtype=np.int64)
    keys = np.empty(size)
    m = 0
    for c in range(start, start + size):
        if np.isnan(v_all[c]):
            waiting[m] = c
            keys[m] = -score[c]
            m += 1
    if m == 0:
        return
    order = np.argsort(keys[:m], kind="mergesort")
    wide = _WIDE and na <= _simd.MAX_NA
    width = LANES if wide else 4
    h = max(na, 2)
    coef = np.zeros((h + 1) * width)
    b1 = np.zeros((width, max(nb1, 1)))
    b2 = np.zeros((width, max(nb2, 1)))
    nk1 = np.zeros(width, dtype=np.int64)
    nk2 = np.zeros(width, dtype=np.int64)
    lanes = np.empty(width, dtype=np.int64)
    v = np.empty(width)
    pruned = np.empty(width, dtype=np.bool_)
    if wide:
        off1 = np.empty(LANES, dtype=np.int64)
        off2 = np.empty(LANES, dtype=np.int64)
        xt = np.empty(_CHUNK * LANES)
        yh = np.empty((h + _CHUNK) * LANES)
        eacc = np.empty(4 * LANES)
    else:
        xs = np.empty((4, _CHUNK))
        yh = np.empty((na + n) * 4)
    bound = np.inf
    n_full = 0
    n_pruned = 0
    samples = 0
    # The fewest batches; the first takes the remainder, so that every
    # later batch is full and runs against a bound.
    first = 0
    used = min(width, m)
    while first < m:
        for lane in range(width):
            if lane >= used and wide:
                # An idle vector lane: a = [1, 0, ...], no input; ignored.
                coef[lane] = 1.0
                for i in range(h):
                    coef[(i + 1) * width + lane] = 0.0
                for j in range(nb1):
                    b1[lane, j] = 0.0
                for j in range(nb2):
                    b2[lane, j] = 0.0
                nk1[lane] = 0
                nk2[lane] = 0
                continue
            # A short first batch of four repeats its first candidate in the idle lanes.
            pick = first + lane if lane < used else first
            c = waiting[order[pick]]
            lanes[lane] = c
            within = c - start
            nk1[lane] = nk1_lo + within // n_d2 if nb1 > 0 else 0
            nk2[lane] = nk2_lo + within % n_d2 if nb2 > 0 else 0
            coef[lane] = 1.0
            for i in range(na):
                coef[(i + 1) * width + lane] = theta_all[c, i]
            for j in range(nb1):
                b1[lane, j] = theta_all[c, na + j]
            for j in range(nb2):
                b2[lane, j] = theta_all[c, na + nb1 + j]
        if wide:
            done = simulate_wide(
                coef, na, b1, nb1, nk1, b2, nb2, nk2, used, i1p, i2p, pad, o, val_start, val_stop,
                bound, off1, off2, xt, yh, eacc, v, pruned,
            )  # fmt: skip
        else:
            done = simulate_lanes(
                coef, na, b1, nb1, nk1, b2, nb2, nk2, i1p, i2p, pad, o, val_start, val_stop,
                bound, xs, yh, v, pruned,
            )  # fmt: skip
        samples += done * used
        for lane in range(used):
            v_all[lanes[lane]] = v[lane]
            if pruned[lane]:
                n_pruned += 1
            else:
                n_full += 1
            if prune and v[lane] < bound:
                bound = v[lane]
        first += used
        used = min(width, m - first)
    counts[row, 0] = n_full
    counts[row, 1] = n_pruned
    counts[row, 2] = samples


@njit(cache=True)
def simulate_blocks(
    block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, pad, o,
    val_start, val_stop, prune, v_all, counts,
):  # fmt: skip
    """Serial driver of the simulations: :func:`_simulate_block` for every order triple.

    Parameters
    ----------
    block_orders : int64 array, shape (n_blocks, 3)
        ``(na, nb1, nb2)`` of each candidate block.
    block_start, block_size : int64 arrays, shape (n_blocks,)
        Where each block starts in the candidate order, and its length.
    theta_all, score, v_all :
        As written by :func:`fit_units` with ``simulate`` False; v_all's
        NaN entries are replaced by V (or a pruned lower bound above the
        block's best V).
    prune : bool
        False: every stable candidate is simulated in full.
    counts : int64 array, shape (n_blocks, 3)
        Out per block: candidates simulated in full, candidates pruned, and
        candidate-samples simulated (lanes times samples).
    """
    for row in range(block_start.shape[0]):
        _simulate_block(
            row, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, pad, o,
            val_start, val_stop, prune, v_all, counts,
        )  # fmt: skip


@njit(cache=True, parallel=True)
def simulate_blocks_parallel(
    block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, pad, o,
    val_start, val_stop, prune, v_all, counts, n_threads,
):  # fmt: skip
    """Parallel driver: thread t takes blocks t, t + n_threads, ...; each block alone
    decides its pruning, so the result is bit-identical to :func:`simulate_blocks`."""
    n_blocks = block_start.shape[0]
    for t in prange(n_threads):
        for row in range(t, n_blocks, n_threads):
            _simulate_block(
                row, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p,
                pad, o, val_start, val_stop, prune, v_all, counts,
            )  # fmt: skip


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
