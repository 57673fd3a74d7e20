"""Lane kernels of the ARX grid engine: many candidates simulated side by side (private).

The candidates of the order triples are simulated ``LANES`` at a time,
each pruned against the best V of its triple so far (see
:func:`simulate_wide`, :func:`_simulate_run`). numba vectorises loops
over samples, but the ARX recursion is a chain through the samples: only
independent candidates (lanes) can share a vector, and numba leaves LLVM's
SLP vectoriser, which would pack them, off. The two steps of
:func:`simulate_wide` (:func:`lane_inputs`, :func:`lane_recursion`) are
therefore numba intrinsics that emit LLVM IR on ``<8 x double>`` vectors,
one vector per eight lanes, ``_GROUPS`` vectors side by side so that their
multiply-add chains overlap. LLVM maps a vector to one AVX-512 register,
or splits it into two AVX2 (four SSE2) registers on a machine without;
the arithmetic of each lane is the same on all of them.

Two input steps. The general one (:func:`lane_inputs`) takes any delays
per lane: it sums each lane's taps over 16 samples and transposes the
sums into lanes. It reads the inputs as :func:`tap_vectors` (every run
of eight values stored apart, eight times the record), so that each
vector load is one aligned cache line rather than two for seven taps in
eight: the step is bound by its loads. An
*affine group* (:func:`lane_inputs_affine`) is eight candidates of one
triple with consecutive nk1 at one nk2: its input 1 is one vector load
from the reversed record and its input 2 one broadcast,
with the tap coefficients held in registers, and no transpose. Most candidates of the direct grid (nk1 1..50) form
such groups; stage 1 (nk1 1..5), the groups with many unstable candidates
and the rest take the general step (:func:`_simulate_run`).

Two arithmetics, chosen per call (``fused``; both loops are compiled, the
flag picks one per chunk). Unfused, every lane does the arithmetic of
:func:`hcid.arx._kernels.simulate_into` (the same IEEE-754 operations in
the same order: ``fmul`` and ``fadd`` / ``fsub`` without fast-math flags,
which LLVM may neither reassociate nor fuse), so a lane's V is
bit-identical to it; the tests compare them. Fused, each multiply-add
(an input tap, an output lag, a squared error) is one ``llvm.fma``,
rounded once: the same order, fewer operations and roundings. ``llvm.fma`` is exact by definition, so the values
are the same on every machine (one without FMA units computes it in
software, slowly); the tests compare them with an exact-rational twin.
The engine uses fused V for its search only and recomputes the frontier's V
unfused (:func:`hcid.arx.engine.fit_grid`).
Where lanes of different B lengths share a batch, the shorter B are padded
with zero coefficients: ``x + 0.0 * i`` is ``x`` (for finite i; the sign of
a zero sum may flip, which changes no later value but a zero's sign, and no
square), so V stays bit-identical; ``fma(0.0, i, x)`` is ``x`` likewise.
:func:`simulate_lanes` (four lanes in plain numba, always unfused) is the
unfused vector path's twin, and the path without the JIT (the intrinsics
run only compiled) and above ``MAX_NA``; so is
:func:`hcid.arx._kernels.squared_errors` for the frontier's VAF, which is
always unfused.

This module calls no kernel of :mod:`hcid.arx._kernels` (nor the reverse):
numba's on-disk cache of a function is invalidated by a change of its own
file only, so kernels that call each other share a file.

Layouts of the vector steps (``LANES`` lanes, flat float64 arrays):
``xt[q * LANES + l]`` the input part of lane l at chunk sample q;
``yh[row * LANES + l]`` the simulated output; ``coef[i * LANES + l]`` the
coefficient a_i of lane l (``a_2 = 0`` when na = 1); ``eacc[p * LANES + l]``
the four partial sums of squared errors of lane l.
"""

from types import SimpleNamespace

import numba
import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

