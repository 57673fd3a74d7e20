"""The closed-loop target: the parametric HC model and the plant in closed loop, driven by ft and fd.

With the disturbance at the plant's output (``theta = Yc u + fd``) or input
(``theta = Yc (u + fd)``), ``e = ft - theta`` and ``u = Hft ft + He e``, the loop's
output is

    u = ((Hft + He) G Ft - He D Fd) / (G + He)        G = 1/Yc,  D = G (output) or 1 (input)

written with ``G = 1/Yc`` so that an integrator plant (``G(0) = 0``) has no
infinite term. ft and fd are the forcing functions the remnant cannot reach,
so the output error ``u - u_cl`` is the remnant's closed-loop response,
uncorrelated with the inputs: no bias from the remnant in e, which the open-loop
``time`` target takes as an input.

The loop is solved in its periodic steady state, one DFT bin at a time: the
record is taken as one period of its forcing functions, as the paper's 81.92 s
window is (SPEC 2). Delays are then exact (``exp(-j w tau)``, no interpolation)
and nothing is discretised. Where the record is not a whole number of periods,
the first seconds carry a transient (the record's end wrapped onto its start,
as a simulation from rest would carry one); the estimation rows should then
start a few seconds in, as the paper's do (5.12 s).

The DFT solution of an unstable loop is a periodic signal no loop could
produce, so stability is checked first: the characteristic polynomial of
``1 + He Yc`` with the delay as a Pade approximant (:data:`PADE_ORDER`) must have
every root in the open left half-plane, else the cost is infinite.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from hcid.errors import IdentificationError
from hcid.hcfit.model import TrackingRecord, _names, _plant_polynomials

__all__ = ["PADE_ORDER", "closed_loop_u", "loop_is_stable", "loop_spectrum", "loops_are_stable"]

#: Order of the Pade approximant of ``exp(-s tau_pe)`` in the stability check: its phase
#: error is below 1 deg up to ``w tau = 9`` (37 rad/s at tau = 0.24 s), far above a
#: human's crossover.
PADE_ORDER = 8


@functools.cache
def _pade_coefficients(order: int = PADE_ORDER) -> np.ndarray:
    """The diagonal Pade approximant's coefficients c_k (ascending powers of s tau), closed form
    (computed once per order: every residual of a fit checks its loop; read-only)."""
    c = np.array(
        [
            math.factorial(2 * order - k)
            * math.factorial(order)
            / (math.factorial(2 * order) * math.factorial(k) * math.factorial(order - k))
            for k in range(order + 1)
        ]
    )
    c.setflags(write=False)
    return c


def _pade(tau: float, order: int = PADE_ORDER) -> tuple[np.ndarray, np.ndarray]:
    """``(p, q)`` descending, ``exp(-s tau) ~ p(s)/q(s)`` (diagonal Pade, closed form)."""
    c = _pade_coefficients(order)
    powers = tau ** np.arange(order + 1)
    q = (c * powers)[::-1]
    p = (c * powers * (-1.0) ** np.arange(order + 1))[::-1]
    return p, q


def loop_is_stable(values: dict, num_c: np.ndarray, den_c: np.ndarray) -> bool:
    """Whether ``1 + He Yc`` has every root in the open left half-plane (delay by Pade).

    ``values`` holds Kpe, TL, tau_pe, w_nms, zeta_nms; ``num_c``, ``den_c`` are
    the plant's polynomials (descending).

    Examples
    --------
    >>> num, den = np.array([5.5]), np.array([1.0, 2.0, 0.0])      # the paper's 2.75*2/(s(s+2))
    >>> p = {"Kpe": 0.75, "TL": 0.4, "tau_pe": 0.24, "w_nms": 10.1, "zeta_nms": 0.35}
    >>> loop_is_stable(p, num, den), loop_is_stable({**p, "Kpe": 20.0}, num, den)
    (True, False)
    """
    w, z = values["w_nms"], values["zeta_nms"]
    if not (w > 0 and z > 0) or not all(math.isfinite(float(v)) for v in values.values()):
        return False
    p, q = _pade(values["tau_pe"])
    nms_den = np.array([1.0, 2.0 * z * w, w * w])
    lead = w * w * values["Kpe"] * np.array([values["TL"], 1.0])
    closed = np.polyadd(np.convolve(np.convolve(nms_den, den_c), q), np.convolve(np.convolve(lead, num_c), p))
    closed = np.trim_zeros(closed, "f")
    if closed.size <= 1:
        return closed.size == 1
    roots = np.roots(closed)
    return bool(np.all(np.isfinite(roots)) and np.all(roots.real < 0))


#: Below this delay (s) the Pade polynomial's leading coefficients (tau^8) are too small for a
#: companion matrix: such sets are checked one by one (:func:`loop_is_stable`).
_BATCH_MIN_TAU = 1e-3


def loops_are_stable(theta: np.ndarray, names, num_c: np.ndarray, den_c: np.ndarray) -> np.ndarray:
    """:func:`loop_is_stable` for every column of ``theta`` (n_p, n_sets) at once (bool, n_sets).

    The characteristic polynomials of the sets share their degree; their roots are the
    eigenvalues of a stack of companion matrices, computed in one call. Sets with a delay
    below :data:`_BATCH_MIN_TAU` or a non-positive NMS pair go through :func:`loop_is_stable`.
    """
    p = dict(zip(names, theta, strict=True))
    w, z, tau = p["w_nms"], p["zeta_nms"], p["tau_pe"]
    batch = (tau >= _BATCH_MIN_TAU) & (w > 0) & (z > 0) & np.isfinite(theta).all(axis=0)
    out = np.zeros(theta.shape[1], dtype=bool)
    for j in np.flatnonzero(~batch):
        column = {name: float(v) for name, v in zip(names, theta[:, j], strict=True)}
        out[j] = loop_is_stable(column, num_c, den_c)
    if not batch.any():
        return out
    w, z, tau = w[batch], z[batch], tau[batch]
    k = np.arange(PADE_ORDER + 1)
    c = _pade_coefficients()
    powers = c * tau[:, None] ** k  # (n, order + 1), ascending powers of s
    q = powers[:, ::-1]
    pp = (powers * (-1.0) ** k)[:, ::-1]
    nms_den = np.stack([np.ones_like(w), 2.0 * z * w, w * w], axis=1)
    lead = (w * w * p["Kpe"][batch])[:, None] * np.stack([p["TL"][batch], np.ones_like(w)], axis=1)

    def conv(a, b):  # row-wise polynomial products
        out = np.zeros((a.shape[0], a.shape[1] + b.shape[1] - 1))
        for i in range(a.shape[1]):
            out[:, i : i + b.shape[1]] += a[:, i : i + 1] * b
        return out

    left = conv(conv(nms_den, den_c[None, :]), q)  # each row times the plant's polynomials
    right = conv(conv(lead, num_c[None, :]), pp)
    closed = np.zeros((w.size, max(left.shape[1], right.shape[1])))
    closed[:, closed.shape[1] - left.shape[1] :] += left
    closed[:, closed.shape[1] - right.shape[1] :] += right
    degree = closed.shape[1] - 1
    companion = np.zeros((w.size, degree, degree))
    companion[:, 0, :] = -closed[:, 1:] / closed[:, :1]
    companion[:, np.arange(1, degree), np.arange(degree - 1)] = 1.0
    with np.errstate(all="ignore"):
        roots = np.linalg.eigvals(companion)
    out[batch] = np.all(np.isfinite(roots), axis=1) & np.all(roots.real < 0, axis=1)
    return out


class _ClosedLoop:
    """The loop's DFT quantities on one record, computed once per fit."""

    def __init__(self, record: TrackingRecord, plant, feedforward: bool, disturbance_at: str):
        if record.fd is None:
            raise IdentificationError("record: the closed-loop target needs the record's fd")
        if disturbance_at not in ("output", "input"):
            raise IdentificationError(f"disturbance_at: must be output or input, got {disturbance_at!r}")
        self.num_c, self.den_c = _plant_polynomials(plant)
        self.names = _names(feedforward)
        self.n = record.ft.size
        omega = 2.0 * np.pi * np.fft.rfftfreq(self.n, 1.0 / record.rate)
        self.s = (1j * omega)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.polyval(self.den_c, self.s) / np.polyval(self.num_c, self.s)  # 1/Yc
        self.g = g
        self.ft = np.fft.rfft(record.ft)[:, None]
        self.fd_term = (g if disturbance_at == "output" else np.ones_like(g)) * np.fft.rfft(record.fd)[
            :, None
        ]

    def u(self, theta: np.ndarray) -> np.ndarray:
        """u_cl (n, n_sets) for parameter columns theta (n_p, n_sets); unstable sets are NaN."""
        spectrum = loop_spectrum(theta, self.names, self.s, self.g, self.ft, self.fd_term)
        with np.errstate(invalid="ignore"):
            u = np.fft.irfft(spectrum, n=self.n, axis=0)
        u[:, ~loops_are_stable(theta, self.names, self.num_c, self.den_c)] = np.nan
        return u


