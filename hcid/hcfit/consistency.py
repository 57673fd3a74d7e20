"""Is a fitted model consistent with the data's own frequency response? (SPEC 11)

At every forcing line k of a record (:mod:`hcid.hcfit.lines`) the model's two paths leave

    r_k = U_k - He(w_k) E_k - Hft(w_k) Ft_k

which is the remnant's coefficient there when the model is the person's, whatever the
noise in E: ``r_k / E_k`` is the Fourier-coefficient estimate of He minus the model's He
at a disturbance line, ``r_k / Ft_k`` that of Ht (with the model's He) at a target line.
The remnant's variance at k is the mean of ``|U_j - He(w_j) E_j|^2`` over the
neighbouring bins without forcing (M of them). Under the model each line's
``t_k = |r_k|^2 / s_k^2`` is F(2, 2M)-distributed; each is carried to the chi-square(2)
value of the same tail probability and summed: ``X^2`` with ``2 L`` degrees of freedom
for L lines, and its p-value. A model with p below :data:`CONTRADICTED` is "contradicted
by the data".

For a group of runs the same model is set against each run's deviations ``d_k = r_k / F_k``,
``F_k`` the forcing function's own coefficient at the line (Fd at a disturbance line, Ft at a
target line): noise-free, so ``d`` is the remnant's coefficient scaled, zero-mean under the model
(a ratio with the noisy E would be biased towards -1/Yc where the remnant is large), and invariant
to a sign flip of the forcing functions. Their mean over the n runs is set against its standard
error from their spread, ``t_k = |mean d_k|^2 / (s_k^2 / n)``, F(2, 2(n - 1)) under the model.
That spread holds the differences between the group's people, not only their remnant.

A model fitted to these same lines (the ``lines`` estimator) has ``fitted`` parameters taken off
the degrees of freedom (its cost is nearly this statistic); a model fitted to other data, or the
group's medians, keeps ``2 L``. Beside the test, the median |error| of the model against the
Fourier-coefficient estimates themselves (:func:`hcid.analysis.fourier.fc_estimate`), in dB and
degrees, per path: a description, not a test (a run's U/E is biased where the remnant is large).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import control
import numpy as np
from scipy import stats

from hcid.analysis.fourier import fc_estimate
from hcid.errors import DataError
from hcid.hcfit.lines import LineData
from hcid.hcfit.model import hc_response

__all__ = ["CONTRADICTED", "Consistency", "consistency", "format_p", "group_consistency", "line_test"]

#: A model whose consistency p-value lies below this is contradicted by the data (SPEC 11).
CONTRADICTED = 0.01


@dataclass(frozen=True)
class Consistency:
    """A fitted model against the data's own frequency response.

    Attributes
    ----------
    chi2, dof, p : float, int, float
        The statistic, its degrees of freedom (2 per line) and its p-value.
    he_db, he_deg : float
        Median |error| of the model's He against the Fourier-coefficient estimates at the
        disturbance lines: magnitude (dB) and phase (deg).
    ht_db, ht_deg : float
        The same for Ht at the target lines (NaN without a feedforward path or target lines).
    lines : int
        Forcing lines used.
    spread : str
        Where the estimates' standard errors came from: ``remnant`` (bins beside the lines)
        or ``across n runs`` (the spread across the group's runs).
    """

    chi2: float
    dof: int
    p: float
    he_db: float
    he_deg: float
    ht_db: float
    ht_deg: float
    lines: int
    spread: str

    @property
    def contradicted(self) -> bool:
        return bool(self.p < CONTRADICTED)

    @property
    def verdict(self) -> str:
        """In words: ``contradicted by the data``, ``consistent with the data``, or ``no test``
        (a p-value that is not a number, e.g. from a model with a NaN parameter)."""
        if not math.isfinite(self.p):
            return "no test (the model's responses are not finite)"
        return "contradicted by the data" if self.contradicted else "consistent with the data"

    def describe(self) -> str:
        """E.g. ``consistent with the data (chi-square 19.5 on 22 dof, p = 0.62, spread: remnant;
        median |error| He 3.0 dB 18 deg, Ht 1.4 dB 9 deg)``."""
        ht = "" if math.isnan(self.ht_db) else f", Ht {self.ht_db:.1f} dB {self.ht_deg:.0f} deg"
        return (
            f"{self.verdict} (chi-square {self.chi2:.1f} on {self.dof} dof, {p_text(self.p)}, "
            f"spread: {self.spread}; median |error| He {self.he_db:.1f} dB {self.he_deg:.0f} deg{ht})"
        )


def format_p(p: float) -> str:
    """A p-value for a reader: two digits, ``< 1e-15`` below what double precision resolves."""
    if not math.isfinite(p):
        return "n/a"
    return "< 1e-15" if p < 1e-15 else f"{p:.2g}"


def p_text(p: float) -> str:
    """A p-value in a sentence: ``p = 0.031``, or ``p < 1e-15`` (not ``p = < 1e-15``).

    >>> p_text(0.0312), p_text(1e-20)
    ('p = 0.031', 'p < 1e-15')
    """
    text = format_p(p)
    return f"p {text}" if text.startswith("<") else f"p = {text}"


def _chi2(t: np.ndarray, dof_noise: int, fitted: int = 0) -> tuple[float, int, float]:
    """Each line's F(2, dof_noise) statistic carried to chi-square(2) (Fisher's ``-2 ln p``),
    summed, on ``2 L - fitted`` degrees of freedom, and its p-value."""
    if t.size == 0 or not np.all(np.isfinite(t)):
        return math.nan, 0, math.nan
    tail = stats.f.sf(t, 2, dof_noise)
    z = stats.chi2.isf(np.clip(tail, 1e-300, 1.0), 2)
    total = float(np.sum(z))
    dof = max(1, 2 * t.size - fitted)
    return total, dof, float(stats.chi2.sf(total, dof))


def _paths(values: Mapping[str, float], plant, omega: np.ndarray):
    hft, he = hc_response(values, plant, omega)
    return (np.zeros_like(he) if hft is None else hft), he


def _residuals(values, plant, data: LineData):
    """r at the lines, the remnant's variance beside them, and d = r / Fd or r / Ft."""
    hft, he = _paths(values, plant, data.omega)
    r = data.u - he * data.e - hft * data.ft
    _, he_near = _paths(values, plant, data.near_omega.ravel())
    near = data.near_u - he_near.reshape(data.near_omega.shape) * data.near_e
    s2 = np.mean(np.abs(near) ** 2, axis=1)
    d = r / np.where(data.is_target, data.ft, data.fd)
    return r, s2, d


