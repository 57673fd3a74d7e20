"""The ``identify`` section: the target shift and the stages' grids and windows (SPEC 3).

:func:`identify_section` keeps each stage's section as given; :func:`build_stages`
builds the stages of the methods a command uses from their stage specs (passed
in by :mod:`hcid.assembly.resolve`, which knows the method registry).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any

from hcid.config._checks import LIMITS, Section, fmt, int_range
from hcid.config.types import Grid, IdentifyConfig, StageConfig, Timing, Window
from hcid.errors import ConfigError, checked_rate

__all__ = ["build_stages", "identify_section", "parse_identify", "record_timing", "stage_raw"]

_ABSENT = object()  # a key left out (None is a value: refused where a mapping is needed)


#: The most input lags (nb1, nb2) and the longest delay (nk1, nk2) a grid may hold, in samples.
MOST_LAGS = 60
MOST_DELAY = 200


def _seconds_window(key: str, value: Any, rate: float, n_record: int) -> list[int]:
    """``[start, end]`` in s (end exclusive: the window holds ``(end - start) rate`` samples) as samples."""
    ok = (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        and 0 <= value[0] < value[1]
    )
    if not ok:
        raise ConfigError(
            f"{key}: must be 'auto' or [start, end] in s with 0 <= start < end "
            f"(identify.windows_in is seconds), got {fmt(value)}"
        )
    samples = []
    for v in value:
        k = v * rate
        if abs(k - round(k)) > 1e-6:
            raise ConfigError(
                f"{key}: {v:g} s is not a whole number of samples at the analysis rate {rate:g} Hz "
                f"(1 sample = {1 / rate:g} s), got {fmt(value)}"
            )
        samples.append(round(k))
    first, last = samples[0] + 1, samples[1]
    if last > n_record:
        raise ConfigError(
            f"{key}: must end within the record ({n_record / rate:g} s, {n_record} samples), got {fmt(value)}"
        )
    return [first, last]


def _window(
    section: Section, name: str, n_record: int, auto_first: int, rate: float, unit: str, given: bool
) -> Window:
    """A stage's window in samples; ``given``: the config gives it (else the method's default)."""
    value = section.get(name)
    key = section.key(name)
    if value == "auto":
        return Window(auto_first + 1, n_record)
    if unit == "seconds":
        value = _seconds_window(key, value, rate, n_record)
    ok = (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
        and 1 <= value[0] <= value[1] <= n_record
    )
    if not ok and not given:  # the method's default (in samples) does not fit this record
        raise ConfigError(
            f"{key}: the method's default window {fmt(value)} (samples) does not fit this record of "
            f"{n_record} samples ({n_record / rate:g} s); give {key} (in seconds with "
            "identify.windows_in: seconds), or leave the identify section out for windows scaled "
            "to the record"
        )
    if not ok:
        seconds = isinstance(value, list) and any(isinstance(v, float) and not v.is_integer() for v in value)
        hint = (
            f"; in seconds ({n_record / rate:g} s of record) with identify.windows_in: seconds"
            if seconds
            else ""
        )
        raise ConfigError(
            f"{key}: must be 'auto' or a sample range [first, last] with "
            f"1 <= first <= last <= {n_record} (1-based, inclusive){hint}, got {fmt(value)}"
        )
    return Window(int(value[0]), int(value[1]))


def _stage(data: Any, path: str, defaults: dict, timing: Timing, unit: str, given: set) -> StageConfig:
    n_record, rate = timing.record_samples, timing.output_rate
    merged = dict(defaults)
    if data is not _ABSENT:
        if not isinstance(data, dict):
            raise ConfigError(
                f"{path}: must be a mapping (leave the key out for the defaults), got {fmt(data)}"
            )
        merged.update(data)
    s = Section(merged, path)
    grid = Grid(
        na=int_range(s, "na", 1, 30),
        nb1=int_range(s, "nb1", 0, MOST_LAGS),
        nb2=int_range(s, "nb2", 0, MOST_LAGS),
        nk1=int_range(s, "nk1", 0, MOST_DELAY),
        nk2=int_range(s, "nk2", 0, MOST_DELAY),
    )
    max_lag = grid.max_lag
    # A method's default window (its StageSpec) is in samples; one the config gives is in `unit`.
    est_unit = unit if "estimation" in given else "samples"
    val_unit = unit if "validation" in given else "samples"
    estimation = _window(s, "estimation", n_record, max_lag, rate, est_unit, "estimation" in given)
    validation = _window(s, "validation", n_record, max_lag, rate, val_unit, "validation" in given)
    s.done()
    if estimation.first - 1 < max_lag:
        raise ConfigError(
            f"{path}.estimation: must start after the grid's largest lag ({max_lag} samples), "
            f"i.e. first >= {max_lag + 1}, got {[estimation.first, estimation.last]}"
        )
    n_params = grid.na[1] + grid.nb1[1] + grid.nb2[1] + 2
    for key, window in (("estimation", estimation), ("validation", validation)):
        if window.length < 2 * n_params:
            raise ConfigError(
                f"{path}.{key}: must hold at least {2 * n_params} samples for this grid, got {window.length}"
            )
    if grid.n_candidates > LIMITS["grid_candidates"]:
        raise ConfigError(
            f"{path}: the grid has {grid.n_candidates:,} candidates, at most "
            f"{LIMITS['grid_candidates']:,} are allowed"
        )
    return StageConfig(grid=grid, estimation=estimation, validation=validation)


def _stage_options(data: Any, path: str, options: dict) -> tuple[Any, tuple[tuple[str, Any], ...]]:
    """Split a stage section's method-declared option keys off its grid and windows and check them.

    Returns the rest of the section and the options whose value differs from
    the default (so a config that states a default resolves like one that omits it).
    """
    if not options or not isinstance(data, dict):
        return data, ()
    rest = {k: v for k, v in data.items() if k not in options}
    parsed = ((k, o.parse(data[k], f"{path}.{k}")) for k, o in options.items() if k in data)
    return rest, tuple((k, v) for k, v in parsed if v != options[k].default)


def _stage_raw(stage: StageConfig) -> dict:
    g = stage.grid
    options = {k: list(v) if isinstance(v, tuple) else v for k, v in stage.options}
    return {
        "na": list(g.na),
        "nb1": list(g.nb1),
        "nb2": list(g.nb2),
        "nk1": list(g.nk1),
        "nk2": list(g.nk2),
        "estimation": [stage.estimation.first, stage.estimation.last],
        "validation": [stage.validation.first, stage.validation.last],
        **options,
    }


def identify_section(top: Section, timing: Timing) -> IdentifyConfig:
    """The target shift, the window unit and each stage's section as given (see :func:`build_stages`)."""
    s = top.section("identify", {})
    target_shift = s.number("target_shift", 0.0, 10.0, 1.0)
    if abs(target_shift * timing.output_rate - round(target_shift * timing.output_rate)) > 1e-9:
        raise ConfigError(
            f"identify.target_shift: must be whole samples at timing.output_rate "
            f"({timing.output_rate:g} Hz), got {target_shift:g} s"
        )
    unit = s.get("windows_in", "samples")
    if unit not in ("samples", "seconds"):
        raise ConfigError(f"identify.windows_in: must be 'samples' or 'seconds', got {fmt(unit)}")
    sections = tuple((str(k), v) for k, v in s.data.items() if k not in ("target_shift", "windows_in"))
    for key, value in sections:
        if value is None or not isinstance(value, dict):
            raise ConfigError(
                f"identify.{key}: must be a mapping (leave the key out for the defaults), got {fmt(value)}"
            )
    return IdentifyConfig(target_shift=target_shift, stages=(), sections=sections, windows_in=unit)