def loop_spectrum(theta, names, s, g, ft, fd_term) -> np.ndarray:
    """The loop's U at ``s`` (n_w, 1) for parameter columns ``theta`` (n_p, n_sets), not checked for
    stability: ``((Hft + He) G Ft - He fd_term) / (G + He)`` with ``g = G = 1/Yc`` and
    ``fd_term = D Fd`` (module notes), each (n_w, 1)."""
    p = dict(zip(names, theta, strict=True))
    w, z = p["w_nms"], p["zeta_nms"]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        nms = w**2 / (s**2 + 2.0 * z * w * s + w**2)
        he = nms * p["Kpe"] * (p["TL"] * s + 1.0) * np.exp(-s * p["tau_pe"])
        numerator = he * (g * ft - fd_term)
        if "Kpt" in p:
            hft = nms * p["Kpt"] * g / (p["TI"] * s + 1.0) ** 2 * np.exp(-s * p["tau_pt"])
            numerator = numerator + hft * g * ft
        return numerator / (g + he)


def closed_loop_u(values: dict, plant, record: TrackingRecord, disturbance_at: str = "output") -> np.ndarray:
    """u of the parametric model in closed loop with ``plant``, driven by the record's ft and fd.

    The periodic steady state over the record (see the module's notes); NaN
    throughout for a loop that is not stable.

    Parameters
    ----------
    values : mapping of str to float
        Feedback parameters, plus the feedforward ones for a feedforward path.
    plant : control.TransferFunction
        ``Yc``.
    record : TrackingRecord
        ft and fd (rad) and the rate (Hz); e and u are not used.
    disturbance_at : str
        ``output`` or ``input`` (SPEC 7).

    Returns
    -------
    ndarray, shape (N,)
    """
    feedforward = "Kpt" in values
    loop = _ClosedLoop(record, plant, feedforward, disturbance_at)
    theta = np.array([[float(values[n])] for n in loop.names])
    return loop.u(theta)[:, 0]