# Doubles per vector and vectors per step: two vectors side by side keep two multiply-add
# chains in flight (the choice and its measurement: docs/engine.md, docs/benchmarks.md).
_WIDTH = 8
_GROUPS = 2
LANES = _WIDTH * _GROUPS
# Samples of one step of lane_inputs: two vectors per lane, so that every
# broadcast coefficient serves two multiplies.
_HALVES = 2
SAMPLES = _HALVES * _WIDTH
# Affine lanes (lane_inputs_affine): samples per step and taps whose
# coefficients stay in registers.
_AFFINE_SAMPLES = 4
_TAP_BLOCK = 8
# Fewest waiting candidates (of _WIDTH) for an affine group: eight affine lanes
# cost about as much as six general ones (docs/benchmarks.md), so a group with
# fewer waiting candidates is left to the general lanes.
_AFFINE_MIN = 6
# Largest na with a vector recursion (each na is its own unrolled loop).
MAX_NA = 12

# Samples of one step of simulate_lanes / simulate_wide: input part,
# recursion, then a pruning check on the validation rows.
_CHUNK = 128
# Values past the record that the vector input step reads (it computes
# whole steps of SAMPLES samples); the engine pads the inputs with them.
TAIL = SAMPLES - 1
# lane_inputs writes whole steps of SAMPLES into a chunk's _CHUNK rows.
assert _CHUNK % SAMPLES == 0
assert SAMPLES % _AFFINE_SAMPLES == 0
# Without the JIT every block takes the plain four-lane path.
_WIDE = not numba.config.DISABLE_JIT


_VEC = ir.VectorType(ir.DoubleType(), _WIDTH)
_I64 = ir.IntType(64)
_I32 = ir.IntType(32)
_ZERO = ir.Constant(_VEC, [0.0] * _WIDTH)


def _c(value):
    return ir.Constant(_I64, value)


def _data(context, builder, ty, value):
    return context.make_array(ty)(context, builder, value).data


def _load(builder, ptr, index):
    return builder.load(builder.bitcast(builder.gep(ptr, [index]), _VEC.as_pointer()), align=8)


def _store(builder, value, ptr, index):
    builder.store(value, builder.bitcast(builder.gep(ptr, [index]), _VEC.as_pointer()), align=8)


def _splat(builder, scalar):
    one = builder.insert_element(ir.Constant(_VEC, None), scalar, ir.Constant(_I32, 0))
    return builder.shuffle_vector(one, ir.Constant(_VEC, None), _mask([0] * _WIDTH))


def _madd(builder, fused, acc, a, x):
    """``acc + a * x``: one rounding if ``fused`` (``llvm.fma``, exact in IEEE 754 on every
    machine), else two (``fmul``, then ``fadd``)."""
    if fused:
        fma = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(_VEC, [_VEC, _VEC, _VEC]), f"llvm.fma.v{_WIDTH}f64"
        )
        return builder.call(fma, [a, x, acc])
    return builder.fadd(acc, builder.fmul(a, x))


def _msub(builder, fused, x, a, y):
    """``x - a * y``, fused (``fma(-a, y, x)``: negation is exact) or not."""
    if fused:
        return _madd(builder, True, x, builder.fneg(a), y)
    return builder.fsub(x, builder.fmul(a, y))


def _both(builder, fused, emit):
    """``emit(True)`` if the run-time flag ``fused`` is set, else ``emit(False)``: two copies
    of a whole loop, chosen once."""
    with builder.if_else(fused) as (then, otherwise):
        with then:
            emit(True)
        with otherwise:
            emit(False)


def _mask(indices):
    return ir.Constant(ir.VectorType(_I32, len(indices)), indices)


def _transpose(builder, rows):
    """Square transpose: rows[w] holds lane w at samples q..; returns sample s at lanes 0...

    One stage per bit of the index: rows r and r | bit swap that bit of
    the lane and sample index (log2(_WIDTH) stages of _WIDTH shuffles).
    """
    rows = list(rows)
    bit = 1
    while bit < _WIDTH:
        for low in range(_WIDTH):
            if low & bit:
                continue
            high = low | bit
            keep = [c if c & bit == 0 else _WIDTH + (c ^ bit) for c in range(_WIDTH)]
            swap = [c ^ bit if c & bit == 0 else _WIDTH + c for c in range(_WIDTH)]
            rows[low], rows[high] = (
                builder.shuffle_vector(rows[low], rows[high], _mask(keep)),
                builder.shuffle_vector(rows[low], rows[high], _mask(swap)),
            )
        bit *= 2
    return rows


