"""A whole experiment's conditions combined per person (SPEC 12; pure numerical core).

A lab's session mixes trials with a target and a disturbance on disjoint lines, trials with
only one of them, line sets swapped between trials and sign flips. Each trial's kind comes
from its data (:func:`trial_lines`): over the window an input is absent when its power at
every forcing line is below :data:`hcid.analysis.fourier.ABSENT` of the other input's strongest
line (zero in the file). From the
DFT coefficients ``U, E, Ft, Fd`` of one window (a whole number of periods):

- ``H_UR = U / Ft`` at the target lines and ``H_UD = U / Fd`` at the disturbance lines, per
  trial (a sign flip of an input flips U with it: the ratios are the same);
- per person, the trials of one condition (the same kind and line sets) averaged (the complex
  mean of their ratios: trials of a condition may differ in phases and sign), then the
  conditions that measured a line averaged;
- He from ``H_UD`` where the line was measured as a disturbance line: ``He = -H_UD / (Yc (1 +
  H_UD))`` (disturbance at the plant input) or ``-H_UD / (1 + H_UD Yc)`` (at the output);
  interpolated (:func:`hcid.analysis.fourier.interpolate`) only where no trial measured it;
- ``Ht = H_UR (1 + He Yc) - He`` at the lines a target measured, and the model inversion
  ``Ht Yc`` (1 is the plant's exact inverse).

Three estimates per person (:data:`SOURCES`): from every trial, from the two-input trials
alone (swapped pairs give both responses at every line) and from the single-input trials
alone (target-only and disturbance-only). :func:`superposition` compares the last two across
people; :func:`prediction` predicts u of one kind of trial with a model from the other.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hcid.analysis.fourier import absent_inputs, interpolate, line_bins

__all__ = [
    "SOURCES",
    "Kind",
    "PersonLines",
    "Prediction",
    "TrialLines",
    "combine",
    "prediction",
    "superposition",
    "swapped",
    "trial_lines",
    "wilcoxon_p",
]


class Kind(enum.Enum):
    """What a trial's inputs are (SPEC 12)."""

    TWO_INPUT = "target and disturbance"
    DISTURBANCE_ONLY = "disturbance only"
    TARGET_ONLY = "target only"


#: The estimates combined per person: the trials each uses.
SOURCES = {
    "all trials": (Kind.TWO_INPUT, Kind.DISTURBANCE_ONLY, Kind.TARGET_ONLY),
    "two-input trials": (Kind.TWO_INPUT,),
    "single-input trials": (Kind.DISTURBANCE_ONLY, Kind.TARGET_ONLY),
}

#: What a kind of trial answers, in words (the answer and the report say it).
ANSWERS = {
    Kind.TWO_INPUT: "feedforward tested (W*, p-values), both paths from the Fourier coefficients",
    Kind.DISTURBANCE_ONLY: (
        "feedback alone: He from the disturbance lines; no feedforward test (no target to respond to)"
    ),
    Kind.TARGET_ONLY: (
        "the closed-loop target response U/Ft at its lines; Ht and He are not separable from it "
        "alone (combined with disturbance lines of the person's other trials)"
    ),
}


@dataclass(frozen=True)
class TrialLines:
    """One trial's forcing lines and responses over the window.

    Attributes
    ----------
    kind : Kind
        From the data (None: neither input is there).
    target, disturbance : ndarray of int
        DFT bins of the window holding the target's and the disturbance's lines (empty for an
        absent input, and both empty where ``problem`` says why the trial has no lines: an input
        that is not a sum of sines over whole periods of the window, shared lines).
    spectra : dict of str to ndarray of complex
        ``ft``, ``fd``, ``e``, ``u``: the window's whole rfft (for predictions).
    n, rate : int, float
        The window's samples and the sample rate (Hz).
    """

    kind: Kind | None
    target: np.ndarray
    disturbance: np.ndarray
    spectra: dict
    n: int
    rate: float
    problem: str | None = None

    def omega(self, bins: np.ndarray) -> np.ndarray:
        """Frequencies (rad/s) of ``bins``."""
        return 2.0 * np.pi * np.asarray(bins, dtype=np.float64) * self.rate / self.n

    @property
    def h_ur(self) -> np.ndarray:
        """``U / Ft`` at the target lines."""
        return self.spectra["u"][self.target] / self.spectra["ft"][self.target]

    @property
    def h_ud(self) -> np.ndarray:
        """``U / Fd`` at the disturbance lines."""
        return self.spectra["u"][self.disturbance] / self.spectra["fd"][self.disturbance]

    @property
    def layout(self) -> tuple:
        """The condition's identity from the data: its kind and its two line sets."""
        return (self.kind, tuple(self.target.tolist()), tuple(self.disturbance.tolist()))


