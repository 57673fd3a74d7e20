"""The loop's descriptors: gain-crossover frequency and phase margin of an open loop (analyses layer).

The manual-control literature describes a tracking loop by the crossover
frequency ``wc`` of its open loop ``L = Hpe Yc`` (where ``|L(j wc)| = 1``) and its
phase margin ``PM = 180 + arg L(j wc)`` (deg), the phase continuous from low
frequency. Delays are welcome: ``L`` is any callable frequency response, so
``exp(-j w tau)`` costs nothing, which python-control's ``margin`` cannot take.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
from scipy import optimize

from hcid.errors import IdentificationError

__all__ = ["LoopMargins", "loop_margins"]


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
        Gain crossovers found in the band; with several, the one of the smallest
        ``|phase_margin|`` is reported (python-control's rule).
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
    wc, pm = min(found, key=lambda item: abs(item[1]))
    return LoopMargins(float(wc), float(pm), len(found))