@intrinsic
def lane_inputs(typingctx, b1, nb1, off1, tv1, b2, nb2, off2, tv2, steps, xt, fused):
    """Input part ``B1 i1 + B2 i2`` of every lane for chunk samples ``q < steps`` into ``xt``.

    ``b1`` (LANES, >= nb1) holds lane l's B1 in row l; tap j of lane l at
    sample q reads ``i1p[off1[l] + q - j]``, likewise for input 2, from
    ``tv1 = tap_vectors(i1p)`` and ``tv2``: the eight values from ``i1p[t]`` on
    are one aligned vector there, where a load from ``i1p`` would span two
    cache lines for seven taps in eight. ``steps`` must be a multiple of
    ``SAMPLES`` (samples past the chunk are computed and ignored, so the
    inputs must hold ``SAMPLES - 1`` readable values past the record). Per
    sample the terms are added as in ``simulate_into``: 0, then b1[0],
    b1[1], ..., then b2[0], ..., each a multiply and an add, or one fused
    multiply-add if ``fused``.
    """
    if not isinstance(fused, types.Boolean):
        return None  # a typing error: the flag chooses between two compiled loops
    sig = types.void(b1, nb1, off1, tv1, b2, nb2, off2, tv2, steps, xt, fused)

    def codegen(context, builder, signature, args):
        ty = signature.args
        inputs = []
        for at in (0, 4):
            b_arr = context.make_array(ty[at])(context, builder, args[at])
            stride = cgutils.unpack_tuple(builder, b_arr.shape)[1]
            inputs.append(
                (
                    b_arr.data,
                    stride,
                    args[at + 1],
                    _data(context, builder, ty[at + 2], args[at + 2]),
                    _data(context, builder, ty[at + 3], args[at + 3]),
                )  # fmt: skip
            )
        out = _data(context, builder, ty[9], args[9])
        # acc[h][w]: lane w of the group at samples q + h * _WIDTH .. q + (h + 1) * _WIDTH - 1.
        acc = [[cgutils.alloca_once(builder, _VEC) for _ in range(_WIDTH)] for _ in range(_HALVES)]

        def emit(fused):
            with cgutils.for_range_slice(builder, _c(0), args[8], _c(SAMPLES)) as (q, _):
                for g in range(_GROUPS):
                    lanes = [g * _WIDTH + w for w in range(_WIDTH)]
                    for half in acc:
                        for a in half:
                            builder.store(_ZERO, a)
                    for b_ptr, stride, nb, off, ip in inputs:
                        starts = [
                            builder.add(builder.load(builder.gep(off, [_c(lane)])), q) for lane in lanes
                        ]
                        rows = [builder.mul(_c(lane), stride) for lane in lanes]
                        with cgutils.for_range(builder, nb) as loop:
                            j = loop.index
                            for w in range(_WIDTH):
                                coef = _splat(
                                    builder, builder.load(builder.gep(b_ptr, [builder.add(rows[w], j)]))
                                )
                                at = builder.sub(starts[w], j)
                                for h in range(_HALVES):
                                    t = builder.add(at, _c(h * _WIDTH))
                                    x = _load(builder, ip, builder.mul(t, _c(_WIDTH)))
                                    total = _madd(builder, fused, builder.load(acc[h][w]), coef, x)
                                    builder.store(total, acc[h][w])
                    for h in range(_HALVES):
                        by_sample = _transpose(builder, [builder.load(a) for a in acc[h]])
                        for s in range(_WIDTH):
                            row = builder.mul(builder.add(q, _c(h * _WIDTH + s)), _c(LANES))
                            _store(builder, by_sample[s], out, builder.add(row, _c(g * _WIDTH)))

        _both(builder, args[10], emit)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def lane_inputs_affine(typingctx, b1t, nb1, r1, base1, b2t, nb2, i2p, base2, k0, steps, xt, fused):
    """Input part of every lane for chunk samples ``q < steps`` into ``xt``: groups of *affine* lanes.

    Lane ``l = g * _WIDTH + w`` (group g, place w) has input 1 delayed by
    ``c1[g] + w`` and input 2 by ``c2[g]`` (consecutive nk1 at one nk2).
    With ``r1`` the reversed padded input 1, ``r1[m] = i1p[len - 1 - m]``,
    its tap j at sample t is ``r1[base1[g] - t + j + w]`` (``base1 = len -
    1 - pad + c1``): one vector load for the group's ``_WIDTH`` lanes, no
    transpose; input 2 is one value for all of them, ``i2p[base2[g] + t -
    j]`` (``base2 = pad - c2``). ``b1t[j * LANES + l]`` is tap j of lane
    l. ``steps`` must be a
    multiple of ``_AFFINE_SAMPLES``; the inputs need ``TAIL`` readable values
    past the record. Per sample the terms are added as in
    ``simulate_into``: 0, then b1[0], b1[1], ..., then b2[0], ... The taps
    run in blocks of up to ``_TAP_BLOCK``, whose coefficients stay in
    registers over the chunk; between blocks the partial sums wait in xt
    (the first block starts from 0). Fused multiply-adds if ``fused``, as
    in :func:`lane_inputs`.
    """
    if not isinstance(fused, types.Boolean):
        return None  # a typing error: the flag chooses between two compiled loops
    sig = types.void(b1t, nb1, r1, base1, b2t, nb2, i2p, base2, k0, steps, xt, fused)

    def codegen(context, builder, signature, args):
        ty = signature.args
        out = _data(context, builder, ty[10], args[10])
        k0_v, steps_v = args[8], args[9]
        nb1_v, nb2_v = args[1], args[5]
        # Without taps the input part is 0 (the first block below starts
        # from 0 itself, so xt needs no clearing otherwise).
        no_taps = builder.icmp_signed("==", builder.or_(nb1_v, nb2_v), _c(0))
        with builder.if_then(no_taps), cgutils.for_range(builder, builder.mul(steps_v, _c(LANES))) as loop:
            builder.store(ir.Constant(ir.DoubleType(), 0.0), builder.gep(out, [loop.index]))

        def emit(fused):
            for at, row in ((0, True), (4, False)):
                coefs = _data(context, builder, ty[at], args[at])
                source = _data(context, builder, ty[at + 2], args[at + 2])
                base_p = _data(context, builder, ty[at + 3], args[at + 3])
                nb = args[at + 1]
                # The group's first block: input 1's first, or input 2's if nb1 = 0.
                first_input = cgutils.true_bit if row else builder.icmp_signed("==", nb1_v, _c(0))
                for g in range(_GROUPS):
                    base = builder.load(builder.gep(base_p, [_c(g)]))
                    taps = SimpleNamespace(coefs=coefs, source=source, base=base, row=row, group=g, k0=k0_v,
                                           steps=steps_v, out=out, fused=fused)  # fmt: skip
                    full = builder.sdiv(nb, _c(_TAP_BLOCK))
                    with cgutils.for_range(builder, full) as loop:
                        fresh = builder.and_(first_input, builder.icmp_signed("==", loop.index, _c(0)))
                        _affine_block(
                            builder, taps, builder.mul(loop.index, _c(_TAP_BLOCK)), _TAP_BLOCK, fresh
                        )
                    rest = builder.srem(nb, _c(_TAP_BLOCK))
                    j0 = builder.mul(full, _c(_TAP_BLOCK))
                    fresh = builder.and_(first_input, builder.icmp_signed("==", full, _c(0)))
                    after = builder.append_basic_block("affine.after")
                    switch = builder.switch(rest, after)
                    for count in range(1, _TAP_BLOCK):
                        block = builder.append_basic_block(f"affine.rest{count}")
                        switch.add_case(ir.Constant(rest.type, count), block)
                        with builder.goto_block(block):
                            _affine_block(builder, taps, j0, count, fresh)
                            builder.branch(after)
                    builder.position_at_end(after)

        _both(builder, args[11], emit)
        return context.get_dummy_value()

    return sig, codegen