def trial_lines(record: Mapping[str, np.ndarray], rate: float, n: int) -> TrialLines:
    """A trial's kind and lines over its first ``n`` samples (a whole number of periods).

    Examples
    --------
    >>> t = np.arange(400) / 10.0                       # 40 s at 10 Hz: bins every 0.025 Hz
    >>> fd = np.sin(2 * np.pi * 0.075 * t)              # bin 3
    >>> rec = {"ft": np.zeros(400), "fd": fd, "e": -fd, "u": 0.5 * fd}
    >>> trial = trial_lines(rec, 10.0, 400)
    >>> trial.kind.value, trial.disturbance.tolist(), np.round(np.abs(trial.h_ud), 6).tolist()
    ('disturbance only', [3], [0.5])
    """
    window = {k: np.asarray(record[k], dtype=np.float64)[:n] for k in ("ft", "fd", "e", "u")}
    spectra = {k: np.fft.rfft(x) for k, x in window.items()}
    target, disturbance = line_bins(window["ft"]), line_bins(window["fd"])
    empty = np.zeros(0, dtype=np.int64)
    no_target, no_disturbance = absent_inputs(window["ft"], window["fd"])

    def made(kind, t_bins, d_bins, problem=None) -> TrialLines:
        return TrialLines(kind, t_bins, d_bins, spectra, int(n), float(rate), problem)

    if no_target and no_disturbance:
        return made(None, empty, empty, "neither a target nor a disturbance over the window")
    if no_target:
        if disturbance.size == 0:
            return made(Kind.DISTURBANCE_ONLY, empty, empty, "the disturbance is not a sum of sines")
        return made(Kind.DISTURBANCE_ONLY, empty, disturbance)
    if no_disturbance:
        if target.size == 0:
            return made(Kind.TARGET_ONLY, empty, empty, "the target is not a sum of sines")
        return made(Kind.TARGET_ONLY, target, empty)
    if target.size == 0 or disturbance.size == 0:
        return made(Kind.TWO_INPUT, empty, empty, "an input is not a sum of sines over the window")
    if np.intersect1d(target, disturbance).size:
        return made(Kind.TWO_INPUT, empty, empty, "target and disturbance share lines")
    return made(Kind.TWO_INPUT, target, disturbance)


def swapped(trials: Sequence[TrialLines]) -> bool:
    """Whether some line is a target line in one trial and a disturbance line in another."""
    target = set().union(*(t.target.tolist() for t in trials))
    disturbance = set().union(*(t.disturbance.tolist() for t in trials))
    return bool(target & disturbance)


# --------------------------------------------------------------------------- combined per person


@dataclass(frozen=True)
class PersonLines:
    """A person's responses at every line of their trials, from one :data:`SOURCES` entry.

    Attributes
    ----------
    omega : ndarray
        The lines (rad/s), ascending.
    h_ur, h_ud : ndarray of complex
        The condition-averaged target and disturbance responses (NaN where not measured).
    he, ht : ndarray of complex
        The feedback and feedforward paths (``ht`` NaN where no target measured the line).
    he_measured : ndarray of bool
        He from a disturbance measured at the line (False: interpolated).
    inversion_runs : list of ndarray
        Per line, the trials' own ``|Ht Yc|`` (each trial's ``H_UR`` with the combined He).
    n_target, n_disturbance : ndarray of int
        Trials measuring each line as a target and as a disturbance line.
    """

    omega: np.ndarray
    h_ur: np.ndarray
    h_ud: np.ndarray
    he: np.ndarray
    ht: np.ndarray
    yc: np.ndarray
    he_measured: np.ndarray
    inversion_runs: list
    n_target: np.ndarray
    n_disturbance: np.ndarray

    @property
    def inversion(self) -> np.ndarray:
        """``Ht Yc`` at every line (NaN where Ht is not known)."""
        return self.ht * self.yc


def _condition_means(trials: Sequence[TrialLines], which: str) -> dict[int, list[complex]]:
    """Per bin, the condition means of ``h_ur`` or ``h_ud`` (complex mean over the trials of a
    condition, a condition being a kind and its line sets)."""
    by_condition: dict[tuple, list[TrialLines]] = {}
    for trial in trials:
        by_condition.setdefault(trial.layout, []).append(trial)
    out: dict[int, list[complex]] = {}
    for members in by_condition.values():
        bins = members[0].target if which == "ur" else members[0].disturbance
        if bins.size == 0:
            continue
        mean = np.mean([t.h_ur if which == "ur" else t.h_ud for t in members], axis=0)
        for b, h in zip(bins.tolist(), mean, strict=True):
            out.setdefault(b, []).append(complex(h))
    return out


