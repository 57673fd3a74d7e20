"""A record's forcing lines: its DFT coefficients there and the remnant's variance beside them.

Where the forcing functions are multisines over whole periods of the record
(:func:`hcid.analysis.fourier.forcing_lines`), everything the forcing functions drive lies
at their lines, and every other bin holds the remnant's response alone. The
remnant's variance at a line is then read off its neighbours: the mean of
``|X_j|^2`` over the :data:`NEIGHBOURS` nearest bins without forcing (a
nonparametric noise estimate, Pintelon and Schoukens, *System Identification: A
Frequency Domain Approach*, 2nd ed. 2012, section 2.5: the remnant's spectrum is
smooth over a few bins). With ``M`` neighbours each estimate has ``2 M`` real
degrees of freedom, far more than the spread across a run's periods gives (one
complex degree of freedom per line for two periods).

Two uses:

- the ``lines`` estimator (:class:`LinesProblem`, :func:`hcid.hcfit.fit.fit_lines`): the
  parametric model in closed loop with the plant, driven by the recorded ft and fd, output
  error on U at the forcing lines weighted by the remnant's variance there. The inputs are ones
  the remnant cannot reach (no bias from the remnant in e, which the ``time`` target takes as an
  input), and the weights, estimated beside each line, bring it close to the maximum-likelihood
  fit for a Gaussian remnant;
- the consistency of a fitted model with the record (:mod:`hcid.hcfit.consistency`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcid.analysis.fourier import NEIGHBOURS, ForcingLines, forcing_lines, free_neighbours, interpolate
from hcid.errors import DataError
from hcid.hcfit.closed_loop import loop_spectrum, loops_are_stable
from hcid.hcfit.model import TrackingRecord, _names, _plant_polynomials

__all__ = ["NEIGHBOURS", "LineData", "feedforward_size", "line_data", "record_lines"]


@dataclass(frozen=True)
class LineData:
    """One record at its forcing lines (sorted by frequency).

    Attributes
    ----------
    omega : ndarray, shape (L,)
        Line frequencies (rad/s).
    is_target : ndarray of bool, shape (L,)
        A target line (ft has power there); else a disturbance line.
    u, e, ft, fd : ndarray of complex, shape (L,)
        DFT coefficients of the record at the lines.
    near_omega : ndarray, shape (L, M)
        Frequencies (rad/s) of each line's neighbouring bins without forcing.
    near_u, near_e : ndarray of complex, shape (L, M)
        u and e there: the remnant's closed-loop response alone.
    lines : ForcingLines
        The bins found.
    """

    omega: np.ndarray
    is_target: np.ndarray
    u: np.ndarray
    e: np.ndarray
    ft: np.ndarray
    fd: np.ndarray
    near_omega: np.ndarray
    near_u: np.ndarray
    near_e: np.ndarray
    lines: ForcingLines

    @property
    def neighbours(self) -> int:
        return self.near_u.shape[1]

    @property
    def noise_u(self) -> np.ndarray:
        """The variance (E |.|^2) of u's remnant part at each line, from its neighbours."""
        return np.mean(np.abs(self.near_u) ** 2, axis=1)


def line_data(record: TrackingRecord, neighbours: int = NEIGHBOURS) -> LineData:
    """The record's forcing lines, their DFT coefficients and their neighbours (whole record).

    Raises
    ------
    DataError
        If the record has no fd, or its forcing functions are not multisines on disjoint
        lines over whole periods of it (the reason of :func:`hcid.analysis.fourier.forcing_lines`),
        or too few bins without forcing lie beside the lines.
    """
    if record.fd is None:
        raise DataError("record: the forcing lines need the record's fd")
    lines = forcing_lines(record.ft, record.fd, record.rate, one_input=True)
    if lines.problem is not None:
        raise DataError(f"no forcing lines: {lines.problem}")
    spectra = {k: np.fft.rfft(getattr(record, k)) for k in ("u", "e", "ft", "fd")}
    bins, near = free_neighbours(lines, neighbours)
    return LineData(
        omega=lines.omega(bins),
        is_target=np.isin(bins, lines.target),
        u=spectra["u"][bins],
        e=spectra["e"][bins],
        ft=spectra["ft"][bins],
        fd=spectra["fd"][bins],
        near_omega=lines.omega(near),
        near_u=spectra["u"][near],
        near_e=spectra["e"][near],
        lines=lines,
    )