def _affine_block(builder, taps, j0, count, fresh):
    """Taps ``j0 .. j0 + count - 1`` of one input of one group added to xt, sample after sample
    (to 0 instead of xt's values if ``fresh``, the group's first block)."""
    lane0 = _c(taps.group * _WIDTH)
    coef = [_load(builder, taps.coefs, builder.add(builder.mul(builder.add(j0, _c(j)), _c(LANES)), lane0))
            for j in range(count)]  # fmt: skip
    with cgutils.for_range_slice(builder, _c(0), taps.steps, _c(_AFFINE_SAMPLES)) as (q0, _):
        t0 = builder.add(taps.k0, q0)
        slots = [
            builder.add(builder.mul(builder.add(q0, _c(s)), _c(LANES)), lane0) for s in range(_AFFINE_SAMPLES)
        ]
        acc = [builder.select(fresh, _ZERO, _load(builder, taps.out, slot)) for slot in slots]
        for j in range(count):
            tap = builder.add(j0, _c(j))
            for s in range(_AFFINE_SAMPLES):
                if taps.row:  # r1[base - (t0 + s) + tap + w], w = 0.._WIDTH - 1
                    at = builder.add(builder.sub(builder.sub(taps.base, t0), _c(s)), tap)
                    x = _load(builder, taps.source, at)
                else:  # i2p[base + t0 + s - tap], the same for every lane
                    at = builder.sub(builder.add(builder.add(taps.base, t0), _c(s)), tap)
                    x = _splat(builder, builder.load(builder.gep(taps.source, [at])))
                acc[s] = _madd(builder, taps.fused, acc[s], coef[j], x)
        for slot, value in zip(slots, acc, strict=True):
            _store(builder, value, taps.out, slot)


