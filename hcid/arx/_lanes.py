"""Lane kernels of the ARX grid engine: many candidates of one order triple simulated side by side (private).

The vector steps are numba intrinsics (:mod:`hcid.arx._lane_ir`, where the
layouts and the two arithmetics are described); :func:`simulate_wide` and
:func:`simulate_affine` run them chunk by chunk with pruning on V;
:func:`simulate_lanes` (four lanes in plain numba, always unfused) is their
twin, and the path without the JIT and above ``MAX_NA``. The order triples
are walked in :mod:`hcid.arx._blocks`.

``simulate_lanes`` is one kernel of about 200 lines: its four lanes' recursion,
pruning check and error sums share registers in one loop, which a split into
called functions would spill.
"""

import numpy as np
from numba import njit

from hcid.arx import _cache  # noqa: F401 (first: the kernels' cache locator, hcid.arx._cache)
from hcid.arx._lane_ir import (  # noqa: F401 (the layout, read by the engine and the tests)
    _AFFINE_MIN,
    _AFFINE_SAMPLES,
    _CHUNK,
    _GROUPS,
    _HALVES,
    _TAP_BLOCK,
    _WIDE,
    _WIDTH,
    LANES,
    MAX_NA,
    SAMPLES,
    TAIL,
    lane_inputs,
    lane_inputs_affine,
    lane_recursion,
)


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
    k0 = np.int64(0)  # not a literal 0: a callee would be compiled for Literal[int](0) too
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
def _aligned_zeros(n):
    """``n`` float64 zeros starting on a 64-byte boundary.

    A vector of _WIDTH doubles then fills one cache line instead of
    straddling two (numba aligns its arrays to 32 bytes only): 1.07 to
    1.25x on a batch of vector lanes.
    """
    raw = np.zeros(n + _WIDTH)
    skip = (-(raw.ctypes.data // 8)) % _WIDTH
    return raw[skip : skip + n]


@njit(cache=True)
def tap_vectors(ip):
    """Every run of eight values of ``ip``, one after another: ``tv[t * 8 + k] = ip[t + k]``
    (0 past the end), 64-byte aligned, so that :func:`lane_inputs` loads each
    from one cache line. Eight times the record: 130 kB for a paper input."""
    n = ip.shape[0]
    tv = _aligned_zeros(n * _WIDTH)
    for t in range(n):
        for k in range(min(_WIDTH, n - t)):
            tv[t * _WIDTH + k] = ip[t + k]
    return tv


@njit(cache=True)
def _finite_or_inf(v):
    return v if v < np.inf else np.inf


@njit(cache=True)
def _check_lanes(x1, x2, pad, n, per_value, b1, nb1, b2, nb2):
    """The vector steps read without bounds checks: refuse what they would overrun
    (B with one row per lane, as :func:`simulate_wide` takes it). The inputs
    must hold pad + n + TAIL values, ``per_value`` entries each (``_WIDTH``
    for :func:`tap_vectors`, 1 for a padded input)."""
    if x1.shape[0] < (pad + n + TAIL) * per_value or x2.shape[0] < (pad + n + TAIL) * per_value:
        raise ValueError("vector lanes: the inputs need pad + n + TAIL values (8 each as tap vectors)")
    if b1.shape[0] != LANES or b2.shape[0] != LANES or b1.shape[1] < nb1 or b2.shape[1] < nb2:
        raise ValueError("vector lanes: B must have one row per lane and at least nb columns")


@njit(cache=True, inline="always")
def simulate_wide(
    coef, na, b1, nb1, nk1, b2, nb2, nk2, n_lanes, tv1, tv2, pad, o, val_start, val_stop, bound,
    off1, off2, xt, yh, eacc, v_out, pruned, fused,
):  # fmt: skip
    """:func:`simulate_lanes` for ``LANES`` lanes, on explicit vectors (the vector steps).

    Lanes ``0 .. n_lanes - 1`` are candidates laid out as in
    :func:`simulate_lanes` with ``LANES`` for 4 (``coef[i * LANES + l]``,
    ``b1[l]``, ``nk1[l]``, ...); the others must hold ``a = [1, 0, ...]``,
    zero B and zero delays and are ignored. Same arithmetic per lane
    (unless ``fused``: then each multiply-add rounds once, module
    docstring), same pruning rule and chunks, with a bound per lane
    (``bound[l]``, float64 (LANES,)), so V (or a pruned lane's lower bound)
    is bit-identical to :func:`simulate_lanes`' with that lane's bound, unfused. Requires ``na <=
    MAX_NA`` and inputs with ``TAIL`` readable values after the record,
    given as ``tv1 = tap_vectors(i1p)``, ``tv2 = tap_vectors(i2p)``.

    Scratch: ``off1``, ``off2`` int64 (LANES,); ``xt`` (_CHUNK * LANES,);
    ``yh`` ((max(na, 2) + _CHUNK) * LANES,), the last rows of one chunk
    moved to its top for the next; ``eacc`` (4 * LANES,).
    """
    _check_lanes(tv1, tv2, pad, o.shape[0], _WIDTH, b1, nb1, b2, nb2)
    used = np.arange(LANES) < n_lanes
    return _wide_loop(
        coef, na, used, o, val_start, val_stop, bound, xt, yh, eacc, v_out, pruned, fused,
        False, b1, nb1, nk1, b2, nb2, nk2, tv1, tv2, pad, off1, off2,
    )  # fmt: skip


@njit(cache=True, inline="always")
def simulate_affine(
    coef, na, b1t, nb1, c1, b2t, nb2, c2, used, r1, i1p, i2p, pad, o, val_start, val_stop, bound,
    xt, yh, eacc, v_out, pruned, fused,
):  # fmt: skip
    """:func:`simulate_wide` for lanes in affine groups (:func:`lane_inputs_affine`).

    Lane ``l = g * _WIDTH + w`` is delayed by ``c1[g] + w`` on input 1 and
    ``c2[g]`` on input 2; its B are ``b1t[:, l]``, ``b2t[:, l]`` (tap-major,
    shape (taps, LANES)); ``used[l]`` says whether it holds a candidate (an
    unused lane must hold ``a = [1, 0, ...]`` and zero B; its delays are
    its group's). ``r1`` is ``i1p`` reversed. Same arithmetic per lane,
    pruning and results as :func:`simulate_wide`.
    """
    _check_lanes(i1p, i2p, pad, o.shape[0], 1, b1t.T, nb1, b2t.T, nb2)
    if (
        r1.shape[0] != i1p.shape[0]
        or c1.shape[0] != _GROUPS
        or c2.shape[0] != _GROUPS
        or used.shape[0] != LANES
    ):
        raise ValueError("affine lanes: r1 as long as i1p, one c1 and c2 per group, one used flag per lane")
    base1 = np.empty(_GROUPS, dtype=np.int64)
    base2 = np.empty(_GROUPS, dtype=np.int64)
    for g in range(_GROUPS):
        if c1[g] < 0 or c1[g] + _WIDTH - 1 + nb1 - 1 > pad or c2[g] < 0 or c2[g] + nb2 - 1 > pad:
            raise ValueError("affine lanes: a delay beyond the padding")
        base1[g] = r1.shape[0] - 1 - pad + c1[g]
        base2[g] = pad - c2[g]
    return _wide_loop(
        coef, na, used, o, val_start, val_stop, bound, xt, yh, eacc, v_out, pruned, fused,
        True, b1t, nb1, c1, b2t, nb2, c2, r1, i2p, pad, base1, base2,
    )  # fmt: skip


@njit(cache=True)
def _wide_loop(
    coef, na, used, o, val_start, val_stop, bound, xt, yh, eacc, v_out, pruned, fused,
    affine, b1, nb1, nk1, b2, nb2, nk2, x1, x2, pad, off1, off2,
):  # fmt: skip
    """The chunk loop of :func:`simulate_wide` and :func:`simulate_affine`: input part
    (general or affine lanes), recursion, finiteness and pruning checks.

    General lanes: inputs ``x1``, ``x2`` as :func:`tap_vectors`, ``nk1``,
    ``nk2`` per lane, ``off1``, ``off2`` scratch for their offsets. Affine
    lanes: ``x1`` the reversed i1p, ``x2`` i2p, ``off1``, ``off2`` the groups'
    base1 and base2 (:func:`lane_inputs_affine`), ``nk1``, ``nk2`` unused.
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
    n_live = 0
    for lane in range(LANES):
        if used[lane]:
            live[lane] = True
            n_live += 1
            v_out[lane] = np.inf
            pruned[lane] = False
    k0 = 0
    while k0 < n:
        r = (val_start - k0) % _CHUNK
        k1 = min(k0 + (r if r > 0 else _CHUNK), n)
        m = k1 - k0
        steps = (m + TAIL) // SAMPLES * SAMPLES
        if affine:
            lane_inputs_affine(b1, nb1, x1, off1, b2, nb2, x2, off2, k0, steps, xt, fused)
        else:
            for lane in range(LANES):
                off1[lane] = pad - nk1[lane] + k0
                off2[lane] = pad - nk2[lane] + k0
            lane_inputs(b1, nb1, off1, x1, b2, nb2, off2, x2, steps, xt, fused)
        if not lane_recursion(coef, na, xt, m, yh, h, o, k0, val_start, val_stop, quad_end, eacc, fused):
            raise ValueError("vector lanes: na above MAX_NA")
        last = (h + m - 1) * LANES
        for lane in range(LANES):
            if live[lane] and not abs(yh[last + lane]) < np.inf:
                live[lane] = False
                n_live -= 1
        if k1 > val_start and k1 < n:
            for lane in range(LANES):
                if live[lane]:
                    p = _partial_v(eacc, lane, n_val)
                    if p < np.inf and p > bound[lane]:
                        v_out[lane] = p
                        pruned[lane] = True
                        live[lane] = False
                        n_live -= 1
            if n_live == 0:
                return k1
        for k in range(h * LANES):
            yh[k] = yh[m * LANES + k]
        k0 = k1
    for lane in range(LANES):
        if live[lane]:
            v_out[lane] = _finite_or_inf(_partial_v(eacc, lane, n_val))
    return n


@njit(cache=True)
def _partial_v(eacc, lane, n_val):
    return ((eacc[lane] + eacc[LANES + lane]) + (eacc[2 * LANES + lane] + eacc[3 * LANES + lane])) / n_val
