"""Frequency response of an identified ARX path (SPEC section 5)."""

from __future__ import annotations

import numpy as np

__all__ = ["path_response"]


def path_response(a, b, nk: int, w: np.ndarray, dt: float, advance: float = 0.0) -> np.ndarray:
    """``exp(jw advance) z^-nk B(z)/A(z)`` at ``z = exp(jw dt)``; zeros for an empty B.

    Parameters
    ----------
    a : array_like
        ``[1, a1, ..., a_na]``.
    b : array_like
        ``[b_0, ..., b_{nb-1}]``; empty for a dropped input.
    nk : int
        Delay in samples.
    w : ndarray
        Frequencies (rad/s).
    dt : float
        Sample time (s).
    advance : float
        Time (s) the input was shifted forward before the fit; the factor
        ``exp(jw advance)`` undoes it (SPEC 5: 1 s for ft).

    Examples
    --------
    >>> path_response([1.0, -0.5], [0.5], 1, np.array([0.0]), 0.04)  # DC gain 0.5 / (1 - 0.5)
    array([1.+0.j])
    """
    w = np.asarray(w, dtype=np.float64)
    if len(b) == 0:
        return np.zeros(w.size, dtype=complex)
    zinv = np.exp(-1j * w * dt)
    num = np.polyval(np.asarray(b)[::-1], zinv)
    den = np.polyval(np.asarray(a)[::-1], zinv)
    return np.exp(1j * w * advance) * zinv**nk * num / den