@intrinsic
def lane_recursion(typingctx, coef, na, xt, m, yh, row0, o, k0, val_start, val_stop, quad_end, eacc, fused):
    """Recursion of every lane for chunk samples ``q < m``, and their squared errors.

    Writes ``yh`` rows ``row0 .. row0 + m - 1`` from ``xt`` and the
    ``max(na, 2)`` rows before ``row0``; a sample ``k = k0 + q`` on the
    validation rows adds ``(y - o[k])^2`` to partial sum ``(k - val_start)
    % 4`` (0 from ``quad_end`` on) of ``eacc``. Returns False, doing
    nothing, if na is not in 1..MAX_NA. Each multiply-add (``a_i y``
    added to a partial sum or subtracted from the output, ``d^2`` added to
    a sum of squares) is one fused operation if ``fused``.
    """
    if not isinstance(fused, types.Boolean):
        return None  # a typing error: the flag chooses between two compiled loops
    sig = types.boolean(coef, na, xt, m, yh, row0, o, k0, val_start, val_stop, quad_end, eacc, fused)

    def codegen(context, builder, signature, args):
        ty = signature.args
        coef_p = _data(context, builder, ty[0], args[0])
        na_v, m_v, row0_v = args[1], args[3], args[5]
        xt_p = _data(context, builder, ty[2], args[2])
        yh_p = _data(context, builder, ty[4], args[4])
        o_p = _data(context, builder, ty[6], args[6])
        k0_v, start_v, stop_v, quad_v = args[7], args[8], args[9], args[10]
        e_p = _data(context, builder, ty[11], args[11])
        handled = cgutils.alloca_once_value(builder, cgutils.false_bit)
        y1 = [cgutils.alloca_once(builder, _VEC) for _ in range(_GROUPS)]
        y2 = [cgutils.alloca_once(builder, _VEC) for _ in range(_GROUPS)]

        def emit(fused):
            done = builder.append_basic_block("lanes.done")
            default = builder.append_basic_block("lanes.other_na")
            switch = builder.switch(na_v, default)
            with builder.goto_block(default):
                builder.branch(done)
            for order in range(1, MAX_NA + 1):
                block = builder.append_basic_block(f"lanes.na{order}")
                switch.add_case(ir.Constant(na_v.type, order), block)
                with builder.goto_block(block):
                    _recursion(builder, fused, order, coef_p, xt_p, m_v, yh_p, row0_v, o_p, k0_v, start_v,
                               stop_v, quad_v, e_p, y1, y2)  # fmt: skip
                    builder.store(cgutils.true_bit, handled)
                    builder.branch(done)
            builder.position_at_end(done)

        _both(builder, args[12], emit)
        return builder.load(handled)

    return sig, codegen


