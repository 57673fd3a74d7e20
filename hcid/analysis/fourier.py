"""Model-free (Fourier-coefficient) estimates of the HC's two paths (SPEC 10; pure numerical core).

With multisine forcing functions on disjoint frequency sets ``W_t`` (target) and
``W_d`` (disturbance), both over a whole number of periods of the window, and
``U, E, Ft`` the DFT coefficients of the window:

- at ``w in W_d`` ft has no power, so ``u = Hft ft + He e`` gives ``He(w) = U / E``;
- at ``w in W_t``, ``He(w)`` is interpolated from the neighbouring disturbance
  frequencies (linearly in log-frequency, on magnitude in dB and on unwrapped
  phase; held at the ends), then ``Ht(w) = (U - He E) / Ft`` (van Paassen and
  Mulder's two-loop method).

Across runs that share the forcing functions (or have them with the sign flipped,
whose coefficients are flipped back first), the coefficients are averaged before
dividing (the remnant's, uncorrelated with the forcing functions, averages out); a
DFT over a window of P whole periods is already the average over its periods.
Per-run estimates give the spread.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from hcid.errors import DataError

__all__ = [
    "ABSENT",
    "NEIGHBOURS",
    "PLANT_MISMATCH_LIMIT",
    "FCEstimate",
    "Inversion",
    "InversionRuns",
    "absent_inputs",
    "ForcingLines",
    "fc_estimate",
    "forcing_lines",
    "interpolate",
    "is_other_plant",
    "line_bins",
    "off_line_share",
    "plant_mismatch",
]

#: A forcing function is a line spectrum over the window when its bins, sorted by power, fall
#: into lines and the rest with a gap of at least :data:`LINE_GAP` (power ratio) between them,
#: and the lines hold at least :data:`LINE_SHARE` of its power (DC left out). A multisine over
#: whole periods has a gap of 1e20 and more; a recorded and resampled one, its noise floor (1e3
#: below the weakest line in the example lab study's 60 Hz files resampled to 20 Hz).
LINE_GAP = 100.0
LINE_SHARE = 0.999


#: Bins without forcing beside each line whose mean power is the remnant's variance there:
#: 6 gives each estimate 12 real degrees of freedom while spanning +-3 bins (0.47 rad/s for a
#: 40 s record), over which a person's remnant spectrum changes little.
NEIGHBOURS = 6


@dataclass(frozen=True)
class ForcingLines:
    """The DFT bins of the forcing functions over a window of ``n`` samples at ``rate`` Hz.

    ``target`` and ``disturbance`` hold the bin indices (frequency ``2 pi k rate / n``);
    ``problem`` says why no Fourier-coefficient estimate is possible (None when it is).
    """

    n: int
    rate: float
    target: np.ndarray
    disturbance: np.ndarray
    problem: str | None = None

    @property
    def inner(self) -> np.ndarray:
        """Every bin of the window but DC and the Nyquist bin: 1 .. (n - 1) // 2."""
        return np.arange(1, (self.n - 1) // 2 + 1)

    def omega(self, bins: np.ndarray) -> np.ndarray:
        """Frequencies (rad/s) of ``bins``."""
        return 2.0 * np.pi * np.asarray(bins, dtype=np.float64) * self.rate / self.n


def _lines(x: np.ndarray) -> tuple[np.ndarray, float]:
    """The bins above the widest power gap (if at least LINE_GAP) and their share of the power.

    Without such a gap (a broadband signal), no bins and a share of 0.
    """
    power = np.abs(np.fft.rfft(x - np.mean(x))) ** 2
    power[0] = 0.0
    total = float(power.sum())
    if total == 0.0:
        return np.zeros(0, dtype=np.int64), 0.0
    order = np.argsort(power)[::-1]
    ranked = power[order]
    floor = np.maximum(ranked[1:], 1e-300 * ranked[0])
    ratios = ranked[:-1] / floor
    top = int(np.argmax(ratios[: max(1, ranked.size // 2)]))  # lines are the minority of the bins
    if ratios[top] < LINE_GAP:
        return np.zeros(0, dtype=np.int64), 0.0
    bins = np.sort(order[: top + 1])
    return bins, float(power[bins].sum() / total)


def line_bins(x: np.ndarray) -> np.ndarray:
    """The bins of ``x``'s lines over the window where it is a sum of sines over whole periods
    (its lines hold :data:`LINE_SHARE` of its power), else none."""
    bins, share = _lines(np.asarray(x, dtype=np.float64))
    return bins if share >= LINE_SHARE else np.zeros(0, dtype=np.int64)


#: An input is absent from a trial when its power at every forcing line is below this share of
#: the other input's strongest line, or it is constant (SPEC 12): a file's zeros, not a weak sine.
ABSENT = 1e-6


def absent_inputs(ft: np.ndarray, fd: np.ndarray) -> tuple[bool, bool]:
    """Whether the target and the disturbance are absent over this window (:data:`ABSENT`)."""
    ft, fd = np.asarray(ft, dtype=np.float64), np.asarray(fd, dtype=np.float64)
    lines = np.union1d(line_bins(ft), line_bins(fd))
    power = [np.abs(np.fft.rfft(x)) ** 2 for x in (ft, fd)]

    def absent(mine: np.ndarray, other: np.ndarray, x: np.ndarray) -> bool:
        below = lines.size > 0 and bool(np.all(mine[lines] < ABSENT * other[lines].max()))
        return below or not np.any(np.diff(x))

    return absent(power[0], power[1], ft), absent(power[1], power[0], fd)


def forcing_lines(ft: np.ndarray, fd: np.ndarray, rate: float, one_input: bool = False) -> ForcingLines:
    """Find the forcing functions' lines in one window of ``ft`` and ``fd`` (same length).

    Each must be a line spectrum over the window (a multisine over whole periods: see
    :data:`LINE_GAP`) and the two sets disjoint; otherwise ``problem`` says which
    condition fails and the sets are empty. With ``one_input``, one of them may be absent
    (:func:`absent_inputs`: a single-input trial, SPEC 12): its set is then empty.

    Examples
    --------
    >>> t = np.arange(400) / 10.0                       # 40 s at 10 Hz: bins every 0.025 Hz
    >>> ft = np.sin(2 * np.pi * 0.05 * t)                # bin 2
    >>> fd = np.sin(2 * np.pi * 0.075 * t) + np.sin(2 * np.pi * 0.2 * t)   # bins 3 and 8
    >>> lines = forcing_lines(ft, fd, 10.0)
    >>> lines.target.tolist(), lines.disturbance.tolist(), lines.problem
    ([2], [3, 8], None)
    """
    ft, fd = np.asarray(ft, dtype=np.float64), np.asarray(fd, dtype=np.float64)
    n = ft.size
    empty = np.zeros(0, dtype=np.int64)
    target, share_t = _lines(ft)
    dist, share_d = _lines(fd)
    problem = None
    no_target, no_disturbance = absent_inputs(ft, fd) if one_input else (False, False)
    single = no_target != no_disturbance  # one input absent (SPEC 12): the other's lines alone
    if single:
        target, share_t = (empty, 1.0) if no_target else (target, share_t)
        dist, share_d = (empty, 1.0) if no_disturbance else (dist, share_d)
    if not single and not np.any(np.diff(ft)):
        problem = "the target is constant over the window"
    elif not single and not np.any(np.diff(fd)):
        problem = "the disturbance is constant over the window"
    elif share_t < LINE_SHARE:
        problem = "the target is not a sum of sines over whole periods of the window"
    elif share_d < LINE_SHARE:
        problem = "the disturbance is not a sum of sines over whole periods of the window"
    elif np.intersect1d(target, dist).size:
        shared = np.intersect1d(target, dist)
        problem = (
            f"target and disturbance share {shared.size} frequencies (e.g. "
            f"{2 * np.pi * shared[0] * rate / n:.3g} rad/s): the paths cannot be told apart there"
        )
    if problem is not None:
        return ForcingLines(n, float(rate), empty, empty, problem)
    return ForcingLines(n, float(rate), target, dist)


def free_neighbours(lines: ForcingLines, count: int = NEIGHBOURS) -> tuple[np.ndarray, np.ndarray]:
    """The lines' bins (sorted) and, for each, its ``count`` nearest bins without forcing (nearest
    first, the lower first at equal distance; DC and the Nyquist bin left out), shape (L, count).

    Raises
    ------
    DataError
        If the window has fewer than ``count`` bins without forcing.
    """
    bins = np.sort(np.concatenate([lines.target, lines.disturbance]))
    free = np.setdiff1d(lines.inner, bins)
    if free.size < count:
        raise DataError(f"the record has {free.size} bins without forcing; {count} are needed")
    return bins, np.array([free[np.lexsort((free, np.abs(free - k)))[:count]] for k in bins])


def off_line_share(u: np.ndarray, ft: np.ndarray, fd: np.ndarray, rate: float) -> float:
    """The remnant's share of u's variance in the closed loop, from the data alone: u's power off
    the forcing lines, plus at each line's bin the mean power of its :data:`NEIGHBOURS` nearest bins
    without forcing (the remnant's part there), over u's variance (DC and the Nyquist bin left
    out); NaN where the forcing functions have no lines (:func:`forcing_lines`).

    Examples
    --------
    >>> t = np.arange(400) / 10.0
    >>> ft, fd = np.sin(2 * np.pi * 0.05 * t), np.sin(2 * np.pi * 0.075 * t)
    >>> noise = np.sin(2 * np.pi * 0.5 * t)        # bin 20, no forcing there: as strong as fd's
    >>> round(off_line_share(ft + fd + noise, ft, fd, 10.0), 6)
    0.333333
    """
    lines = forcing_lines(ft, fd, rate)
    if lines.problem is not None:
        return math.nan
    u = np.asarray(u, dtype=np.float64)
    power = np.abs(np.fft.rfft(u - u.mean())) ** 2
    bins, near = free_neighbours(lines)
    off = power[np.setdiff1d(lines.inner, bins)].sum()
    return float(min(1.0, (off + power[near].mean(axis=1).sum()) / power[lines.inner].sum()))


#: The most of a run's theta = ft - e at its forcing lines that the configured plant may leave
#: unexplained (RMS share, :func:`plant_mismatch`); it accepts a plant gain 0.7 to 1.3 times the
#: true one, and the measurements behind it are in docs/measured-studies.md.
PLANT_MISMATCH_LIMIT = 0.3


def is_other_plant(mismatch: float | None) -> bool:
    """Whether a :func:`plant_mismatch` says the record is of another plant: above
    :data:`PLANT_MISMATCH_LIMIT`, or NaN (theta and the plant's output both 0 at every line is no
    agreement either); None (no lines to check at) is not."""
    return mismatch is not None and not mismatch <= PLANT_MISMATCH_LIMIT


def plant_mismatch(
    record: dict[str, np.ndarray],
    rate: float,
    num: Sequence[float],
    den: Sequence[float],
    disturbance_at: str,
) -> float | None:
    """How far a record is from the configured plant: the share (RMS) of ``theta = ft - e`` at the
    forcing lines that ``Yc = num / den`` does not explain, ``|Theta - Yc (U + Fd)|`` over
    ``|Theta|`` (``Yc U + Fd`` for a disturbance at the output); None where the forcing functions
    have no lines (:func:`forcing_lines`).

    The plant is deterministic (the remnant enters through u, which is measured), so a record of
    the configured plant leaves only recording and resampling error, and the drift its
    integrators make of a mean input (taken out: a polynomial in t of their order, fitted)
    (docs/measured-studies.md has the figures on the example studies and the shared recordings).
    A single-input record is checked at its input's lines.

    Examples
    --------
    >>> t = np.arange(400) / 10.0
    >>> ft, fd = np.sin(2 * np.pi * 0.05 * t), np.sin(2 * np.pi * 0.075 * t)
    >>> w = 2 * np.pi * 0.075                      # u = 0 and theta = Yc fd with Yc = 1/s:
    >>> theta = -np.cos(w * t) / w + 1 / w         # x' = fd from rest
    >>> rec = {"ft": ft, "fd": fd, "e": ft - theta, "u": np.zeros(400)}
    >>> round(plant_mismatch(rec, 10.0, [1.0], [1.0, 0.0], "input"), 6)
    0.0
    >>> round(plant_mismatch(rec, 10.0, [2.0], [1.0, 0.0], "input"), 3)   # twice the gain
    1.0
    """
    lines = forcing_lines(record["ft"], record["fd"], rate, one_input=True)
    if lines.problem is not None:
        return None
    bins = np.concatenate([lines.target, lines.disturbance])
    ft, fd, e, u = (
        np.fft.rfft(np.asarray(record[k], dtype=np.float64))[bins] for k in ("ft", "fd", "e", "u")
    )
    s = 1j * lines.omega(bins)
    den = np.trim_zeros(np.asarray(den, dtype=np.float64), "f")
    yc = np.polyval(np.asarray(num, dtype=np.float64), s) / np.polyval(den, s)
    theta = ft - e
    explained = yc * (u + fd) if disturbance_at == "input" else yc * u + fd
    missed = theta - explained
    # A plant with integrators (poles at 0) turns a mean input and its initial state into a drift,
    # a polynomial in t up to their number, which is not periodic and leaks into the lines: taken
    # out by least squares (real coefficients; its spectrum, falling as 1/k per order with a fixed
    # phase, cannot stand for another plant's gain or phase). A person's offset on the CPHS `so`
    # plant left 42% before (a ramp of the mean of u + fd), 20% after.
    integrators = den.size - np.trim_zeros(den, "b").size
    order = min(integrators, max(0, bins.size - 1))
    if order:
        t = np.arange(np.asarray(record["u"]).size) / rate
        drift = np.array([np.fft.rfft(t**p)[bins] for p in range(1, order + 1)]).T
        a = np.vstack([drift.real, drift.imag])
        c, *_ = np.linalg.lstsq(a, np.concatenate([missed.real, missed.imag]), rcond=None)
        missed = missed - drift @ c
    return float(np.sqrt(np.sum(np.abs(missed) ** 2) / np.sum(np.abs(theta) ** 2)))


class Inversion(NamedTuple):
    """``Ht Yc`` at the target lines (:meth:`FCEstimate.inversion`): the runs' average's magnitude
    (linear) and phase (deg), and their sd across runs."""

    magnitude: np.ndarray
    phase_deg: np.ndarray
    sd: np.ndarray
    sd_deg: np.ndarray


class InversionRuns(NamedTuple):
    """The runs' own ``|Ht Yc|`` at the target lines (:meth:`FCEstimate.inversion_runs`)."""

    median: np.ndarray
    q25: np.ndarray
    q75: np.ndarray


@dataclass(frozen=True)
class FCEstimate:
    """Fourier-coefficient estimates of He (at the disturbance lines) and Ht (at the target lines).

    Attributes
    ----------
    omega_e, omega_t : ndarray
        Frequencies (rad/s) of the disturbance and target lines.
    he, ht : ndarray of complex
        Averaged over runs (coefficients averaged before dividing).
    he_runs, ht_runs : ndarray of complex, shape (n_runs, n_lines)
        Per run.
    he_at_t : ndarray of complex
        He interpolated at the target lines (what ``ht`` used).
    extrapolated : ndarray of bool
        Target lines outside the disturbance lines' range (He held, not interpolated).
    """

    omega_e: np.ndarray
    omega_t: np.ndarray
    he: np.ndarray
    ht: np.ndarray
    he_runs: np.ndarray
    ht_runs: np.ndarray
    he_at_t: np.ndarray
    extrapolated: np.ndarray

    def spread(self, which: str) -> tuple[np.ndarray, np.ndarray]:
        """Across runs, per line: sd of the magnitude (dB) and of the phase (deg, unwrapped about
        the mean), NaN for a single run."""
        runs, mean = (self.he_runs, self.he) if which == "e" else (self.ht_runs, self.ht)
        if runs.shape[0] < 2:
            nan = np.full(mean.size, np.nan)
            return nan, nan
        db = 20.0 * np.log10(np.abs(runs))
        phase = np.degrees(np.angle(runs / mean))
        return np.std(db, axis=0, ddof=1), np.std(phase, axis=0, ddof=1)

    def inversion(self, yc: np.ndarray) -> Inversion:
        """Model inversion ``Ht Yc`` at the target lines (SPEC 11; 1 is the plant's exact inverse),
        with ``yc`` the plant's response there: magnitude (linear) and phase (deg) of the runs'
        average, and their sd across runs (phase unwrapped about the average; NaN for one run)."""
        mean = self.ht * yc
        runs = self.ht_runs * yc
        if runs.shape[0] < 2:
            nan = np.full(mean.size, np.nan)
            return Inversion(np.abs(mean), np.degrees(np.angle(mean)), nan, nan)
        return Inversion(
            np.abs(mean),
            np.degrees(np.angle(mean)),
            np.std(np.abs(runs), axis=0, ddof=1),
            np.std(np.degrees(np.angle(runs / mean)), axis=0, ddof=1),
        )

    def inversion_runs(self, yc: np.ndarray) -> InversionRuns:
        """The runs' own ``|Ht Yc|`` at the target lines: their median and quartiles (25%, 75%).

        Beside :meth:`inversion`'s coefficient average: where the runs' phases scatter (large
        remnant, or people who differ) the average's magnitude falls below the runs' own, which
        are in turn biased upward by the remnant in each run's coefficients; both are shown."""
        runs = np.abs(self.ht_runs * yc)
        q25, median, q75 = np.percentile(runs, [25.0, 50.0, 75.0], axis=0)
        return InversionRuns(median, q25, q75)


def interpolate(omega_from: np.ndarray, h: np.ndarray, omega_to: np.ndarray) -> np.ndarray:
    """He between the disturbance lines (SPEC 10): linear in log-frequency, on magnitude (dB) and
    unwrapped phase; held beyond the ends."""
    x = np.log(omega_from)
    db = np.interp(np.log(omega_to), x, 20.0 * np.log10(np.abs(h)))
    phase = np.interp(np.log(omega_to), x, np.unwrap(np.angle(h)))
    return 10.0 ** (db / 20.0) * np.exp(1j * phase)


def _paths(lines: ForcingLines, u, e, ft) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(He at W_d, Ht at W_t, He at W_t) from DFT coefficients (arrays over all bins)."""
    he = u[lines.disturbance] / e[lines.disturbance]
    omega_e, omega_t = lines.omega(lines.disturbance), lines.omega(lines.target)
    he_t = interpolate(omega_e, he, omega_t)
    ht = (u[lines.target] - he_t * e[lines.target]) / ft[lines.target]
    return he, ht, he_t


def fc_estimate(
    runs: Sequence[dict[str, np.ndarray]], rate: float, rows: slice, lines: ForcingLines | None = None
) -> FCEstimate:
    """Fourier-coefficient estimates of both paths from runs that share their forcing functions.

    Parameters
    ----------
    runs : sequence of mapping
        ``ft`` (unshifted), ``fd``, ``e``, ``u`` (rad) per run, equal lengths.
    rate : float
        Sample rate (Hz).
    rows : slice
        The window: a whole number of the forcing functions' periods.
    lines : ForcingLines, optional
        The forcing lines; found from the first run's ft and fd over ``rows`` when not given.

    Raises
    ------
    DataError
        If the design allows no estimate (``lines.problem``), the runs' forcing functions
        differ over the window (other than by their sign), or e has no power at a disturbance line.
    """
    if not runs:
        raise DataError("no runs for a Fourier-coefficient estimate")
    window = [{k: np.asarray(r[k], dtype=np.float64)[rows] for k in ("ft", "fd", "e", "u")} for r in runs]
    if lines is None:
        lines = forcing_lines(window[0]["ft"], window[0]["fd"], rate)
    if lines.problem is not None:
        raise DataError(f"no Fourier-coefficient estimate: {lines.problem}")
    spectra = [{k: np.fft.rfft(w[k]) for k in w} for w in window]
    reference = spectra[0]

    def same(s, sign) -> bool:
        return all(
            np.allclose(
                sign * s[k][bins], reference[k][bins], rtol=1e-6, atol=1e-12 * np.abs(reference[k]).max()
            )
            for k, bins in (("ft", lines.target), ("fd", lines.disturbance))
        )

    for i, s in enumerate(spectra[1:], start=2):
        if same(s, 1.0):
            continue
        if not same(s, -1.0):
            raise DataError(
                f"run {i} of the set has other forcing functions than run 1 (nor the same with their "
                "sign flipped): the runs' coefficients cannot be averaged"
            )
        # The same forcing functions with their sign flipped (a common design): a linear loop's
        # coefficients flip with them, so the run's are flipped back before averaging.
        for k in s:
            s[k] = -s[k]
    if any(np.any(np.abs(s["e"][lines.disturbance]) == 0) for s in spectra):
        raise DataError("e has no power at a disturbance frequency: He cannot be estimated there")
    per_run = [_paths(lines, s["u"], s["e"], s["ft"]) for s in spectra]
    mean = {k: np.mean([s[k] for s in spectra], axis=0) for k in ("u", "e", "ft")}
    he, ht, he_t = _paths(lines, mean["u"], mean["e"], mean["ft"])
    omega_e, omega_t = lines.omega(lines.disturbance), lines.omega(lines.target)
    return FCEstimate(
        omega_e=omega_e,
        omega_t=omega_t,
        he=he,
        ht=ht,
        he_runs=np.array([p[0] for p in per_run]),
        ht_runs=np.array([p[1] for p in per_run]),
        he_at_t=he_t,
        extrapolated=(omega_t < omega_e.min()) | (omega_t > omega_e.max()),
    )
