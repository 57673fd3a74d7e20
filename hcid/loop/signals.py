"""Forcing functions of the tracking task (SPEC sections 2 and 7): target and disturbance.

Pure functions of time. Time ``t`` is in s with ``t = 0`` at the start of the
measurement window that is kept; values are in rad. Each kind of forcing
function (:data:`FORCING`: multisine, segments, a file's column) gives its
values at every simulation sample with :func:`forcing`.
"""

from __future__ import annotations

import numpy as np

from hcid.config import FileSignal, Forcing, Multisine, Segments, Timing

__all__ = [
    "FORCING",
    "file_signal",
    "forcing",
    "forcing_frequencies",
    "multisine",
    "segments",
    "segments_in_period",
    "simulation_time",
]


def multisine(t: np.ndarray, spec: Multisine) -> np.ndarray:
    """Sum of sines ``f(t) = sum_i A_i sin(k_i wm (t + t0) + phi_i)``.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Time in s, 0 at the start of the kept measurement window. f is
        periodic in ``spec.base_period``, so negative times (the run-in) are valid.
    spec : Multisine
        Integer frequency multiples, amplitudes (rad) and phases (rad).

    Returns
    -------
    ndarray, shape (n,)
        f in rad.
    """
    t = np.asarray(t, dtype=np.float64)
    wm = 2.0 * np.pi / spec.base_period
    k = np.asarray(spec.k, dtype=np.float64)[:, None]
    amplitude = np.asarray(spec.amplitude)[:, None]
    phase = np.asarray(spec.phase)[:, None]
    return np.sum(amplitude * np.sin(k * wm * (t[None, :] + spec.time_offset) + phase), axis=0)


def segments_in_period(tau: np.ndarray, spec: Segments) -> np.ndarray:
    """Segments' value at time ``tau`` (s) after the start of the segments; 0 before them.

    A parabola segment ``p`` of duration T and step S accelerates at ``4 S / T**2``
    for T/2 and decelerates equally for T/2, so position and velocity are
    continuous; a ramp ``r`` moves at the constant velocity S / T (position
    continuous); a hold ``c`` keeps the level. After the last segment the
    signal holds its final level.

    Returns
    -------
    ndarray
        The signal in rad.
    """
    tau = np.asarray(tau, dtype=np.float64)
    out = np.zeros_like(tau)
    level = 0.0
    start = 0.0
    for seg in spec.segments:
        end = start + seg.duration
        inside = (tau >= start) & (tau < end)
        if seg.kind == "c":
            out[inside] = level
        else:
            step = seg.step * spec.gain
            x = tau[inside] - start
            if seg.kind == "r":
                rise = step * x / seg.duration
            else:
                half = seg.duration / 2.0
                accel = 4.0 * step / seg.duration**2
                rise = np.where(
                    x < half,
                    0.5 * accel * x**2,
                    step - 0.5 * accel * (seg.duration - x) ** 2,
                )
            out[inside] = level + rise
            level += step
        start = end
    out[tau >= start] = level
    out[tau < 0] = 0.0
    return out


def simulation_time(timing: Timing, ahead: int = 0) -> np.ndarray:
    """Time of every simulation sample (s), 0 at the start of the kept window.

    ``timing.periods`` periods of run-in plus window at ``timing.sim_rate``;
    the last ``timing.window_samples`` samples are the kept window (t >= 0).
    ``ahead``: that many samples more, past the last (what an anticipating feedforward reads).
    """
    n = timing.periods * timing.period_samples
    start = n - timing.window_samples
    return (np.arange(n + ahead) - start) / timing.sim_rate


def segments(timing: Timing, spec: Segments, ahead: int = 0) -> np.ndarray:
    """At every simulation sample (rad): each period is run-in (0) then the segments (``ahead``:
    samples past the last, the next period's)."""
    n = timing.periods * timing.period_samples
    run_in = round(timing.run_in * timing.sim_rate)
    in_period = np.arange(n + ahead) % timing.period_samples - run_in
    return segments_in_period(in_period / timing.sim_rate, spec)


def file_signal(timing: Timing, spec: FileSignal, ahead: int = 0) -> np.ndarray:
    """A file's column at every simulation sample (rad), its window repeated as one period.

    The ``timing.window`` seconds from ``spec.start`` are resampled from the file's
    rate to the simulation rate by the FFT method (exact for a signal periodic in
    the window and band-limited below both Nyquist frequencies) and repeated
    backwards over the run-in and earlier periods (and ``ahead`` samples past the last).
    """
    first = round(spec.start * spec.rate)
    window = spec.values[first : first + round(timing.window * spec.rate)]
    if window.size == timing.window_samples:
        one = window
    else:
        from scipy import signal as sps

        one = sps.resample(window, timing.window_samples)
    n = timing.periods * timing.period_samples
    return one[(np.arange(n + ahead) - (n - timing.window_samples)) % timing.window_samples]


#: Kinds of forcing function by their config type: ``f(timing, spec, ahead)`` at every simulation
#: sample and ``ahead`` samples past the last.
FORCING = {
    Multisine: lambda timing, spec, ahead: multisine(simulation_time(timing, ahead), spec),
    Segments: segments,
    FileSignal: file_signal,
}


def forcing(timing: Timing, spec: Forcing, ahead: int = 0) -> np.ndarray:
    """A forcing function at every simulation sample (rad), whatever its kind, and ``ahead``
    samples past the last (as the kind continues: a multisine or a file's window periodically,
    segments into the next period's run-in)."""
    return FORCING[type(spec)](timing, spec, ahead)


def forcing_frequencies(spec: Forcing) -> np.ndarray | None:
    """The frequencies (rad/s) of a multisine; None for the other kinds (broadband or unknown)."""
    if isinstance(spec, Multisine):
        return 2 * np.pi / spec.base_period * np.asarray(spec.k, dtype=np.float64)
    return None