def _recursion(builder, fused, na, coef, xt, m, yh, row0, o, k0, val_start, val_stop, quad_end, eacc, y1, y2):
    """The sample loop for one na, fully unrolled over lags and groups."""
    lags = max(na, 2)
    a = [[_load(builder, coef, _c(i * LANES + g * _WIDTH)) for g in range(_GROUPS)] for i in range(lags + 1)]
    first = builder.mul(row0, _c(LANES))
    for g in range(_GROUPS):
        builder.store(_load(builder, yh, builder.add(first, _c(g * _WIDTH - LANES))), y1[g])
        builder.store(_load(builder, yh, builder.add(first, _c(g * _WIDTH - 2 * LANES))), y2[g])
    with cgutils.for_range(builder, m) as loop:
        q = loop.index
        base = builder.add(first, builder.mul(q, _c(LANES)))
        ys = []
        for g in range(_GROUPS):
            at = builder.add(base, _c(g * _WIDTH))
            # simulate_into: older lags first into two partial sums, then a2 y2, a1 y1.
            s0 = s1 = None
            i = na
            while i > 3:
                s0 = _accumulate(
                    builder, fused, s0, a[i][g], _load(builder, yh, builder.add(at, _c(-i * LANES)))
                )
                s1 = _accumulate(
                    builder, fused, s1, a[i - 1][g], _load(builder, yh, builder.add(at, _c(-(i - 1) * LANES)))
                )
                i -= 2
            if i == 3:
                s0 = _accumulate(
                    builder, fused, s0, a[3][g], _load(builder, yh, builder.add(at, _c(-3 * LANES)))
                )
            x = _load(builder, xt, builder.add(builder.mul(q, _c(LANES)), _c(g * _WIDTH)))
            total = builder.fadd(_ZERO if s0 is None else s0, _ZERO if s1 is None else s1)
            prev1, prev2 = builder.load(y1[g]), builder.load(y2[g])
            y = builder.fsub(x, total)
            y = _msub(builder, fused, _msub(builder, fused, y, a[2][g], prev2), a[1][g], prev1)
            _store(builder, y, yh, at)
            builder.store(prev1, y2[g])
            builder.store(y, y1[g])
            ys.append(y)
        k = builder.add(k0, q)
        inside = builder.and_(builder.icmp_signed(">=", k, val_start), builder.icmp_signed("<", k, val_stop))
        with builder.if_then(inside):
            part = builder.select(
                builder.icmp_signed("<", k, quad_end), builder.and_(builder.sub(k, val_start), _c(3)), _c(0)
            )
            target = _splat(builder, builder.load(builder.gep(o, [k])))
            row = builder.mul(part, _c(LANES))
            for g, y in enumerate(ys):
                at = builder.add(row, _c(g * _WIDTH))
                d = builder.fsub(y, target)
                _store(builder, _madd(builder, fused, _load(builder, eacc, at), d, d), eacc, at)


