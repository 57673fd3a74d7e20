"""Explicit-vector steps of the lane simulation (private; see :mod:`hcid.arx._kernels`).

numba vectorises loops over samples, but the ARX recursion is a chain
through the samples: only independent candidates (lanes) can share a
vector, and numba leaves LLVM's SLP vectoriser, which would pack them, off.
These two intrinsics therefore emit LLVM IR on ``<4 x double>`` vectors
directly, one vector per four lanes, ``_GROUPS`` vectors side by side so
that their multiply-add chains overlap.

Every lane does the arithmetic of :func:`hcid.arx._kernels.simulate_into`
(the same IEEE-754 operations in the same order: ``fmul`` and ``fadd`` /
``fsub`` without fast-math flags, which LLVM may neither reassociate nor
fuse), so a lane's output and V are bit-identical to it; the tests compare
them, and :func:`hcid.arx._kernels.simulate_lanes` is the plain twin used
when numba's JIT is off.

Layouts (``LANES`` lanes, flat float64 arrays): ``xt[q * LANES + l]`` the
input part of lane l at chunk sample q; ``yh[row * LANES + l]`` the
simulated output; ``coef[i * LANES + l]`` the coefficient a_i of lane l
(``a_2 = 0`` when na = 1); ``eacc[p * LANES + l]`` the four partial sums of
squared errors of lane l.
"""

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

# Doubles per vector (AVX2) and vectors per step.
_WIDTH = 4
_GROUPS = 4
LANES = _WIDTH * _GROUPS
# Samples of one step of lane_inputs: two vectors per lane, so that every
# broadcast coefficient serves two multiplies.
_HALVES = 2
SAMPLES = _HALVES * _WIDTH
# Largest na with a vector recursion (each na is its own unrolled loop).
MAX_NA = 12

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
    return builder.shuffle_vector(one, ir.Constant(_VEC, None), ir.Constant(ir.VectorType(_I32, 4), [0] * 4))


def _transpose(builder, rows):
    """4 x 4 transpose: rows[w] holds lane w at samples q..q+3; returns sample s at lanes 0..3."""
    mask = lambda *m: ir.Constant(ir.VectorType(_I32, 4), list(m))  # noqa: E731
    lo01 = builder.shuffle_vector(rows[0], rows[1], mask(0, 4, 2, 6))
    hi01 = builder.shuffle_vector(rows[0], rows[1], mask(1, 5, 3, 7))
    lo23 = builder.shuffle_vector(rows[2], rows[3], mask(0, 4, 2, 6))
    hi23 = builder.shuffle_vector(rows[2], rows[3], mask(1, 5, 3, 7))
    return [
        builder.shuffle_vector(lo01, lo23, mask(0, 1, 4, 5)),
        builder.shuffle_vector(hi01, hi23, mask(0, 1, 4, 5)),
        builder.shuffle_vector(lo01, lo23, mask(2, 3, 6, 7)),
        builder.shuffle_vector(hi01, hi23, mask(2, 3, 6, 7)),
    ]