def _errors(values, plant, fc, feedforward: bool):
    """Median |error| (dB, deg) of He and Ht against the estimates ``fc`` (NaN without them)."""
    if fc is None:
        return math.nan, math.nan, math.nan, math.nan
    he_hat, omega_e, ht_hat, omega_t = fc

    def median_errors(model, estimate):
        db = np.abs(20.0 * np.log10(np.abs(model) / np.abs(estimate)))
        deg = np.abs(np.degrees(np.angle(model / estimate)))
        return float(np.median(db)), float(np.median(deg))

    _, he = _paths(values, plant, omega_e)
    he_db, he_deg = median_errors(he, he_hat)
    ht_db = ht_deg = math.nan
    if feedforward and omega_t.size:
        hft, _ = _paths(values, plant, omega_t)
        ht_db, ht_deg = median_errors(hft, ht_hat)
    return he_db, he_deg, ht_db, ht_deg


def _by_frequency(estimates: Sequence[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Per frequency (rad/s, to 1e-9 relative), the mean of the estimates there, ascending."""
    found: dict[float, list[complex]] = {}
    for omega, h in estimates:
        for w, x in zip(omega.tolist(), h.tolist(), strict=True):
            key = next((k for k in found if math.isclose(k, w, rel_tol=1e-9)), w)
            found.setdefault(key, []).append(x)
    omega = np.array(sorted(found))
    return omega, np.array([np.mean(found[w]) for w in omega.tolist()])


def _fc(runs: Sequence[dict[str, np.ndarray]], rate: float):
    """The Fourier-coefficient estimates of the runs together (or, where their forcing functions
    differ, the mean of each run's, per frequency where their line sets differ); None where there
    is none (e.g. e without power at a line)."""
    n = runs[0]["u"].size
    try:
        fc = fc_estimate(runs, rate, slice(0, n))
        return fc.he, fc.omega_e, fc.ht, fc.omega_t
    except DataError:
        pass
    try:
        each = [fc_estimate([r], rate, slice(0, n)) for r in runs]
    except DataError:
        return None

    def same(a: np.ndarray, b: np.ndarray) -> bool:
        return a.shape == b.shape and np.allclose(a, b, rtol=1e-9, atol=0.0)

    if not all(same(f.omega_e, each[0].omega_e) and same(f.omega_t, each[0].omega_t) for f in each):
        # Line sets that differ between runs (swapped between trials): per frequency, the mean over
        # the runs that measured it as such a line.
        he_omega, he = _by_frequency([(f.omega_e, f.he) for f in each])
        ht_omega, ht = _by_frequency([(f.omega_t, f.ht) for f in each])
        return he, he_omega, ht, ht_omega
    return (
        np.mean([f.he for f in each], axis=0),
        each[0].omega_e,
        np.mean([f.ht for f in each], axis=0),
        each[0].omega_t,
    )


def line_test(
    values: Mapping[str, float], plant: control.TransferFunction, data: LineData, fitted: int = 0
) -> tuple[float, int, float]:
    """One run's test (module notes) alone: chi-square, degrees of freedom and p-value."""
    r, s2, _ = _residuals(values, plant, data)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _chi2(np.abs(r) ** 2 / s2, 2 * data.neighbours, fitted)


def consistency(
    values: Mapping[str, float],
    plant: control.TransferFunction,
    data: LineData,
    record: Mapping[str, np.ndarray],
    rate: float,
    fitted: int = 0,
) -> Consistency:
    """One run's consistency with a model (module notes).

    Parameters
    ----------
    values : mapping of str to float
        The model's parameters (feedforward ones only for a feedforward path).
    plant : control.TransferFunction
        ``Yc``.
    data : LineData
        The run at its forcing lines (:func:`hcid.hcfit.lines.line_data`).
    record : mapping
        The run's ``ft``, ``fd``, ``e``, ``u`` (rad), the same window as ``data``.
    rate : float
        Its rate (Hz).
    fitted : int
        Parameters fitted to these same lines (the ``lines`` estimator's free ones), taken off
        the degrees of freedom; 0 for a model fitted to other data.
    """
    chi2, dof, p = line_test(values, plant, data, fitted)
    errors = _errors(values, plant, _fc([record], rate), "Kpt" in values)
    return Consistency(chi2, dof, p, *errors, lines=int(data.omega.size), spread="remnant")


def group_consistency(
    values: Mapping[str, float],
    plant: control.TransferFunction,
    datas: Sequence[LineData],
    records: Sequence[Mapping[str, np.ndarray]],
    rate: float,
) -> Consistency:
    """A group's consistency with its model: the runs' mean deviation against its spread across
    runs (module notes); a single run is tested as by :func:`consistency`.

    Raises
    ------
    DataError
        If the runs' forcing lines differ (the deviations cannot be averaged line by line).
    """
    if len(datas) < 2:
        return consistency(values, plant, datas[0], records[0], rate)
    if any(d.omega.shape != datas[0].omega.shape or not np.allclose(d.omega, datas[0].omega) for d in datas):
        raise DataError("the group's runs have other forcing lines: their deviations cannot be averaged")
    d = np.array([_residuals(values, plant, data)[2] for data in datas])
    n = d.shape[0]
    mean = d.mean(axis=0)
    s2 = np.sum(np.abs(d - mean) ** 2, axis=0) / (n - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(s2 > 0, np.abs(mean) ** 2 / (s2 / n), np.nan)
    chi2, dof, p = _chi2(t, 2 * (n - 1))
    errors = _errors(values, plant, _fc(list(records), rate), "Kpt" in values)
    return Consistency(chi2, dof, p, *errors, lines=int(mean.size), spread=f"across {n} runs")
