"""Forcing functions against the figures of SPEC section 2."""

import numpy as np
import pytest

from hcid import signals


def _window(config):
    t = signals.simulation_time(config.timing)
    keep = t >= 0
    return t, keep


def test_disturbance_rms(paper_config):
    # SPEC 2: RMS(fd) = 1.2247 deg over the 81.92 s window.
    t, keep = _window(paper_config)
    fd = signals.disturbance(t[keep], paper_config.disturbance)
    assert np.degrees(np.sqrt(np.mean(fd**2))) == pytest.approx(1.2247, abs=5e-5)


def test_disturbance_is_periodic_in_base_period(paper_config):
    # SPEC 2: fd is periodic in 81.92 s, so the run-in values repeat the window's.
    t = np.linspace(-50.0, 0.0, 101)
    d = paper_config.disturbance
    np.testing.assert_allclose(
        signals.disturbance(t, d), signals.disturbance(t + d.base_period, d), atol=1e-12
    )


def test_target_range_and_rms(paper_config):
    # SPEC 2: ft swings between +20 and -20 deg, RMS 16.07 deg over the window.
    t, keep = _window(paper_config)
    ft = np.degrees(signals.target(paper_config.timing, paper_config.target)[keep])
    assert ft.max() == pytest.approx(20.0, abs=1e-9)
    assert ft.min() == pytest.approx(-20.0, abs=1e-9)
    assert np.sqrt(np.mean(ft**2)) == pytest.approx(16.07, abs=5e-3)


def test_target_zero_in_run_in_and_tail(paper_config):
    # SPEC 2: ft = 0 in the run-in and after the segments (79.98 s) up to 81.92 s.
    timing = paper_config.timing
    t = signals.simulation_time(timing)
    ft = signals.target(timing, paper_config.target)
    assert np.all(ft[(t < 0) & (t > -timing.run_in)] == 0.0)
    assert np.all(ft[t >= 79.98 + 1e-9] == 0.0)


def test_parabola_position_and_velocity_continuous(paper_config):
    # Constant acceleration 4S/T^2 for T/2 then deceleration: position and velocity
    # are continuous; a jump would show as a finite difference far above a*dt.
    tau = np.arange(0.0, 81.92, 1e-4)
    ft = signals.target_in_period(tau, paper_config.target)
    velocity = np.diff(ft) / 1e-4
    accel_max = max(  # |a| = 4 |S| / T^2 per parabola segment
        4 * abs(seg.step) * paper_config.target.gain / seg.duration**2
        for seg in paper_config.target.segments
        if seg.kind == "p"
    )
    # Position: no jump larger than the peak velocity times the step.
    peak_velocity = max(
        2 * abs(seg.step) * paper_config.target.gain / seg.duration
        for seg in paper_config.target.segments
        if seg.kind == "p"
    )
    assert np.max(np.abs(np.diff(ft))) <= peak_velocity * 1e-4 * 1.001
    assert np.max(np.abs(np.diff(velocity))) <= accel_max * 1e-4 * 1.01
    # Peak velocity of a step S over T is 2|S|/T (at the midpoint).
    peak = max(
        2 * abs(seg.step) * paper_config.target.gain / seg.duration
        for seg in paper_config.target.segments
        if seg.kind == "p"
    )
    assert np.max(np.abs(velocity)) == pytest.approx(peak, rel=1e-3)
