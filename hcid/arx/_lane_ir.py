"""The lanes' vector steps as LLVM IR (numba intrinsics) and their layout constants (private).

Part of the lane kernels (:mod:`hcid.arx._lanes`, :mod:`hcid.arx._blocks`).

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
with the tap coefficients held in registers, and no transpose. Most
candidates of the direct grid (nk1 1..50) form such groups; stage 1
(nk1 1..5), the groups with many unstable candidates and the rest take the
general step (:func:`hcid.arx._blocks._simulate_run`).

Two arithmetics, chosen per call (``fused``): a literal flag (the block
walkers pass ``True``) compiles only its loop; a run-time one compiles both
and picks one per chunk (the tests call the kernels so). Unfused, every lane does the arithmetic of
:func:`hcid.arx._kernels.simulate_into` (the same IEEE-754 operations in
the same order: ``fmul`` and ``fadd`` / ``fsub`` without fast-math flags,
which LLVM may neither reassociate nor fuse), so a lane's V is
bit-identical to it; the tests compare them. Fused, each multiply-add
(an input tap, an output lag, a squared error) is one ``llvm.fma``,
rounded once: the same order, fewer operations and roundings. ``llvm.fma``
is exact by definition, so the values are the same on every machine (one without FMA units computes it in
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

The kernels are spread over several files (:mod:`hcid.arx._cache` gives their
cached copies one stamp, so a change to any of them recompiles all).

Layouts of the vector steps (``LANES`` lanes, flat float64 arrays):
``xt[q * LANES + l]`` the input part of lane l at chunk sample q;
``yh[row * LANES + l]`` the simulated output; ``coef[i * LANES + l]`` the
coefficient a_i of lane l (``a_2 = 0`` when na = 1); ``eacc[p * LANES + l]``
the four partial sums of squared errors of lane l.
"""

from types import SimpleNamespace

import numba
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from hcid.arx import _cache  # noqa: F401 (first: the kernels' cache locator, hcid.arx._cache)

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


def _both(builder, fused, emit, fused_type):
    """``emit(True)`` if the flag ``fused`` is set, else ``emit(False)``: for a run-time flag two
    copies of a whole loop, chosen once; for a literal one (``fused_type`` a
    ``types.BooleanLiteral``: the lane kernels' own path) only the copy it names, so that
    numba compiles half the code."""
    if isinstance(fused_type, types.BooleanLiteral):
        emit(bool(fused_type.literal_value))
        return
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

        _both(builder, args[10], emit, ty[10])
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

        _both(builder, args[11], emit, ty[11])
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

        _both(builder, args[12], emit, ty[12])
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


# --------------------------------------------------------------------------- prefetch (the fits' rows)


def _prefetch_check(arr, index):
    """_prefetch_write without the JIT (an intrinsic runs compiled only): no hint, but the
    index is checked, so that the callers' index arithmetic is tested as plain Python."""
    if not 0 <= index < arr.size:
        raise IndexError(f"prefetch: flat index {index} outside an array of {arr.size}")


@intrinsic
def _prefetch_hint(typingctx, arr, index):
    """Hint that element ``index`` (flat, of a C-contiguous array) is about to be written.

    A hint only (``llvm.prefetch``, which never faults): no value changes.
    """
    sig = types.void(arr, index)

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0")
        address = builder.bitcast(builder.gep(data, [args[1]]), i8p)
        # rw = 1 (write), locality = 3 (keep in every cache level), data cache.
        builder.call(fn, [address, ir.Constant(i32, 1), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return sig, codegen


_prefetch_write = _prefetch_check if numba.config.DISABLE_JIT else _prefetch_hint


@njit(cache=True)
def _prefetch_rows(offset, c1, c2, within, v_out, theta_out, score_out):
    """Prefetch the output rows of group (c1, c2) of the unit (every na).

    A unit's rows lie one per order triple, far apart: without the hint
    each store waits for its cache line (the direct grid's fits: 1.2x with it).
    """
    width = theta_out.shape[1]
    for c in range(offset.shape[0]):
        row = offset[c, c1, c2] + within
        _prefetch_write(v_out, row)
        _prefetch_write(score_out, row)
        for j in range(0, width, 8):
            _prefetch_write(theta_out, row * width + j)
        _prefetch_write(theta_out, row * width + width - 1)