@intrinsic
def lane_inputs(typingctx, b1, nb1, off1, i1p, b2, nb2, off2, i2p, m8, xt):
    """Input part ``B1 i1 + B2 i2`` of every lane for chunk samples ``q < m8`` into ``xt``.

    ``b1`` (LANES, >= nb1) holds lane l's B1 in row l; tap j of lane l at
    sample q reads ``i1p[off1[l] + q - j]``, likewise for input 2. ``m8``
    must be a multiple of ``SAMPLES`` (samples past the chunk are computed
    and ignored, so the inputs must hold ``SAMPLES - 1`` readable values
    past the record). Per sample the terms are added as in
    ``simulate_into``: 0, then b1[0], b1[1], ..., then b2[0], ...
    """
    sig = types.void(b1, nb1, off1, i1p, b2, nb2, off2, i2p, m8, xt)

    def codegen(context, builder, signature, args):
        ty = signature.args
        inputs = []
        for at in (0, 4):
            b_arr = context.make_array(ty[at])(context, builder, args[at])
            stride = cgutils.unpack_tuple(builder, b_arr.shape)[1]
            inputs.append(
                (b_arr.data, stride, args[at + 1], _data(context, builder, ty[at + 2], args[at + 2]),
                 _data(context, builder, ty[at + 3], args[at + 3]))  # fmt: skip
            )
        out = _data(context, builder, ty[9], args[9])
        # acc[h][w]: lane w of the group at samples q + 4h .. q + 4h + 3.
        acc = [[cgutils.alloca_once(builder, _VEC) for _ in range(_WIDTH)] for _ in range(_HALVES)]
        with cgutils.for_range_slice(builder, _c(0), args[8], _c(SAMPLES)) as (q, _):
            for g in range(_GROUPS):
                lanes = [g * _WIDTH + w for w in range(_WIDTH)]
                for half in acc:
                    for a in half:
                        builder.store(_ZERO, a)
                for b_ptr, stride, nb, off, ip in inputs:
                    starts = [builder.add(builder.load(builder.gep(off, [_c(lane)])), q) for lane in lanes]
                    rows = [builder.mul(_c(lane), stride) for lane in lanes]
                    with cgutils.for_range(builder, nb) as loop:
                        j = loop.index
                        for w in range(_WIDTH):
                            coef = _splat(builder, builder.load(builder.gep(b_ptr, [builder.add(rows[w], j)])))
                            at = builder.sub(starts[w], j)
                            for h in range(_HALVES):
                                x = _load(builder, ip, builder.add(at, _c(h * _WIDTH)))
                                total = builder.fadd(builder.load(acc[h][w]), builder.fmul(coef, x))
                                builder.store(total, acc[h][w])
                for h in range(_HALVES):
                    by_sample = _transpose(builder, [builder.load(a) for a in acc[h]])
                    for s in range(_WIDTH):
                        row = builder.mul(builder.add(q, _c(h * _WIDTH + s)), _c(LANES))
                        _store(builder, by_sample[s], out, builder.add(row, _c(g * _WIDTH)))
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def lane_recursion(typingctx, coef, na, xt, m, yh, row0, o, k0, val_start, val_stop, quad_end, eacc):
    """Recursion of every lane for chunk samples ``q < m``, and their squared errors.

    Writes ``yh`` rows ``row0 .. row0 + m - 1`` from ``xt`` and the
    ``max(na, 2)`` rows before ``row0``; a sample ``k = k0 + q`` on the
    validation rows adds ``(y - o[k])^2`` to partial sum ``(k - val_start)
    % 4`` (0 from ``quad_end`` on) of ``eacc``. Returns False, doing
    nothing, if na is not in 1..MAX_NA.
    """
    sig = types.boolean(coef, na, xt, m, yh, row0, o, k0, val_start, val_stop, quad_end, eacc)

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
        done = builder.append_basic_block("lanes.done")
        default = builder.append_basic_block("lanes.other_na")
        switch = builder.switch(na_v, default)
        with builder.goto_block(default):
            builder.branch(done)
        for order in range(1, MAX_NA + 1):
            block = builder.append_basic_block(f"lanes.na{order}")
            switch.add_case(ir.Constant(na_v.type, order), block)
            with builder.goto_block(block):
                _recursion(builder, order, coef_p, xt_p, m_v, yh_p, row0_v, o_p, k0_v, start_v, stop_v,
                           quad_v, e_p, y1, y2)  # fmt: skip
                builder.store(cgutils.true_bit, handled)
                builder.branch(done)
        builder.position_at_end(done)
        return builder.load(handled)

    return sig, codegen


def _recursion(builder, na, coef, xt, m, yh, row0, o, k0, val_start, val_stop, quad_end, eacc, y1, y2):
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
                s0 = _accumulate(builder, s0, a[i][g], _load(builder, yh, builder.add(at, _c(-i * LANES))))
                s1 = _accumulate(builder, s1, a[i - 1][g], _load(builder, yh, builder.add(at, _c(-(i - 1) * LANES))))
                i -= 2
            if i == 3:
                s0 = _accumulate(builder, s0, a[3][g], _load(builder, yh, builder.add(at, _c(-3 * LANES))))
            x = _load(builder, xt, builder.add(builder.mul(q, _c(LANES)), _c(g * _WIDTH)))
            total = builder.fadd(_ZERO if s0 is None else s0, _ZERO if s1 is None else s1)
            prev1, prev2 = builder.load(y1[g]), builder.load(y2[g])
            y = builder.fsub(builder.fsub(builder.fsub(x, total), builder.fmul(a[2][g], prev2)),
                             builder.fmul(a[1][g], prev1))  # fmt: skip
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
                _store(builder, builder.fadd(_load(builder, eacc, at), builder.fmul(d, d)), eacc, at)


def _accumulate(builder, partial, a, y):
    """``partial + a * y``, the partial sum starting from 0.0 as in simulate_into."""
    return builder.fadd(_ZERO if partial is None else partial, builder.fmul(a, y))
