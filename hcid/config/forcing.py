"""The ``signals`` and ``timing`` sections: forcing functions (SPEC 2 and 7) and the simulation's timing.

A forcing function of kind ``file`` is described here and read by :mod:`hcid.assembly.resolve`;
:func:`check_forcing_values` checks its values once read.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from hcid.config._checks import LIMITS, Section, fmt, integer, number_list
from hcid.config.types import FileSignal, Forcing, HCModel, Multisine, Segment, Segments, Timing
from hcid.errors import ConfigError

__all__ = [
    "FORCING_KINDS",
    "check_against_timing",
    "check_forcing_values",
    "signals_section",
    "timing_section",
]


def _multisine(s: Section) -> Multisine:
    k = s.get("k")
    if not isinstance(k, list) or not k:
        raise ConfigError(f"{s.key('k')}: must be a non-empty list of integers, got {fmt(k)}")
    k_int = tuple(integer(v, f"{s.key('k')}[{i}]", 1, 100_000) for i, v in enumerate(k))
    return Multisine(
        base_period=s.number("base_period", 0.0, 1e5, open_lo=True),
        time_offset=s.number("time_offset", -1e5, 1e5, 0.0),
        k=k_int,
        amplitude=number_list(s, "amplitude", len(k_int)),
        phase=number_list(s, "phase", len(k_int)),
    )


def _segment(path: str, i: int, seg: Any) -> Segment:
    key = f"{path}.segments[{i}]"
    ok = (
        isinstance(seg, list)
        and len(seg) == 3
        and seg[0] in ("c", "p", "r")
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in seg[1:])
        and all(math.isfinite(v) for v in seg[1:])
        and seg[1] > 0
    )
    if not ok:
        raise ConfigError(f"{key}: must be [c|p|r, seconds > 0, step], got {fmt(seg)}")
    if seg[0] == "c" and seg[2] != 0:
        raise ConfigError(f"{key}: a hold segment 'c' must have step 0, got {seg[2]}")
    return Segment(seg[0], float(seg[1]), float(seg[2]))


def _segments(s: Section) -> Segments:
    gain_deg = s.number("gain_deg", 0.0, 180.0)
    raw = s.get("segments")
    if not isinstance(raw, list) or not raw:
        raise ConfigError(
            f"{s.key('segments')}: must be a non-empty list of [kind, seconds, step], got {fmt(raw)}"
        )
    return Segments(
        gain=math.radians(gain_deg), segments=tuple(_segment(s.path, i, x) for i, x in enumerate(raw))
    )


def _file_signal(s: Section, base: Path | None) -> FileSignal:
    # A forcing function recorded in a data file: described here, read by the resolution
    # step (hcid.assembly.resolve), which owns file access.
    raw_path = s.get("path")
    column = s.get("column")
    for key, value in (("path", raw_path), ("column", column)):
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{s.key(key)}: must be a non-empty string, got {fmt(value)}")
    rate = s.number("rate", 0.1, 1e5)
    start = s.number("start", 0.0, 1e5, 0.0)
    run = s.get("run", None)
    if run is not None:
        run = integer(run, s.key("run"), 0, 2**31 - 1)
    run_column = s.get("run_column", "run")
    if not isinstance(run_column, str) or not run_column:
        raise ConfigError(f"{s.key('run_column')}: must be a non-empty string, got {fmt(run_column)}")
    path = Path(raw_path)
    if not path.is_absolute() and base is not None:
        path = base / path
    return FileSignal(
        path=str(path), column=column, rate=rate, start=start, run=run, run_column=run_column, values=None
    )


#: Kinds of forcing function (``signals.<target|disturbance>.kind``), each a parser of its
#: section. The target defaults to ``segments``, the disturbance to ``multisine``.
FORCING_KINDS = {"multisine": _multisine, "segments": _segments, "file": _file_signal}


def _forcing(sig: Section, name: str, default_kind: str, base: Path | None) -> Forcing:
    s = sig.section(name)
    kind = s.get("kind", default_kind)
    if kind not in FORCING_KINDS:
        raise ConfigError(
            f"{s.key('kind')}: unknown forcing function {fmt(kind)} (allowed: {', '.join(FORCING_KINDS)})"
        )
    spec = _file_signal(s, base) if kind == "file" else FORCING_KINDS[kind](s)
    s.done()
    return spec


def signals_section(top: Section, base: Path | None) -> tuple[Forcing, Forcing]:
    sig = top.section("signals")
    disturbance = _forcing(sig, "disturbance", "multisine", base)
    target = _forcing(sig, "target", "segments", base)
    sig.done()
    return disturbance, target


def timing_section(top: Section) -> Timing:
    s = top.section("timing")
    timing = Timing(
        sim_rate=s.number("sim_rate", 1.0, 10_000.0),
        output_rate=s.number("output_rate", 0.1, 10_000.0),
        run_in=s.number("run_in", 0.0, 1e4),
        window=s.number("window", 0.0, 1e4, open_lo=True),
        periods=s.integer("periods", 1, 100),
    )
    s.done()
    ratio = timing.sim_rate / timing.output_rate
    if abs(ratio - round(ratio)) > 1e-9:
        raise ConfigError(
            f"timing.output_rate: must divide timing.sim_rate ({timing.sim_rate:g} Hz) "
            f"into a whole factor, got {timing.output_rate:g}"
        )
    for key, secs in (("run_in", timing.run_in), ("window", timing.window)):
        if abs(secs * timing.sim_rate - round(secs * timing.sim_rate)) > 1e-6:
            raise ConfigError(f"timing.{key}: must be whole samples at sim_rate, got {secs:g} s")
    samples = timing.period_samples * timing.periods
    if samples > LIMITS["simulation_samples"]:
        raise ConfigError(
            f"timing: a simulation of {samples:,} samples (sim_rate x (run_in + window) x periods), "
            f"at most {LIMITS['simulation_samples']:,} are allowed"
        )
    if timing.window_samples % timing.decimation:
        raise ConfigError(f"timing.window: must be whole samples at output_rate, got {timing.window:g} s")
    return timing


#: Why each forcing function must not be zero (or constant) over the window.
_NEEDED_FOR = {
    "disturbance": "the remnant gain (loop.remnant_ratio) is set in the disturbance-only task and the "
    "error path is identified from the disturbance",
    "target": "the target path (feedforward) is identified from the target",
}


def _constant_forcing(spec: Forcing, timing: Timing) -> str | None:
    """How ``spec`` is constant over the window (a multisine's amplitudes all 0, ...), or None."""
    if isinstance(spec, Multisine):
        return "every amplitude is 0" if not any(spec.amplitude) else None
    if isinstance(spec, Segments):
        return (
            "its gain or every step is 0"
            if spec.gain == 0 or not any(s.step for s in spec.segments)
            else None
        )
    first = round(spec.start * spec.rate)
    window = spec.values[first : first + round(timing.window * spec.rate)]
    return f"column {fmt(spec.column)} is constant ({window[0]:.6g})" if np.ptp(window) == 0 else None


def _check_forcing(name: str, spec: Forcing, timing: Timing) -> None:
    key = f"signals.{name}"
    if isinstance(spec, Segments):
        total = sum(s.duration for s in spec.segments)
        if total > timing.window + 1e-9:
            raise ConfigError(
                f"{key}.segments: must last at most timing.window ({timing.window:g} s), got {total:g} s"
            )
    elif isinstance(spec, FileSignal):
        for what, secs in (("start", spec.start), ("timing.window", timing.window)):
            if abs(secs * spec.rate - round(secs * spec.rate)) > 1e-6:
                raise ConfigError(
                    f"{key}.{what if what == 'start' else 'rate'}: {what} ({secs:g} s) must be whole "
                    f"samples at the file's rate {spec.rate:g} Hz"
                )


def check_forcing_values(name: str, spec: Forcing, timing: Timing) -> None:
    """Refuse a forcing function too short for the window or constant over it.

    A file's column is checked once read (its ``values`` set); the other kinds at once.

    Raises
    ------
    ConfigError
        Naming ``signals.<name>``.
    """
    if isinstance(spec, FileSignal):
        if spec.values is None:
            return
        need = round((spec.start + timing.window) * spec.rate)
        if spec.values.size < need:
            raise ConfigError(
                f"signals.{name}: column {spec.column!r} of {spec.path} holds {spec.values.size} samples, "
                f"the window from {spec.start:g} s to {spec.start + timing.window:g} s needs {need}"
            )
    how = _constant_forcing(spec, timing)
    if how is not None:
        raise ConfigError(f"signals.{name}: is constant over the window ({how}); {_NEEDED_FOR[name]}")


def check_against_timing(
    timing: Timing, signals: tuple[Forcing, Forcing], models: tuple[HCModel, ...]
) -> None:
    for name, spec in zip(("disturbance", "target"), signals, strict=True):
        _check_forcing(name, spec, timing)
        check_forcing_values(name, spec, timing)
    for m in models:
        for key, tau in (("tau_pe", m.tau_pe), ("tau_pt", m.tau_pt)):
            if abs(tau * timing.sim_rate - round(tau * timing.sim_rate)) > 1e-6:
                raise ConfigError(
                    f"models.{m.name}.{key}: must be whole samples at timing.sim_rate "
                    f"({timing.sim_rate:g} Hz), got {tau:g} s"
                )
