"""Parse a YAML study config into :class:`~hcid.config.types.Config`, one section at a time.

Each ``_section`` function checks one top-level section and returns its
dataclass; :func:`parse_config` runs them in order and checks what spans
sections (timing against the target, delays against the simulation rate).
The ``identify`` section holds one subsection per stage of the registered
methods (:func:`hcid.methods.stage_specs`); the ``selection`` section names
the criteria of :mod:`hcid.criteria`.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hcid.config._checks import Section, fmt, int_range, integer, number_list
from hcid.config.types import (
    Config,
    DataConfig,
    FileSignal,
    Forcing,
    Grid,
    HCModel,
    IdentifyConfig,
    Loop,
    Multisine,
    Plant,
    Segment,
    Segments,
    SelectionConfig,
    StageConfig,
    Timing,
    Window,
)
from hcid.errors import ConfigError

__all__ = ["DISTURBANCE_POINTS", "LIMITS", "PLANTS", "load_config", "parse_config"]

#: Bounds on what a config may ask for, each checked at parse time with a one-line error:
#: the file, its nesting, seeds, candidates per grid and per study, samples per simulation.
LIMITS = {
    "file_bytes": 1 << 20,
    "nesting": 40,
    "seeds": 10_000,
    "grid_candidates": 10_000_000,
    "study_candidates": 2_000_000_000,
    "simulation_samples": 10_000_000,
    "name_chars": 100,
}

_ABSENT = object()  # a key left out (None is a value: refused where a mapping is needed)
_DATA_COLUMNS = {
    "ft": "ft",
    "fd": "fd",
    "e": "e",
    "u": "u",
    "theta": "theta",
    "time": "t",
    "run": "run",
    "rate": "rate",
}
#: The sections only a config that simulates holds; a config without them (and with a
#: ``data`` section) describes measured data only.
SIMULATION_SECTIONS = ("models", "loop", "signals", "seeds")


# --------------------------------------------------------------------------- models and loop


def _model(name: Any, data: Any) -> HCModel:
    if not isinstance(name, str) or not name.isidentifier() or len(name) > 40:
        raise ConfigError(
            f"models: model names must be identifiers of at most 40 characters, got {fmt(name)}"
        )
    s = Section(data, f"models.{name}")
    Kpt = s.number("Kpt", 0.0, 10.0)
    model = HCModel(
        name=name,
        Kpt=Kpt,
        TI=s.number("TI", 0.0, 10.0, 0.0),
        tau_pt=s.number("tau_pt", 0.0, 2.0, 0.0),
        Kpe=s.number("Kpe", 0.0, 100.0, open_lo=True),
        TL=s.number("TL", 0.0, 10.0),
        tau_pe=s.number("tau_pe", 0.0, 2.0, open_lo=True),
    )
    if Kpt > 0 and model.TI <= 0:
        raise ConfigError(f"models.{name}.TI: must be > 0 when Kpt > 0, got {model.TI:g}")
    s.done()
    return model


def _models_section(top: Section) -> tuple[HCModel, ...]:
    raw = top.get("models")
    if not isinstance(raw, dict) or not raw:
        raise ConfigError(f"models: must be a non-empty mapping of model name to parameters, got {fmt(raw)}")
    return tuple(_model(k, v) for k, v in raw.items())


def _integrator(s: Section) -> Plant:
    K = s.number("K", 0.0, 1e4, open_lo=True)
    return Plant("integrator", (K,), (1.0, 0.0), f"{K:g}/s")


def _double_integrator(s: Section) -> Plant:
    K = s.number("K", 0.0, 1e4, open_lo=True)
    return Plant("double_integrator", (K,), (1.0, 0.0, 0.0), f"{K:g}/s^2")


def _second_order(s: Section) -> Plant:
    return Plant.second_order(s.number("K", 0.0, 1e4, open_lo=True), s.number("wb", 0.0, 1e4, open_lo=True))


def _poly_text(coefs: tuple[float, ...]) -> str:
    n = len(coefs) - 1
    terms = [
        f"{c:g}" + ("" if i == n else " s" if i == n - 1 else f" s^{n - i}")
        for i, c in enumerate(coefs)
        if c != 0
    ]
    return " + ".join(terms).replace("+ -", "- ")


def _transfer_function(s: Section) -> Plant:
    num, den = number_list(s, "num"), number_list(s, "den")
    for key, coefs in (("num", num), ("den", den)):
        if len(coefs) > 11:
            raise ConfigError(
                f"loop.plant.{key}: must hold at most 11 coefficients (degree 10), got {len(coefs)}"
            )
    num = tuple(num[next((i for i, c in enumerate(num) if c != 0), len(num)) :])
    if not num:
        raise ConfigError("loop.plant.num: must not be all zero")
    if den[0] == 0:
        raise ConfigError(f"loop.plant.den: the leading coefficient must not be 0, got {list(den)}")
    if len(num) > len(den):
        raise ConfigError(
            f"loop.plant: must be proper (degree of num <= degree of den), got degrees "
            f"{len(num) - 1} and {len(den) - 1}"
        )
    return Plant("tf", num, den, f"({_poly_text(num)}) / ({_poly_text(den)})")


#: Plant shorthands of ``loop.plant.kind``, each a builder from its section (SPEC 7);
#: ``tf`` takes any proper transfer function in s. Add a shorthand here.
PLANTS = {
    "second_order": _second_order,
    "integrator": _integrator,
    "double_integrator": _double_integrator,
    "tf": _transfer_function,
}

#: Where the disturbance enters: at the plant's output (the paper) or its input.
DISTURBANCE_POINTS = ("output", "input")


def _plant(loop: Section) -> Plant:
    s = loop.section("plant")
    kind = s.get("kind")
    try:
        builder = PLANTS[kind]
    except (KeyError, TypeError):
        raise ConfigError(
            f"loop.plant.kind: unknown plant shorthand {fmt(kind)} (allowed: {', '.join(PLANTS)})"
        ) from None
    plant = builder(s)
    s.done()
    return plant


def _loop_section(top: Section) -> Loop:
    s = top.section("loop")
    if "plant" in s.data:
        both = [k for k in ("Kc", "wb") if k in s.data]
        if both:
            raise ConfigError(
                f"loop.{both[0]}: give the plant either as loop.Kc and loop.wb (the paper's "
                "Kc wb / (s (s + wb))) or as loop.plant, not both"
            )
        plant = _plant(s)
    else:
        Kc = s.number("Kc", 0.0, 1e3, open_lo=True)
        plant = Plant.second_order(Kc, s.number("wb", 0.0, 1e3, open_lo=True))
    point = s.get("disturbance_at", "output")
    if point not in DISTURBANCE_POINTS:
        raise ConfigError(
            f"loop.disturbance_at: must be one of {', '.join(DISTURBANCE_POINTS)}, got {fmt(point)}"
        )
    loop = Loop(
        plant=plant,
        w_nms=s.number("w_nms", 0.0, 1e3, open_lo=True),
        zeta_nms=s.number("zeta_nms", 0.0, 10.0, open_lo=True),
        w_n=s.number("w_n", 0.0, 1e3, open_lo=True),
        zeta_n=s.number("zeta_n", 0.0, 10.0, open_lo=True),
        remnant_ratio=s.number("remnant_ratio", 0.0, 0.9),
        disturbance_at=point,
    )
    s.done()
    return loop


# --------------------------------------------------------------------------- signals and timing


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
    # A forcing function recorded in a data file: read here, at the entry point, with the
    # data readers (hcid.measured.READERS), so that the numerical core never opens a file.
    from hcid.errors import DataError
    from hcid.measured import read_signal

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
        path = (base / path).resolve()
        # The resolved config (a run's config.yaml, read back by `hcid report` from the run
        # directory) names the file by its absolute path.
        s.data["path"] = str(path)
    try:
        values = read_signal(path, column, run, run_column)
    except DataError as exc:
        raise ConfigError(f"{s.path}: {exc}") from None
    return FileSignal(path=str(raw_path), column=column, rate=rate, start=start, values=values)


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


def _signals_section(top: Section, base: Path | None) -> tuple[Forcing, Forcing]:
    sig = top.section("signals")
    disturbance = _forcing(sig, "disturbance", "multisine", base)
    target = _forcing(sig, "target", "segments", base)
    sig.done()
    return disturbance, target


def _timing_section(top: Section) -> Timing:
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
        need = round((spec.start + timing.window) * spec.rate)
        if spec.values.size < need:
            raise ConfigError(
                f"{key}: column {spec.column!r} of {spec.path} holds {spec.values.size} samples, the window "
                f"from {spec.start:g} s to {spec.start + timing.window:g} s needs {need}"
            )


def _check_against_timing(
    timing: Timing, signals: tuple[Forcing, Forcing], models: tuple[HCModel, ...]
) -> None:
    for name, spec in zip(("disturbance", "target"), signals, strict=True):
        _check_forcing(name, spec, timing)
        how = _constant_forcing(spec, timing)
        if how is not None:
            raise ConfigError(f"signals.{name}: is constant over the window ({how}); {_NEEDED_FOR[name]}")
    for m in models:
        for key, tau in (("tau_pe", m.tau_pe), ("tau_pt", m.tau_pt)):
            if abs(tau * timing.sim_rate - round(tau * timing.sim_rate)) > 1e-6:
                raise ConfigError(
                    f"models.{m.name}.{key}: must be whole samples at timing.sim_rate "
                    f"({timing.sim_rate:g} Hz), got {tau:g} s"
                )


def _seeds_section(top: Section) -> tuple[int, ...]:
    value = top.get("seeds")
    if isinstance(value, dict):
        s = Section(value, "seeds")
        first = s.integer("first", 0, 2**31 - 1)
        count = s.integer("count", 1, LIMITS["seeds"])
        s.done()
        return tuple(range(first, first + count))
    if not isinstance(value, list) or not value:
        raise ConfigError(
            f"seeds: must be a non-empty list of integers or {{first, count}}, got {fmt(value)}"
        )
    if len(value) > LIMITS["seeds"]:
        raise ConfigError(f"seeds: must hold at most {LIMITS['seeds']:,} seeds, got {len(value):,}")
    seeds = tuple(integer(v, f"seeds[{i}]", 0, 2**31 - 1) for i, v in enumerate(value))
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"seeds: must not repeat a seed, got {list(seeds)}")
    return seeds


# --------------------------------------------------------------------------- identification


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


def _window(section: Section, name: str, n_record: int, auto_first: int, rate: float, unit: str) -> Window:
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
    if not ok:
        raise ConfigError(
            f"{key}: must be 'auto' or a sample range [first, last] with "
            f"1 <= first <= last <= {n_record} (1-based, inclusive), got {fmt(value)}"
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
        nb1=int_range(s, "nb1", 0, 60),
        nb2=int_range(s, "nb2", 0, 60),
        nk1=int_range(s, "nk1", 0, 200),
        nk2=int_range(s, "nk2", 0, 200),
    )
    max_lag = grid.max_lag
    # A method's default window (its StageSpec) is in samples; one the config gives is in `unit`.
    est_unit = unit if "estimation" in given else "samples"
    val_unit = unit if "validation" in given else "samples"
    estimation = _window(s, "estimation", n_record, max_lag, rate, est_unit)
    validation = _window(s, "validation", n_record, max_lag, rate, val_unit)
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


def _identify_section(top: Section, timing: Timing) -> IdentifyConfig:
    # The stages are those the registered methods declare: the one place the config
    # layer looks at the method registry (hcid.methods), to know which sections exist.
    from hcid.methods import stage_specs

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
    stages = []
    for name, spec in stage_specs().items():
        defaults = dict(spec.defaults)
        given = set()
        if spec.defaults_from is not None:
            inherited = s.data.get(spec.defaults_from)
            if isinstance(inherited, dict):
                defaults.update(inherited)
                given |= set(inherited)
        data, options = _stage_options(s.get(name, _ABSENT), f"identify.{name}", spec.options)
        if isinstance(data, dict):
            given |= set(data)
        stage = _stage(data, f"identify.{name}", defaults, timing, unit, given)
        stages.append((name, dataclasses.replace(stage, options=options)))
    s.done()
    return IdentifyConfig(target_shift=target_shift, stages=tuple(stages))


# --------------------------------------------------------------------------- selection and data


def _criteria(s: Section) -> tuple[tuple[str, tuple[tuple[str, float], ...]], ...]:
    from hcid import criteria

    raw = s.get("criteria", {name: {} for name in criteria.DEFAULT})
    if isinstance(raw, list):
        raw = {name: {} for name in raw}
    if not isinstance(raw, dict) or not raw:
        raise ConfigError(
            f"selection.criteria: must be a non-empty mapping of criterion name to constants "
            f"(allowed names: {', '.join(criteria.CRITERIA)}), got {fmt(raw)}"
        )
    out = []
    for name, constants in raw.items():
        if constants is None:
            constants = {}
        if not isinstance(constants, dict) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in constants.values()
        ):
            raise ConfigError(
                f"selection.criteria.{name}: must be a mapping of constants, got {fmt(constants)}"
            )
        built = criteria.build(str(name), constants)
        out.append((built.name, built.constants))
    return tuple(out)


def _selection_section(top: Section) -> tuple[SelectionConfig, dict]:
    s = top.section("selection", {})
    wg = s.section("w_grid", {"min": 1e-4, "max": 2.0, "points": 241})
    w_min = wg.number("min", 0.0, 1e3, open_lo=True)
    w_max = wg.number("max", 0.0, 1e3, open_lo=True)
    points = wg.integer("points", 2, 100_000)
    wg.done()
    target_rate = s.number("target_rate", 0.0, 0.5, 0.0)
    chosen = _criteria(s)
    s.done()
    if w_max <= w_min:
        raise ConfigError(f"selection.w_grid.max: must be > selection.w_grid.min ({w_min:g}), got {w_max:g}")
    lo, hi = math.log10(w_min), math.log10(w_max)
    w_grid = tuple(float(10 ** (lo + i * (hi - lo) / (points - 1))) for i in range(points))
    resolved = {
        "w_grid": {"min": w_min, "max": w_max, "points": points},
        "target_rate": target_rate,
        "criteria": {n: dict(c) for n, c in chosen},
    }
    return SelectionConfig(w_grid=w_grid, target_rate=target_rate, criteria=chosen), resolved


def _data_timing(top: Section) -> Timing:
    """The analysis timing of a data-only config without a timing section: data.analysis_rate, data.window."""
    s = top.section("data")
    rate = s.number("analysis_rate", 0.1, 10_000.0)
    window = s.number("window", 0.0, 1e4, open_lo=True)
    if abs(window * rate - round(window * rate)) > 1e-6:
        raise ConfigError(
            f"data.window: must be whole samples at data.analysis_rate ({rate:g} Hz), got {window:g} s"
        )
    return Timing(sim_rate=rate, output_rate=rate, run_in=0.0, window=window, periods=1)


def default_data() -> DataConfig:
    """The data section of a config that has none: the default column names."""
    return DataConfig(name="data", columns=dict(_DATA_COLUMNS), w_report=(0.00715, 0.47), time_default=True)


def _data_section(top: Section, model_names: list[str], timing: Timing) -> DataConfig:
    value = top.get("data", {})
    s = Section(value, "data")
    if "timing" not in top.data:  # a data-only config: its analysis timing, read by _data_timing
        s.get("analysis_rate")
        s.get("window")
    name = s.get("name", "data")
    if not isinstance(name, str) or not name.isidentifier() or len(name) > 40 or name in model_names:
        raise ConfigError(
            f"data.name: must be an identifier other than the model names {model_names}, got {fmt(name)}"
        )
    cs = s.section("columns", {})
    columns = {}
    for key, default in _DATA_COLUMNS.items():
        col = cs.get(key, default)
        if not isinstance(col, str) or not col:
            raise ConfigError(f"data.columns.{key}: must be a column or variable name, got {fmt(col)}")
        columns[key] = col
    time_default = "time" not in cs.data
    cs.done()
    w_raw = s.get("w_report", [0.00715, 0.47])
    if (
        not isinstance(w_raw, list)
        or not w_raw
        or not all(isinstance(w, int | float) and not isinstance(w, bool) and w > 0 for w in w_raw)
    ):
        raise ConfigError(f"data.w_report: must be a non-empty list of W > 0, got {fmt(w_raw)}")
    lead_in = s.number("lead_in", 0.0, 1e4, 0.0)
    rate = timing.output_rate
    if abs(lead_in * rate - round(lead_in * rate)) > 1e-6:
        raise ConfigError(
            f"data.lead_in: must be whole samples at the analysis rate ({rate:g} Hz), got {lead_in:g} s"
        )
    s.done()
    return DataConfig(
        name=name,
        columns=columns,
        w_report=tuple(float(w) for w in w_raw),
        lead_in=lead_in,
        time_default=time_default,
    )


def _fit_hc_section(top: Section, band: tuple[float, float], timing: Timing):
    # The settings live with the fit (hcid.hcfit.settings), parsed here once like every section.
    from hcid.hcfit.settings import parse_fit_settings

    settings = parse_fit_settings(top.get("fit_hc", None), "fit_hc", default_band=band)
    nyquist = math.pi * timing.output_rate
    if settings.band is not None and settings.band[1] > nyquist * (1 + 1e-9):
        raise ConfigError(
            f"fit_hc.band: must end at or below the analysis Nyquist frequency (pi x "
            f"{timing.output_rate:g} Hz = {nyquist:.4g} rad/s), got {list(settings.band)}"
        )
    return settings


# --------------------------------------------------------------------------- entry points

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")


def _study_name(value: Any) -> str:
    """The study name, also the default run directory ``runs/<name>``: one plain path component."""
    ok = (
        isinstance(value, str)
        and len(value) <= LIMITS["name_chars"]
        and _NAME.fullmatch(value) is not None
        and value not in (".", "..")
    )
    if not ok:
        raise ConfigError(
            f"name: must be 1 to {LIMITS['name_chars']} letters, digits and _ . + - (starting with a "
            f"letter or digit; it names the run directory), got {fmt(value)}"
        )
    return value


def _check_study_size(identify: IdentifyConfig, seeds: tuple[int, ...], models: tuple[HCModel, ...]) -> None:
    per_record = sum(stage.grid.n_candidates for _, stage in identify.stages)
    total = per_record * len(seeds) * len(models)
    if total > LIMITS["study_candidates"]:
        raise ConfigError(
            f"identify: the study fits {total:,} candidates ({per_record:,} per record x "
            f"{len(seeds) * len(models):,} records), at most {LIMITS['study_candidates']:,} are allowed"
        )


class _Loader(yaml.SafeLoader):
    """yaml.SafeLoader without aliases (no expansion bombs), duplicate keys or deep nesting."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise ConfigError(f"line {mark.line + 1}: YAML aliases (*name) are not allowed in a config")
        self._depth += 1
        if self._depth > LIMITS["nesting"]:
            mark = self.peek_event().start_mark
            raise ConfigError(f"line {mark.line + 1}: nested deeper than {LIMITS['nesting']} levels")
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, list | dict):
                raise ConfigError(f"line {key_node.start_mark.line + 1}: a mapping key must be a plain value")
            if key in seen:
                raise ConfigError(f"line {key_node.start_mark.line + 1}: duplicate key {fmt(key)}")
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def read_yaml(path: Path, what: str = "config") -> Any:
    """Read a YAML file with :class:`_Loader`: at most ``LIMITS['file_bytes']``, UTF-8.

    Raises
    ------
    ConfigError
        One line naming the file and the problem.
    """
    try:
        with open(path, "rb") as f:
            raw = f.read(LIMITS["file_bytes"] + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what} ({exc.strerror or exc})") from exc
    if len(raw) > LIMITS["file_bytes"]:
        raise ConfigError(f"{path}: larger than {LIMITS['file_bytes']:,} bytes; not a {what}")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start})"
        ) from exc
    if "\0" in text:
        raise ConfigError(f"{path}: holds a NUL character; not a {what}")
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 (a SafeLoader subclass)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}: not valid YAML{where}") from exc
    except (ValueError, RecursionError) as exc:  # e.g. an integer of more than 4300 digits
        raise ConfigError(f"{path}: not a usable {what} ({fmt(str(exc).splitlines()[0])})") from exc