def _feedback(h_ud: np.ndarray, yc: np.ndarray, disturbance_at: str) -> np.ndarray:
    """He from the disturbance response (NaN where it was not measured)."""
    with np.errstate(invalid="ignore"):
        return _he(h_ud, yc, disturbance_at)


def _he(h_ud: np.ndarray, yc: np.ndarray, disturbance_at: str) -> np.ndarray:
    if disturbance_at == "input":
        return -h_ud / (yc * (1.0 + h_ud))
    return -h_ud / (1.0 + h_ud * yc)


def combine(
    trials: Sequence[TrialLines], yc_of, disturbance_at: str, bins: np.ndarray | None = None
) -> PersonLines | None:
    """One person's paths at every line from their ``trials`` (of one plant; SPEC 12).

    Parameters
    ----------
    trials : sequence of TrialLines
        The person's trials to combine, all over windows of the same length and rate.
    yc_of : callable
        The plant's frequency response, of omega (rad/s).
    disturbance_at : str
        ``input`` or ``output``.
    bins : ndarray of int, optional
        The lines to report (default: every line of ``trials``).

    Returns
    -------
    PersonLines or None
        None where the trials measured no disturbance line (He unknown everywhere).
    """
    trials = [t for t in trials if t.problem is None]
    if not trials:
        return None
    first = trials[0]
    ur, ud = _condition_means(trials, "ur"), _condition_means(trials, "ud")
    if not ud:
        return None
    if bins is None:
        bins = np.array(sorted(set(ur) | set(ud)), dtype=np.int64)
    omega = first.omega(bins)
    yc = yc_of(omega)
    nan = complex(math.nan, math.nan)
    h_ur = np.array([np.mean(ur[b]) if b in ur else nan for b in bins.tolist()])
    h_ud = np.array([np.mean(ud[b]) if b in ud else nan for b in bins.tolist()])
    measured = np.array([b in ud for b in bins.tolist()])
    he = _feedback(h_ud, yc, disturbance_at)
    if not measured.all():
        he[~measured] = interpolate(omega[measured], he[measured], omega[~measured])
    ht = h_ur * (1.0 + he * yc) - he
    runs = []
    for i, b in enumerate(bins.tolist()):
        own = [t.h_ur[t.target.tolist().index(b)] for t in trials if b in t.target.tolist()]
        runs.append(np.abs((np.array(own) * (1.0 + he[i] * yc[i]) - he[i]) * yc[i]))
    count = {
        which: np.array(
            [sum(b in (t.target if which == "t" else t.disturbance).tolist() for t in trials) for b in bins]
        )
        for which in ("t", "d")
    }
    return PersonLines(omega, h_ur, h_ud, he, ht, yc, measured, runs, count["t"], count["d"])


def of_kinds(trials: Sequence[TrialLines], source: str) -> list[TrialLines]:
    """The trials a :data:`SOURCES` entry uses."""
    return [t for t in trials if t.kind in SOURCES[source]]


# --------------------------------------------------------------------------- the study's comparisons


@dataclass(frozen=True)
class Comparison:
    """A paired comparison across people (single-input against two-input estimates).

    ``ratio``: the median over the pairs of ``|H_single| / |H_two|`` with its range; ``phase``:
    the median wrapped phase difference (deg) with its range; ``p_magnitude`` and ``p_phase``:
    the Wilcoxon signed-rank test's two-sided p on the log-magnitude and phase differences
    (NaN for fewer than 2 pairs)."""

    response: str
    omega: float  # NaN: pooled over lines
    pairs: int
    ratio: float
    ratio_low: float
    ratio_high: float
    phase: float
    phase_low: float
    phase_high: float
    p_magnitude: float
    p_phase: float


#: Differences this small are rounding, not a difference (a test of them would rank noise).
TIE = 1e-9


def wilcoxon_p(x: np.ndarray) -> float:
    """The two-sided Wilcoxon signed-rank p of the differences ``x`` against 0 (NaN ones left
    out; differences below :data:`TIE` in magnitude are ties at 0, which the test drops); NaN
    where fewer than 2 remain."""
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x) & (np.abs(x) >= TIE)]
    if x.size < 2:
        return math.nan
    return float(stats.wilcoxon(x, alternative="two-sided").pvalue)


