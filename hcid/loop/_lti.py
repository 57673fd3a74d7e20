"""The loop's transfer-function arithmetic without importing python-control or scipy.signal.

A simulating command needs a handful of continuous transfer functions (products, one
pole-zero cancellation) and their Tustin and ZOH discretisations. python-control does this
through scipy.signal, whose imports (with scipy.stats and matplotlib, which python-control
pulls in) cost about 1 s of every command's serial start. This module repeats the operations
those libraries do for SISO transfer functions, numpy call for numpy call, so the coefficients
are the same bits (``tests/test_hcmodel.py`` compares them with python-control's over every
config's models and random ones):

- :func:`product`: ``control.TransferFunction.__mul__`` (and ``__rmul__`` for a gain),
- :func:`minreal`: ``control.TransferFunction.minreal`` (control 0.10.2, after octave),
- :func:`sample`: ``control.sample_system``, that is ``scipy.signal.cont2discrete`` on
  ``tf2ss`` and back by ``ss2tf`` (scipy 1.17; BSD-3-Clause).

A transfer function is a pair ``(num, den)`` of float arrays, highest power first, without
leading zeros (as python-control keeps them).
"""

from __future__ import annotations

import sys
import warnings

import numpy as np
from scipy import linalg

Polynomials = tuple[np.ndarray, np.ndarray]


def _truncated(p: np.ndarray) -> np.ndarray:
    """python-control's ``_truncatecoeff``: leading exact zeros removed (all zeros -> [0.])."""
    nonzero = np.flatnonzero(p)
    return np.zeros(1) if nonzero.size == 0 else p[nonzero[0] :]


def _made(num: np.ndarray, den: np.ndarray) -> Polynomials:
    """What python-control's constructor keeps: a zero numerator over 1, leading zeros dropped."""
    if not np.any(num):
        den = np.ones(1)
    return _truncated(num), _truncated(den)


def tf(num, den) -> Polynomials:
    """``control.tf(num, den)`` for a SISO list of coefficients."""
    return _made(np.array([float(c) for c in num]), np.array([float(c) for c in den]))


def product(left: Polynomials, right: Polynomials) -> Polynomials:
    """``left * right`` as python-control forms it: ``0/1 + (nl nr)/(dl dr)``, truncated."""
    num_product = np.polymul(left[0], right[0])
    den_product = np.polymul(left[1], right[1])
    zero, one = np.array([0]), np.array([1])
    num = np.polyadd(np.polymul(zero, den_product), np.polymul(num_product, one))
    den = np.polymul(one, den_product)
    return _made(num, den)


def gain(k: float, right: Polynomials) -> Polynomials:
    """``k * right`` (python-control's ``__rmul__``: the gain as ``[[k]]/[[1.]]`` on the left)."""
    return product((np.array([(np.eye(1) * k)[0, 0]]), np.array([1.0])), right)


def minreal(p: Polynomials) -> Polynomials:
    """``control.minreal(p, verbose=False)``: zeros within 1000 max(eps, |z| sqrt(eps)) of a
    pole cancelled against it."""
    eps = sys.float_info.epsilon
    sqrt_eps = np.sqrt(eps)
    zeros = np.roots(p[0])
    poles = np.roots(p[1])
    k = p[0][0] / p[1][0]
    kept = []
    for z in zeros:
        t = 1000 * max(eps, abs(z) * sqrt_eps)
        idx = np.where(abs(z - poles) < t)[0]
        if len(idx):
            poles = np.delete(poles, idx[0])
        else:
            kept.append(z)
    num = np.atleast_1d(k * np.real(np.poly(kept)))
    den = np.atleast_1d(np.real(np.poly(poles)))
    return _made(num.astype(np.float64), den.astype(np.float64))


def poles(p: Polynomials) -> np.ndarray:
    """python-control's ``TransferFunction.poles`` for SISO (through ``_common_den``): the roots
    of the normalised denominator, those within 2 sqrt(eps) of the real axis made real, multiplied
    out again and their roots taken. (A plant's zeros on the imaginary axis give feedforward poles
    whose real part is rounding: the same rounding as python-control's, the same verdict.)"""
    num, den = p
    eps = np.finfo(float).eps
    if np.abs(num).max() <= eps:
        found = np.roots(den)
    else:
        _, a = _normalize(num, den)
        found = np.roots((a + 0.0) / a[0])
    snapped = [c.real if abs(c.imag) < 2 * np.sqrt(eps) else c for c in found]
    if not snapped:
        return np.array([], dtype=complex)
    return np.roots(np.poly(snapped).real).astype(complex)


