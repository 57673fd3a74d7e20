"""Forcing functions against the figures of SPEC section 2."""

import numpy as np
import pytest

from hcid.loop import signals


def _window(config):
    t = signals.simulation_time(config.timing)
    keep = t >= 0
    return t, keep


def test_disturbance_rms(paper_config):
    # SPEC 2: RMS(fd) = 1.2247 deg over the 81.92 s window.
    t, keep = _window(paper_config)
    fd = signals.multisine(t[keep], paper_config.disturbance)
    assert np.degrees(np.sqrt(np.mean(fd**2))) == pytest.approx(1.2247, abs=5e-5)


def test_disturbance_is_periodic_in_base_period(paper_config):
    # SPEC 2: fd is periodic in 81.92 s, so the run-in values repeat the window's.
    t = np.linspace(-50.0, 0.0, 101)
    d = paper_config.disturbance
    np.testing.assert_allclose(signals.multisine(t, d), signals.multisine(t + d.base_period, d), atol=1e-12)


def test_target_range_and_rms(paper_config):
    # SPEC 2: ft swings between +20 and -20 deg, RMS 16.07 deg over the window.
    t, keep = _window(paper_config)
    ft = np.degrees(signals.segments(paper_config.timing, paper_config.target)[keep])
    assert ft.max() == pytest.approx(20.0, abs=1e-9)
    assert ft.min() == pytest.approx(-20.0, abs=1e-9)
    assert np.sqrt(np.mean(ft**2)) == pytest.approx(16.07, abs=5e-3)


def test_target_zero_in_run_in_and_tail(paper_config):
    # SPEC 2: ft = 0 in the run-in and after the segments (79.98 s) up to 81.92 s.
    timing = paper_config.timing
    t = signals.simulation_time(timing)
    ft = signals.segments(timing, paper_config.target)
    assert np.all(ft[(t < 0) & (t > -timing.run_in)] == 0.0)
    assert np.all(ft[t >= 79.98 + 1e-9] == 0.0)


def test_parabola_position_and_velocity_continuous(paper_config):
    # Constant acceleration 4S/T^2 for T/2 then deceleration: position and velocity
    # are continuous; a jump would show as a finite difference far above a*dt.
    tau = np.arange(0.0, 81.92, 1e-4)
    ft = signals.segments_in_period(tau, paper_config.target)
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


# --------------------------------------------------------------------------- other forcing functions (SPEC 7)


def test_ramp_and_parabola_segments_levels_and_continuity():
    # Exact values: a ramp 'r' of step S over T moves at S/T from one level to the next;
    # a parabola reaches S/2 at T/2; holds keep the level; after the last segment the
    # final level holds. Position is continuous at every boundary (no jump above v dt).
    from hcid.config import Segment, Segments

    spec = Segments(
        gain=0.5,
        segments=(
            Segment("c", 1.0, 0.0),
            Segment("r", 2.0, 1.0),
            Segment("c", 1.0, 0.0),
            Segment("p", 4.0, -2.0),
        ),
    )
    tau = np.array([-1.0, 0.5, 1.0, 2.0, 2.999999, 3.5, 4.0, 6.0, 8.0, 9.0])
    got = signals.segments_in_period(tau, spec)
    # levels: 0 until 1 s; ramp 0 -> 0.5 over 1..3 s; hold 0.5; parabola 0.5 -> -0.5 over 4..8 s.
    expected = [0.0, 0.0, 0.0, 0.25, 0.5 - 0.25e-6, 0.5, 0.5, 0.0, -0.5, -0.5]
    np.testing.assert_allclose(got, expected, atol=1e-12)
    dt = 1e-4
    fine = signals.segments_in_period(np.arange(0.0, 9.0, dt), spec)
    v_max = max(0.5 / 2.0, 2 * 1.0 / 4.0)  # ramp S/T, parabola peak 2|S|/T (in rad/s)
    assert np.max(np.abs(np.diff(fine))) <= v_max * dt * 1.001
    # The ramp's velocity is constant inside it: S/T = 0.25 rad/s.
    inside = np.diff(fine[int(1.1 / dt) : int(2.9 / dt)]) / dt
    np.testing.assert_allclose(inside, 0.25, rtol=1e-6)


def test_file_signal_repeats_its_window_at_the_simulation_rate(tmp_path):
    # A multisine written to a CSV at 50 Hz (one 20 s period after a 2 s lead-in) and read as a
    # 'file' forcing function must equal the formula at 100 Hz over every period, run-in included
    # (FFT resampling is exact for a periodic band-limited signal).
    from hcid.config import FileSignal, Multisine, Timing
    from hcid.io.measured import read_signal

    ms = Multisine(
        base_period=20.0, time_offset=0.0, k=(1, 3, 7), amplitude=(0.1, 0.05, 0.02), phase=(0, 1, 2)
    )
    t50 = np.arange(0, 25.0, 1 / 50) - 2.0
    path = tmp_path / "f.csv"
    path.write_text(
        "# a comment line from the logger\nt,target\n"
        + "".join(f"{a:.17g},{b:.17g}\n" for a, b in zip(t50, signals.multisine(t50, ms), strict=True))
    )
    spec = FileSignal(str(path), "target", 50.0, 2.0, values=read_signal(path, "target"))
    timing = Timing(sim_rate=100.0, output_rate=25.0, run_in=3.0, window=20.0, periods=2)
    got = signals.forcing(timing, spec)
    np.testing.assert_allclose(got, signals.multisine(signals.simulation_time(timing), ms), atol=1e-12)


def test_forcing_functions_from_the_example_data_file():
    # configs/integrator_example: the target and disturbance read back from the synthetic data
    # file (trial 1, the 40 s after the 5 s lead-in, 60 Hz) are the config's multisines, which
    # made them (written with 9 significant digits; FFT resampling 60 -> 100 Hz is exact for
    # them): calibrate-w can simulate with the measured file's own forcing functions.
    import dataclasses

    from hcid.assembly.resolve import load_config, parse_config, read_yaml

    from .conftest import ROOT

    path = ROOT / "configs" / "integrator_example.yaml"
    config = load_config(path)
    raw = read_yaml(path)
    for name, column in (("target", "target"), ("disturbance", "disturbance")):
        raw["signals"][name] = {
            "kind": "file",
            "path": "integrator_example/trials_synthetic.csv",
            "column": column,
            "rate": 60.0,
            "start": 5.0,
            "run": 1,
            "run_column": "trial",
        }
    from_file = parse_config(raw, "x", path.parent)
    timing = dataclasses.replace(config.timing, periods=1)
    for name in ("target", "disturbance"):
        want = signals.forcing(timing, getattr(config, name))
        got = signals.forcing(timing, getattr(from_file, name))
        np.testing.assert_allclose(got, want, atol=1e-8 * np.max(np.abs(want)) + 1e-9)