def parse_config(data: Any, name: str, base: Path | None = None) -> Config:
    """Check a parsed YAML document and build the :class:`Config`.

    Parameters
    ----------
    data : object
        The result of ``yaml.safe_load``.
    name : str
        Study name used when the document has no ``name`` key (the file stem).
    base : Path, optional
        Folder that relative file paths in the config are read from (the config's own).

    Raises
    ------
    ConfigError
        On the first unknown key, wrong type or out-of-range value, naming it.
    """
    top = Section(data, "")
    study_name = _study_name(top.get("name", name))
    simulates = "data" not in top.data or any(k in top.data for k in SIMULATION_SECTIONS)
    if simulates:
        models = _models_section(top)
        loop = _loop_section(top)
        disturbance, target = _signals_section(top, base)
        timing = _timing_section(top)
        _check_against_timing(timing, (disturbance, target), models)
        seeds = _seeds_section(top)
    else:
        models, loop, disturbance, target, seeds = (), None, None, None, ()
        timing = _timing_section(top) if "timing" in top.data else _data_timing(top)
    identify = _identify_section(top, timing)
    selection, selection_raw = _selection_section(top)
    data_cfg = _data_section(top, [m.name for m in models], timing)
    fit_hc = _fit_hc_section(top, Config.band_of(disturbance, timing), timing)
    top.done()
    _check_study_size(identify, seeds, models)
    if simulates:
        # The closed loops' stability needs the discretised paths (hcid.hcmodel): checked
        # here so that an unstable hypothesis is refused before anything is simulated.
        from hcid.hcmodel import check_closed_loops

        check_closed_loops(models, loop, timing.sim_dt)

    raw = dict(data)
    raw["name"] = study_name
    raw["identify"] = {
        "target_shift": identify.target_shift,
        **{stage_name: _stage_raw(stage) for stage_name, stage in identify.stages},
    }
    raw["selection"] = selection_raw
    return Config(
        name=study_name,
        models=models,
        loop=loop,
        disturbance=disturbance,
        target=target,
        timing=timing,
        seeds=seeds,
        identify=identify,
        selection=selection,
        data=data_cfg,
        fit_hc=fit_hc,
        raw=raw,
    )


def load_config(path: str | Path) -> Config:
    """Read and check a YAML study config.

    Raises
    ------
    ConfigError
        If the file is missing, is not YAML, or any key is wrong (naming it).
    """
    path = Path(path)
    return parse_config(read_yaml(path), path.stem, path.parent)