def _compared(response: str, omega: float, single: np.ndarray, two: np.ndarray) -> Comparison:
    with np.errstate(invalid="ignore"):  # NaN where a person did not measure the line
        log_ratio = np.log(np.abs(single)) - np.log(np.abs(two))
        phase = np.degrees(np.angle(single / two))  # wrapped to (-180, 180]
    ok = np.isfinite(log_ratio) & np.isfinite(phase)
    log_ratio, phase = log_ratio[ok], phase[ok]
    if not ok.any():
        nan = math.nan
        return Comparison(response, omega, 0, nan, nan, nan, nan, nan, nan, nan, nan)
    return Comparison(
        response,
        omega,
        int(ok.sum()),
        float(np.exp(np.median(log_ratio))),
        float(np.exp(log_ratio.min())),
        float(np.exp(log_ratio.max())),
        float(np.median(phase)),
        float(phase.min()),
        float(phase.max()),
        wilcoxon_p(log_ratio),
        wilcoxon_p(phase),
    )


def superposition(single: Sequence[PersonLines], two: Sequence[PersonLines]) -> list[Comparison]:
    """Does the response superpose (SPEC 12)? Per response (``U/R``, ``U/D``), per line and pooled
    over lines: each person's single-input estimate against their two-input one, paired across
    people (the i-th of ``single`` and ``two`` are one person's, on the same lines)."""
    if any(not np.array_equal(p.omega, single[0].omega) for p in (*single, *two)):
        raise ValueError("superposition: every person's estimates must be on the same lines")
    out = []
    for response, attr in (("U/R", "h_ur"), ("U/D", "h_ud")):
        s = np.array([getattr(p, attr) for p in single])
        t = np.array([getattr(p, attr) for p in two])
        if s.size == 0:
            continue
        for i, omega in enumerate(single[0].omega):
            out.append(_compared(response, float(omega), s[:, i], t[:, i]))
        out.append(_compared(response, math.nan, s.ravel(), t.ravel()))
    return out


@dataclass(frozen=True)
class Prediction:
    """u of one trial predicted by a model at the lines: ``RMS(u - u_hat) / RMS(u)`` over the
    window (means removed), for the feedback-only model (``Ht = 0``) and the feedback plus
    feedforward model, and the same counted at the trial's forcing lines only."""

    error_fb: float
    error_ff: float
    lines_fb: float
    lines_ff: float


def prediction(trial: TrialLines, model: PersonLines, bins: np.ndarray) -> Prediction:
    """Predict ``trial``'s u from its measured ft and e: ``U_hat = Ht Ft + He E`` at its forcing
    lines (``model``'s paths at ``bins``, which must hold them, Ht at every target line of the
    trial), nothing elsewhere (SPEC 12)."""
    lines = np.sort(np.concatenate([trial.target, trial.disturbance]))
    index = {b: i for i, b in enumerate(bins.tolist())}
    at = np.array([index[b] for b in lines.tolist()])
    s = trial.spectra
    errors = []
    ht_model = np.where(np.isin(lines, trial.target), model.ht[at], 0.0)  # no ft at a disturbance line
    if not np.all(np.isfinite(ht_model)):
        raise ValueError("prediction: the model has no Ht at some of the trial's target lines")
    for ht in (np.zeros(at.size), ht_model):
        u_hat = np.zeros_like(s["u"])
        u_hat[lines] = ht * s["ft"][lines] + model.he[at] * s["e"][lines]
        residual = s["u"].copy()
        residual[0] = 0.0
        residual -= u_hat
        u = s["u"].copy()
        u[0] = 0.0
        errors.append(
            (
                math.sqrt(_power(residual, trial.n) / _power(u, trial.n)),
                math.sqrt(np.sum(np.abs(residual[lines]) ** 2) / np.sum(np.abs(s["u"][lines]) ** 2)),
            )
        )
    (fb, fb_lines), (ff, ff_lines) = errors
    return Prediction(fb, ff, fb_lines, ff_lines)


def _power(spectrum: np.ndarray, n: int) -> float:
    """A real signal's energy from its rfft over ``n`` samples (Parseval, times n): each bin but DC
    and, for an even n, the Nyquist bin stands for two."""
    p = np.abs(spectrum) ** 2
    weight = np.full(p.size, 2.0)
    weight[0] = 1.0
    if n % 2 == 0:
        weight[-1] = 1.0
    return float(np.sum(weight * p))
