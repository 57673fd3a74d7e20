"""Checked inputs of the engine and the simulation of one ARX model from rest (SPEC 3).

:func:`simulate` runs the kernel :func:`hcid.arx.engine.fit_grid` uses, so a
frontier row's output is the one its V was computed from, bit for bit.
"""

from __future__ import annotations

import operator

import numpy as np

from hcid.arx import _kernels, _lanes
from hcid.errors import DataError, IdentificationError

__all__ = ["checked_rows", "checked_signal", "padded", "simulate"]


def checked_signal(name: str, value, n: int | None = None) -> np.ndarray:
    """``value`` as a finite 1-D float64 array (of length ``n`` if given); DataError naming ``name``."""
    x = np.ascontiguousarray(value, dtype=np.float64)
    if x.ndim != 1:
        raise DataError(f"{name}: must be a 1-D array, got shape {x.shape}")
    if n is not None and x.size != n:
        raise DataError(f"{name}: must have the length of i1 ({n}), got {x.size}")
    if not np.all(np.isfinite(x)):
        raise DataError(f"{name}: must be finite, got {np.count_nonzero(~np.isfinite(x))} NaN/inf")
    return x


def checked_rows(name: str, rows: slice, n: int) -> tuple[int, int]:
    """``(start, stop)`` of a window ``start:stop`` of ``n`` samples; IdentificationError naming ``name``."""
    message = f"{name}: must be a slice start:stop with 0 <= start < stop <= {n}, got {rows!r}"
    if not isinstance(rows, slice) or rows.step not in (None, 1):
        raise IdentificationError(message)
    try:
        start = 0 if rows.start is None else operator.index(rows.start)
        stop = n if rows.stop is None else operator.index(rows.stop)
    except TypeError as exc:
        raise IdentificationError(message) from exc
    if not 0 <= start < stop <= n:
        raise IdentificationError(message)
    return start, stop


def padded(x: np.ndarray, pad: int) -> np.ndarray:
    """``x`` with ``pad`` zeros before (the record starts from rest) and ``TAIL`` after."""
    # TAIL zeros after the record: the vector input step reads whole steps of SAMPLES.
    return np.concatenate((np.zeros(pad), x, np.zeros(_lanes.TAIL)))


def simulate(a, b1, b2, nk1: int, nk2: int, i1, i2) -> np.ndarray:
    """Simulate an ARX model over a whole record from zero initial conditions.

    ``o_hat = (B1/A) i1(k - nk1) + (B2/A) i2(k - nk2)``, inputs before the
    record 0. Runs the kernel :func:`fit_grid` uses, so a frontier row's
    output is the one its V was computed from, bit for bit.

    Parameters
    ----------
    a : array_like of float, shape (na + 1,)
        ``[1, a1, ..., a_na]``; the leading coefficient must be exactly 1.
    b1, b2 : array_like of float, shape (nb1,), (nb2,)
        B coefficients; empty drops the input.
    nk1, nk2 : int
        Input delays in samples, >= 0 (ignored for a dropped input).
    i1, i2 : array_like of float, shape (n,)
        Inputs.

    Returns
    -------
    numpy.ndarray of float64, shape (n,)
        The simulated output. If it stops being finite (an unstable model),
        the samples after the first 256-sample block holding a non-finite
        value are NaN.

    Raises
    ------
    hcid.errors.IdentificationError
        If ``a`` is empty or ``a[0] != 1``, or a delay is negative.
    hcid.errors.DataError
        If a signal is not 1-D and finite, or the inputs differ in length.

    Examples
    --------
    >>> import numpy as np
    >>> from hcid.arx import simulate
    >>> simulate([1.0, -0.5], [1.0], [], 1, 0, np.ones(4), np.zeros(4))
    array([0.  , 1.  , 1.5 , 1.75])
    """
    a = checked_signal("a", a)
    b1 = checked_signal("b1", b1)
    b2 = checked_signal("b2", b2)
    if a.size == 0 or a[0] != 1.0:
        raise IdentificationError(f"a: must start with the coefficient 1, got {a[:1]}")
    nk1, nk2 = operator.index(nk1), operator.index(nk2)
    if nk1 < 0 or nk2 < 0:
        raise IdentificationError(f"nk1, nk2: must be >= 0, got {nk1}, {nk2}")
    i1 = checked_signal("i1", i1)
    i2 = checked_signal("i2", i2, i1.size)
    return _simulate(a, b1, b2, nk1, nk2, i1, i2)


def _simulate(a, b1, b2, nk1: int, nk2: int, i1: np.ndarray, i2: np.ndarray) -> np.ndarray:
    n = i1.size
    na = a.size - 1
    pad = max(nk1 + b1.size, nk2 + b2.size, 1)
    x = np.empty(n)
    ypad = max(na, 1)
    yp = np.zeros(ypad + n)
    a_k = np.concatenate((a, [0.0])) if na == 0 else a
    with np.errstate(over="ignore", invalid="ignore"):
        done = _kernels.simulate_into(
            a_k, na, _nonempty(b1), b1.size, nk1, _nonempty(b2), b2.size, nk2,
            padded(i1, pad), padded(i2, pad), pad, x, yp, ypad,
        )  # fmt: skip
    o_hat = yp[ypad:].copy()
    o_hat[done:] = np.nan
    return o_hat


def _nonempty(b: np.ndarray) -> np.ndarray:
    # numba wants a typed, non-empty buffer even for a dropped input.
    return b if b.size else np.zeros(1)
