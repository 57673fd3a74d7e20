"""The loop's descriptors (analyses layer, SPEC 8): crossover and phase margin, the variance
split of u, and the remnant's level and spectrum.

The manual-control literature describes a tracking loop by the crossover
frequency ``wc`` of its open loop ``L = Hpe Yc`` (where ``|L(j wc)| = 1``) and its
phase margin ``PM = 180 + arg L(j wc)`` (deg), the phase continuous from low
frequency. Delays are welcome: ``L`` is any callable frequency response, so
``exp(-j w tau)`` costs nothing, which python-control's ``margin`` cannot take.

The remnant of a record is what a model of the person leaves of u:
``n = u - Hft ft - He e``. Its level is ``var(n)/var(u)``; its spectrum is
fitted with the remnant filter of SPEC 1, ``Yn = Kn wn^3 / ((s^2 + 2 zn wn s + wn^2)
(s + wn))`` driven by white noise of unit variance at a stated rate (the
simulation's), so that a simulation can be given the remnant a person showed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
from scipy import optimize

from hcid.errors import IdentificationError

__all__ = ["LoopMargins", "RemnantFit", "fit_remnant", "loop_margins", "remnant_spectrum", "variance_shares"]

#: Welch segments of the remnant spectrum (s): 0.1 Hz resolution.
SEGMENT_SECONDS = 10.24


@dataclass(frozen=True)
class LoopMargins:
    """Gain crossover and phase margin of an open loop.

    Attributes
    ----------
    crossover : float
        Gain-crossover frequency (rad/s): ``|L(j wc)| = 1``; NaN when ``|L|`` does
        not cross 1 in the band searched.
    phase_margin : float
        ``180 + arg L(j wc)`` (deg), the phase continuous from the band's low end;
        NaN without a crossover.
    n_crossovers : int
        Gain crossovers found in the band; with several, the lowest is reported
        (SPEC 8; python-control's ``margin`` takes the one of the smallest margin).
    """

    crossover: float
    phase_margin: float
    n_crossovers: int

    def to_arrow(self) -> pa.Table:
        """One row: crossover (rad/s), phase_margin (deg), n_crossovers."""
        return pa.table(
            {
                "crossover": [self.crossover],
                "phase_margin": [self.phase_margin],
                "n_crossovers": [self.n_crossovers],
            }
        )


def loop_margins(
    open_loop: Callable[[np.ndarray], np.ndarray],
    band: tuple[float, float] = (1e-2, 1e3),
    points: int = 4001,
) -> LoopMargins:
    """Gain crossover and phase margin of the open loop ``L(j w) = open_loop(w)``.

    Parameters
    ----------
    open_loop : callable
        ``w`` (rad/s, ndarray) -> ``L(j w)`` (complex ndarray of the same shape).
    band : tuple of float
        Frequencies (rad/s) searched for a crossover; the phase is unwrapped from
        ``band[0]`` upwards.
    points : int
        Log-spaced frequencies of the search; each crossover between two of them
        is then solved to machine precision (Brent's method on ``log |L|``).

    Returns
    -------
    LoopMargins

    Raises
    ------
    IdentificationError
        For a band that is not ``0 < lo < hi`` or a response that is not finite.

    Examples
    --------
    >>> m = loop_margins(lambda w: 2.0 / (1j * w))  # 2/s: crosses at 2 rad/s, phase -90 deg
    >>> round(m.crossover, 9), round(m.phase_margin, 9)
    (2.0, 90.0)
    """
    lo, hi = band
    if not 0 < lo < hi or not np.isfinite(hi):
        raise IdentificationError(f"band: must be (lo, hi) rad/s with 0 < lo < hi, got {band}")
    w = np.geomspace(lo, hi, points)
    response = np.asarray(open_loop(w), dtype=complex)
    if response.shape != w.shape or not np.all(np.isfinite(response)):
        raise IdentificationError("open_loop: must give a finite complex response of the shape of w")
    with np.errstate(divide="ignore"):  # a zero response (no feedback path) never crosses
        log_mag = np.log(np.abs(response))
    phase = np.unwrap(np.angle(response))
    crossings = np.flatnonzero(np.sign(log_mag[:-1]) * np.sign(log_mag[1:]) < 0)
    crossings = np.union1d(crossings, np.flatnonzero(log_mag == 0.0))
    found = []
    for i in crossings:
        if log_mag[i] == 0.0:
            wc = w[i]
        else:
            wc = optimize.brentq(
                lambda x: float(np.log(np.abs(open_loop(np.array([x]))[0]))),
                w[i],
                w[i + 1],
                xtol=1e-15,
                rtol=1e-15,
            )
        # The phase at wc, continuous with the unwrapped grid phase at w[i].
        step = np.angle(open_loop(np.array([wc]))[0] / response[i])
        found.append((wc, 180.0 + np.degrees(phase[i] + step)))
    if not found:
        return LoopMargins(float("nan"), float("nan"), 0)
    wc, pm = found[0]  # SPEC 8: the lowest crossing (python-control takes the smallest margin)
    return LoopMargins(float(wc), float(pm), len(found))


# --------------------------------------------------------------------------- the variance split


def variance_shares(u: np.ndarray, parts: dict[str, np.ndarray]) -> dict[str, float]:
    """``var(part)/var(u)`` for each part, and ``remnant``: ``var(u - sum parts)/var(u)``.

    The shares need not sum to 1: the parts are correlated through the loop.

    Examples
    --------
    >>> u = np.array([1.0, -1.0, 2.0, -2.0])
    >>> variance_shares(u, {"e": 0.5 * u})
    {'e': 0.25, 'remnant': 0.25}
    """
    var_u = float(np.var(u))
    out = {name: float(np.var(x)) / var_u for name, x in parts.items()}
    out["remnant"] = float(np.var(u - sum(parts.values()))) / var_u
    return out


# --------------------------------------------------------------------------- the remnant


@dataclass(frozen=True)
class RemnantFit:
    """The remnant filter fitted to a remnant's spectrum (SPEC 1's ``Yn``).

    Attributes
    ----------
    kn : float
        Gain for white noise of unit variance at ``kn_rate`` (Hz), as SPEC 1's
        simulation draws it.
    w_n : float
        Break frequency (rad/s).
    zeta_n : float
        Damping (-).
    kn_rate : float
        The rate ``kn`` refers to (Hz).
    at_bound : bool
        ``w_n`` or ``zeta_n`` on a bound of the search (0.5 rad/s to Nyquist, 0.02 to 5):
        the spectrum is not the filter's shape, and the three values mean little.
    omega : ndarray
        Frequencies of the spectrum (rad/s).
    psd : ndarray
        Welch estimate, one-sided (rad^2/Hz).
    psd_fit : ndarray
        The fitted filter's one-sided density at ``omega`` (rad^2/Hz).
    """

    kn: float
    w_n: float
    zeta_n: float
    kn_rate: float
    at_bound: bool
    omega: np.ndarray
    psd: np.ndarray
    psd_fit: np.ndarray


def remnant_spectrum(n: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch density of ``n`` (rad^2/Hz) at frequencies (rad/s), DC left out.

    Hann segments of :data:`SEGMENT_SECONDS` (or the whole series if shorter),
    half overlapping.
    """
    from scipy import signal as sps

    n = np.asarray(n, dtype=np.float64)
    nperseg = min(n.size, round(SEGMENT_SECONDS * rate))
    f, p = sps.welch(n, fs=rate, window="hann", nperseg=nperseg, detrend="constant")
    return 2.0 * np.pi * f[1:], p[1:]


def _unit_density(omega: np.ndarray, w_n: float, zeta_n: float, kn_rate: float) -> np.ndarray:
    s = 1j * omega
    yn = w_n**3 / ((s**2 + 2.0 * zeta_n * w_n * s + w_n**2) * (s + w_n))
    return 2.0 * np.abs(yn) ** 2 / kn_rate


def fit_remnant(
    n: np.ndarray, rate: float, kn_rate: float, band: tuple[float, float] | None = None
) -> RemnantFit:
    """Fit SPEC 1's remnant filter to the spectrum of ``n`` by Whittle's likelihood.

    The model density is ``2 Kn^2 |Yn1(j w)|^2 / kn_rate`` (white noise of unit
    variance at ``kn_rate`` through ``Yn``, one-sided); ``Kn`` is profiled out
    (its optimum is ``mean(psd / shape)``), ``w_n`` and ``zeta_n`` minimise
    ``sum log P + psd/P`` over the band (default: the lowest bin to 80% of
    Nyquist): unbiased for a Welch estimate, where a least-squares fit on log
    densities is not.

    Parameters
    ----------
    n : ndarray
        The remnant (rad) at ``rate`` (Hz).
    kn_rate : float
        The rate (Hz) of the unit-variance white noise ``kn`` refers to.
    band : tuple of float, optional
        Frequencies fitted (rad/s).
    """
    omega, psd = remnant_spectrum(n, rate)
    lo, hi = band if band is not None else (omega[0], 0.8 * np.pi * rate)
    keep = (omega >= lo) & (omega <= hi) & (psd > 0)
    w, p = omega[keep], psd[keep]
    if w.size < 4:
        raise IdentificationError(f"remnant: {w.size} spectral lines in the band, need 4")

    def profiled(x):
        shape = _unit_density(w, np.exp(x[0]), np.exp(x[1]), kn_rate)
        kn2 = float(np.mean(p / shape))
        return float(np.sum(np.log(kn2 * shape))), kn2

    best = None
    limits = [(np.log(0.5), np.log(np.pi * rate)), (np.log(0.02), np.log(5.0))]
    for w0 in (5.0, 12.0, 25.0):
        for z0 in (0.2, 0.7):
            res = optimize.minimize(
                lambda x: profiled(x)[0], np.log([w0, z0]), method="L-BFGS-B", bounds=limits
            )
            if best is None or res.fun < best.fun:
                best = res
    w_n, zeta_n = (float(v) for v in np.exp(best.x))
    kn = float(np.sqrt(profiled(best.x)[1]))
    hit = any(min(abs(v - lo), abs(hi - v)) < 1e-6 for v, (lo, hi) in zip(best.x, limits, strict=True))
    return RemnantFit(
        kn, w_n, zeta_n, float(kn_rate), hit, omega, psd, kn**2 * _unit_density(omega, w_n, zeta_n, kn_rate)
    )