def _accumulate(builder, fused, partial, a, y):
    """``partial + a * y``, the partial sum starting from 0.0 as in simulate_into."""
    return _madd(builder, fused, _ZERO if partial is None else partial, a, y)


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


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
def _simulate_block(
    row, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, pad, o,
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
    bound = np.inf
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


@njit(cache=True)
def _simulate_affine_groups(
    first_row, stop_row, block_orders, block_start, bounds, theta_all, score, i1p, i2p, pad, o,
    val_start, val_stop, prune, fused, v_all, counts, best,
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
        batch_nb2 = 0
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
            val_stop, lane_bound, xt, yh, eacc, v, pruned, fused,
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


@njit(cache=True)
def _simulate_run(
    first_row, stop_row, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p,
    tv1, tv2, pad, o, val_start, val_stop, prune, fused, v_all, counts,
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
    inf until the block has one), which cannot change the frontier. A
    batch that spans two blocks pads B with zero coefficients to its longer
    nb2: ``x + 0.0 * i`` is ``x``, the same value bit for bit but for a zero's sign, which
    V's squares do not keep, so every V is what the block alone would give.
    ``counts`` as in :func:`_simulate_block`; the inputs as in
    :func:`simulate_blocks` (``i1p``, ``i2p`` for the affine groups, their
    tap vectors ``tv1``, ``tv2`` for the rest).
    """
    na, nb1 = block_orders[first_row, 0], block_orders[first_row, 1]
    best = np.full(stop_row - first_row, np.inf)
    _simulate_affine_groups(
        first_row, stop_row, block_orders, block_start, bounds, theta_all, score, i1p, i2p, pad, o,
        val_start, val_stop, prune, fused, v_all, counts, best,
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
        batch_nb2 = 0
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
            lane_bound, off1, off2, xt, yh, eacc, v, pruned, fused,
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
    """First block of each run :func:`_simulate_group` takes at once, then the number of
    blocks: consecutive blocks of one (na, nb1) on the vector path, any other block alone."""
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


@njit(cache=True)
def _simulate_group(
    g, firsts, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, tv1, tv2,
    pad, o, val_start, val_stop, prune, fused, v_all, counts,
):  # fmt: skip
    first_row, stop_row = firsts[g], firsts[g + 1]
    if _WIDE and block_orders[first_row, 0] <= MAX_NA:
        _simulate_run(
            first_row, stop_row, block_orders, block_start, block_size, bounds, theta_all, score,
            i1p, i2p, tv1, tv2, pad, o, val_start, val_stop, prune, fused, v_all, counts,
        )  # fmt: skip
    else:
        _simulate_block(
            first_row, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p,
            pad, o, val_start, val_stop, prune, v_all, counts,
        )  # fmt: skip


@njit(cache=True)
def simulate_blocks(
    block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, tv1, tv2, pad, o,
    val_start, val_stop, prune, fused, v_all, counts,
):  # fmt: skip
    """Serial driver of the simulations: every order triple, the runs of blocks of one
    (na, nb1) by :func:`_simulate_run`, or each block alone by :func:`_simulate_block`.

    Parameters
    ----------
    block_orders : int64 array, shape (n_blocks, 3)
        ``(na, nb1, nb2)`` of each candidate block.
    block_start, block_size : int64 arrays, shape (n_blocks,)
        Where each block starts in the candidate order, and its length.
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
    fused : bool
        Fused multiply-adds in the vector steps (module docstring); the
        plain path (without the JIT, above ``MAX_NA``) is always unfused.
    counts : int64 array, shape (n_blocks, 3), zeros
        Out per block: candidates simulated in full, candidates pruned, and
        candidate-samples simulated (lanes times samples).
    """
    firsts = _runs(block_orders)
    for g in range(firsts.shape[0] - 1):
        _simulate_group(
            g, firsts, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, tv1,
            tv2, pad, o, val_start, val_stop, prune, fused, v_all, counts,
        )  # fmt: skip


@njit(cache=True, parallel=True)
def simulate_blocks_parallel(
    block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p, tv1, tv2, pad, o,
    val_start, val_stop, prune, fused, v_all, counts, n_threads,
):  # fmt: skip
    """Parallel driver: thread t takes runs t, t + n_threads, ... of :func:`simulate_blocks`;
    each run alone decides its pruning, so the result is bit-identical to it."""
    firsts = _runs(block_orders)
    n_groups = firsts.shape[0] - 1
    for t in prange(n_threads):
        for g in range(t, n_groups, n_threads):
            _simulate_group(
                g, firsts, block_orders, block_start, block_size, bounds, theta_all, score, i1p, i2p,
                tv1, tv2, pad, o, val_start, val_stop, prune, fused, v_all, counts,
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