def feedforward_size(data: LineData) -> float:
    """A model-free size of the feedforward path (issue 34): ``sum |U - He E|^2 / s^2`` over the
    target lines, i.e. ``|Ht|^2 / se(Ht)^2`` summed, with He interpolated from the disturbance
    lines' ``U / E`` (SPEC 10) at the target lines and at their neighbours, and ``s^2`` the mean of
    ``|U_j - He E_j|^2`` over the neighbours without forcing. The interpolation leaks He's error
    into Ht even without feedforward, so its null distribution comes from twins, not a formula
    (tests/test_hcfit_lines.py: it grows with the feedforward gain of a synthetic loop).
    """
    dist = ~data.is_target
    he_lines = data.u[dist] / data.e[dist]
    omega_d = data.omega[dist]
    he_t = interpolate(omega_d, he_lines, data.omega[data.is_target])
    he_near = interpolate(omega_d, he_lines, data.near_omega[data.is_target].ravel()).reshape(
        data.near_omega[data.is_target].shape
    )
    r = data.u[data.is_target] - he_t * data.e[data.is_target]
    near = data.near_u[data.is_target] - he_near * data.near_e[data.is_target]
    s2 = np.mean(np.abs(near) ** 2, axis=1)
    return float(np.sum(np.abs(r) ** 2 / s2))


def record_lines(signals, rate: float, neighbours: int = NEIGHBOURS) -> LineData:
    """:func:`line_data` of a whole record given as its ``ft``, ``fd``, ``e``, ``u`` arrays (rad)
    at ``rate`` Hz (a run's or a twin's)."""
    n = np.asarray(signals["u"]).size
    rows = slice(0, n)
    record = TrackingRecord(signals["ft"], signals["e"], signals["u"], rate, rows, rows, fd=signals["fd"])
    return line_data(record, neighbours)


class LinesProblem:
    """The ``lines`` estimator's residuals: ``(U - U_cl(theta)) / sigma_u`` at the forcing lines,
    real and imaginary parts, with ``U_cl`` the parametric model's closed loop
    (:func:`hcid.hcfit.closed_loop.loop_spectrum`) and ``sigma_u^2`` the remnant's variance in u
    beside each line (:attr:`LineData.noise_u`)."""

    def __init__(self, data: LineData, plant, feedforward: bool, disturbance_at: str):
        self.plant = plant
        self.num_c, self.den_c = _plant_polynomials(plant)
        self.names = _names(feedforward)
        self.s = (1j * data.omega)[:, None]
        g = np.polyval(self.den_c, self.s) / np.polyval(self.num_c, self.s)  # 1/Yc, lines are > 0
        self.g = g
        self.ft = data.ft[:, None]
        self.fd_term = (g if disturbance_at == "output" else np.ones_like(g)) * data.fd[:, None]
        self.u = data.u[:, None]
        self.scale = 1.0 / np.sqrt(data.noise_u)[:, None]

    def _errors(self, thetas: np.ndarray) -> np.ndarray:
        u = loop_spectrum(thetas, self.names, self.s, self.g, self.ft, self.fd_term)
        errors = (u - self.u) * self.scale
        errors[:, ~loops_are_stable(thetas, self.names, self.num_c, self.den_c)] = np.nan
        return errors

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.residual_columns(x[:, None])[:, 0]

    def residual_columns(self, thetas: np.ndarray) -> np.ndarray:
        """:meth:`residuals` of every column of ``thetas`` (one parameter vector per column)."""
        r = self._errors(thetas)
        r = np.concatenate([r.real, r.imag])
        # An unstable loop (never at the bounds' interior optimum) gets a large finite cost.
        return np.where(np.isfinite(r), r, 1e6)

    def jacobian(self, x: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """Forward differences of :meth:`residuals` at ``x``, every column in one call (scipy's
        ``2-point`` steps, taken backwards where a forward step would leave the bounds)."""
        h = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))
        h = np.where(x + h > upper, -h, h)
        thetas = np.column_stack([x, x[:, None] + np.diag(h)])
        # The loop's stability checked at x alone (a step of 1.5e-8 relative does not cross the
        # boundary where the fit can be: an unstable x has no slope, its cost is flat at 1e6).
        errors = (
            loop_spectrum(thetas, self.names, self.s, self.g, self.ft, self.fd_term) - self.u
        ) * self.scale
        r = np.concatenate([errors.real, errors.imag])
        if not (
            loops_are_stable(thetas[:, :1], self.names, self.num_c, self.den_c)[0] and np.isfinite(r).all()
        ):
            return np.zeros((r.shape[0], x.size))
        return (r[:, 1:] - r[:, :1]) / h

    def costs(self, thetas: np.ndarray) -> np.ndarray:
        c = np.sum(np.abs(self._errors(thetas)) ** 2, axis=0)
        return np.where(np.isfinite(c), c, np.inf)
