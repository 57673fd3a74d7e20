"""Forcing functions of the tracking task (SPEC section 2): target and disturbance.

Pure functions of time. Time ``t`` is in s with ``t = 0`` at the start of the
measurement window that is kept; values are in rad.
"""

from __future__ import annotations

import numpy as np

from hcid.config import Disturbance, Target, Timing

__all__ = ["disturbance", "target", "target_in_period", "simulation_time"]


def disturbance(t: np.ndarray, spec: Disturbance) -> np.ndarray:
    """Multisine disturbance ``fd(t) = sum_i A_i sin(k_i wm (t + t0) + phi_i)``.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Time in s, 0 at the start of the kept measurement window. fd is
        periodic in ``spec.base_period``, so negative times (the run-in) are valid.
    spec : Disturbance
        Integer frequency multiples, amplitudes (rad) and phases (rad).

    Returns
    -------
    ndarray, shape (n,)
        fd in rad.
    """
    t = np.asarray(t, dtype=np.float64)
    wm = 2.0 * np.pi / spec.base_period
    k = np.asarray(spec.k, dtype=np.float64)[:, None]
    amplitude = np.asarray(spec.amplitude)[:, None]
    phase = np.asarray(spec.phase)[:, None]
    return np.sum(amplitude * np.sin(k * wm * (t[None, :] + spec.time_offset) + phase), axis=0)


def target_in_period(tau: np.ndarray, spec: Target) -> np.ndarray:
    """Target ft at time ``tau`` (s) after the start of the segments; 0 before them.

    A parabola segment of duration T and step S accelerates at ``4 S / T**2``
    for T/2 and decelerates equally for T/2, so position and velocity are
    continuous. After the last segment ft holds its final level.

    Returns
    -------
    ndarray
        ft in rad.
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
            half = seg.duration / 2.0
            accel = 4.0 * step / seg.duration**2
            x = tau[inside] - start
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


def simulation_time(timing: Timing) -> np.ndarray:
    """Time of every simulation sample (s), 0 at the start of the kept window.

    ``timing.periods`` periods of run-in plus window at ``timing.sim_rate``;
    the last ``timing.window_samples`` samples are the kept window (t >= 0).
    """
    n = timing.periods * timing.period_samples
    start = n - timing.window_samples
    return (np.arange(n) - start) / timing.sim_rate


def target(timing: Timing, spec: Target) -> np.ndarray:
    """ft at every simulation sample (rad): each period is run-in (ft = 0) then the segments."""
    n = timing.periods * timing.period_samples
    run_in = round(timing.run_in * timing.sim_rate)
    in_period = np.arange(n) % timing.period_samples - run_in
    return target_in_period(in_period / timing.sim_rate, spec)