def sample(p: Polynomials, dt: float, method: str) -> Polynomials:
    """``control.sample_system(tf(p), dt, method)``: ``(numd, dend)`` as python-control keeps them."""
    a, b, c, d = _tf2ss(*p)
    if method == "bilinear":
        a, b, c, d = _gbt(a, b, c, d, dt, 0.5)
    elif method == "zoh":
        a, b, c, d = _zoh(a, b, c, d, dt)
    else:
        raise ValueError(f"sample: method {method!r} is not one the loop uses (bilinear, zoh)")
    num, den = _ss2tf(a, b, c, d)
    return _made(np.asarray(num[0, :], dtype=np.float64), np.asarray(den, dtype=np.float64))


def _normalize(b: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.normalize`` for one numerator."""
    den = np.atleast_1d(np.asarray(a))
    num = np.atleast_2d(np.asarray(b))
    first = 0
    for value in den:
        if value != 0.0:
            break
        first += 1
    den = den[first:]
    num, den = num / den[0], den / den[0]
    leading = 0
    for j in range(num.shape[-1]):
        if np.all(np.abs(num[:, j]) <= 1e-14):
            leading += 1
        else:
            break
    if leading > 0:
        warnings.warn(
            "Badly conditioned filter coefficients (numerator): the results may be meaningless", stacklevel=3
        )
        if leading == num.shape[1]:
            leading -= 1
        num = num[:, leading:]
    return num[0, :], den


def _tf2ss(num: np.ndarray, den: np.ndarray):
    """``scipy.signal.tf2ss`` for a proper SISO transfer function of order >= 1."""
    num, den = _normalize(num, den)
    num = np.asarray([num], num.dtype)
    m, k = num.shape[1], len(den)
    if m > k:
        raise ValueError("Improper transfer function. `num` is longer than `den`.")
    num = np.hstack((np.zeros((num.shape[0], k - m), dtype=num.dtype), num))
    d = np.atleast_2d(num[:, 0])
    if k == 1:
        return np.zeros((1, 1)), np.zeros((1, d.shape[1])), np.zeros((d.shape[0], 1)), d.reshape(num.shape)
    a = np.r_[-np.array([den[1:]]), np.eye(k - 2, k - 1)]
    b = np.eye(k - 1, 1)
    c = num[:, 1:] - np.outer(num[:, 0], den[1:])
    return a, b, c, d.reshape((c.shape[0], b.shape[1]))


def _gbt(a, b, c, d, dt: float, alpha: float):
    """``scipy.signal.cont2discrete(..., method="gbt", alpha=alpha)`` of a state-space system."""
    ima = np.eye(a.shape[0]) - alpha * dt * a
    ad = linalg.solve(ima, np.eye(a.shape[0]) + (1.0 - alpha) * dt * a)
    bd = linalg.solve(ima, dt * b)
    cd = linalg.solve(ima.transpose(), c.transpose()).transpose()
    dd = d + alpha * np.dot(c, bd)
    return ad, bd, cd, dd


def _zoh(a, b, c, d, dt: float):
    """``scipy.signal.cont2discrete(..., method="zoh")`` of a state-space system."""
    upper = np.hstack((a, b))
    lower = np.hstack((np.zeros((b.shape[1], a.shape[0])), np.zeros((b.shape[1], b.shape[1]))))
    ms = linalg.expm(dt * np.vstack((upper, lower)))[: a.shape[0], :]
    return ms[:, 0 : a.shape[1]], ms[:, a.shape[1] :], c, d


def _ss2tf(a, b, c, d):
    """``scipy.signal.ss2tf`` for input 0 of a system with at least one state."""
    b, d = b[:, 0:1], d[:, 0:1]
    den = np.poly(a)
    n = a.shape[0]
    type_test = a[:, 0] + b[:, 0] + c[0, :] + d + 0.0
    num = np.empty((d.shape[0], n + 1), type_test.dtype)
    for k in range(d.shape[0]):
        num[k] = np.poly(a - np.dot(b, np.atleast_2d(c[k, :]))) + (d[k] - 1) * den
    return num, den