def build_stages(identify: IdentifyConfig, specs: dict[str, Any], timing: Timing) -> IdentifyConfig:
    """``identify`` with the stages of ``specs`` (name -> a method's stage spec) built and checked.

    A stage spec gives ``defaults`` (its section's defaults, windows in samples),
    ``defaults_from`` (a stage whose section it inherits, or None) and ``options``
    (its method-declared keys). Stages not in ``specs`` are not built; their
    sections stay as given.

    Raises
    ------
    ConfigError
        Naming the stage's key, as for any section.
    """
    given_sections = dict(identify.sections)
    stages = []
    for name, spec in specs.items():
        defaults = dict(spec.defaults)
        given: set = set()
        if spec.defaults_from is not None:
            inherited = given_sections.get(spec.defaults_from)
            if isinstance(inherited, dict):
                defaults.update(inherited)
                given |= set(inherited)
        path = f"identify.{name}"
        data, options = _stage_options(given_sections.get(name, _ABSENT), path, spec.options)
        if isinstance(data, dict):
            given |= set(data)
        stage = _stage(data, path, defaults, timing, identify.windows_in, given)
        stages.append((name, dataclasses.replace(stage, options=options)))
    return dataclasses.replace(identify, stages=tuple(stages))


def stage_raw(stage: StageConfig) -> dict:
    """A built stage as its config section: grid, windows in samples, non-default options."""
    return _stage_raw(stage)


def record_timing(rate: float, n_samples: int) -> Timing:
    """The timing of one record of ``n_samples`` (a positive integer, numpy's too) at ``rate`` Hz:
    no run-in, one period, the whole record the window.

    Raises
    ------
    ConfigError
        For a rate or a number of samples that is none.
    """
    checked_rate(rate)
    if isinstance(n_samples, numbers.Integral) and not isinstance(n_samples, bool):
        n_samples = int(n_samples)
    if not (isinstance(n_samples, int) and n_samples > 0):
        raise ConfigError(f"n_samples: must be a positive integer, got {fmt(n_samples)}")
    return Timing(sim_rate=rate, output_rate=rate, run_in=0.0, window=n_samples / rate, periods=1)


def parse_identify(data: Any, rate: float, n_samples: int) -> tuple[IdentifyConfig, Timing]:
    """The ``identify`` section alone, for a record of ``n_samples`` at ``rate`` Hz, and that timing.

    ``data`` is the section's mapping (None: every default). Its stages are built
    by :func:`build_stages` with the methods' stage specs.

    Raises
    ------
    ConfigError
        Naming the key, as in a config.
    """
    timing = record_timing(rate, n_samples)
    return identify_section(Section({"identify": {} if data is None else data}, ""), timing), timing
