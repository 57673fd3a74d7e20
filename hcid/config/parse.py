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
from pathlib import Path
from typing import Any

import yaml

from hcid.config._checks import Section, fmt, int_range, integer, number_list
from hcid.config.types import (
    Config,
    DataConfig,
    Disturbance,
    Grid,
    HCModel,
    IdentifyConfig,
    Loop,
    Segment,
    SelectionConfig,
    StageConfig,
    Target,
    Timing,
    Window,
)
from hcid.errors import ConfigError

__all__ = ["load_config", "parse_config"]

_DATA_COLUMNS = {"ft": "ft", "fd": "fd", "e": "e", "u": "u", "time": "t", "run": "run", "rate": "rate"}


# --------------------------------------------------------------------------- models and loop


def _model(name: Any, data: Any) -> HCModel:
    if not isinstance(name, str) or not name.isidentifier():
        raise ConfigError(f"models: model names must be identifiers, got {fmt(name)}")
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


def _loop_section(top: Section) -> Loop:
    s = top.section("loop")
    loop = Loop(
        Kc=s.number("Kc", 0.0, 1e3, open_lo=True),
        wb=s.number("wb", 0.0, 1e3, open_lo=True),
        w_nms=s.number("w_nms", 0.0, 1e3, open_lo=True),
        zeta_nms=s.number("zeta_nms", 0.0, 10.0, open_lo=True),
        w_n=s.number("w_n", 0.0, 1e3, open_lo=True),
        zeta_n=s.number("zeta_n", 0.0, 10.0, open_lo=True),
        remnant_ratio=s.number("remnant_ratio", 0.0, 0.9),
    )
    s.done()
    return loop


# --------------------------------------------------------------------------- signals and timing


def _disturbance(sig: Section) -> Disturbance:
    s = sig.section("disturbance")
    k = s.get("k")
    if not isinstance(k, list) or not k:
        raise ConfigError(f"signals.disturbance.k: must be a non-empty list of integers, got {fmt(k)}")
    k_int = tuple(integer(v, f"signals.disturbance.k[{i}]", 1, 100_000) for i, v in enumerate(k))
    disturbance = Disturbance(
        base_period=s.number("base_period", 0.0, 1e5, open_lo=True),
        time_offset=s.number("time_offset", -1e5, 1e5),
        k=k_int,
        amplitude=number_list(s, "amplitude", len(k_int)),
        phase=number_list(s, "phase", len(k_int)),
    )
    s.done()
    return disturbance


def _segment(i: int, seg: Any) -> Segment:
    key = f"signals.target.segments[{i}]"
    ok = (
        isinstance(seg, list)
        and len(seg) == 3
        and seg[0] in ("c", "p")
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in seg[1:])
        and all(math.isfinite(v) for v in seg[1:])
        and seg[1] > 0
    )
    if not ok:
        raise ConfigError(f"{key}: must be [c|p, seconds > 0, step], got {fmt(seg)}")
    if seg[0] == "c" and seg[2] != 0:
        raise ConfigError(f"{key}: a hold segment 'c' must have step 0, got {seg[2]}")
    return Segment(seg[0], float(seg[1]), float(seg[2]))


def _target(sig: Section) -> Target:
    s = sig.section("target")
    gain_deg = s.number("gain_deg", 0.0, 180.0)
    raw = s.get("segments")
    if not isinstance(raw, list) or not raw:
        raise ConfigError(
            f"signals.target.segments: must be a non-empty list of [kind, seconds, step], got {fmt(raw)}"
        )
    target = Target(gain=math.radians(gain_deg), segments=tuple(_segment(i, x) for i, x in enumerate(raw)))
    s.done()
    return target


def _signals_section(top: Section) -> tuple[Disturbance, Target]:
    sig = top.section("signals")
    disturbance, target = _disturbance(sig), _target(sig)
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
    if timing.window_samples % timing.decimation:
        raise ConfigError(f"timing.window: must be whole samples at output_rate, got {timing.window:g} s")
    return timing


def _check_against_timing(timing: Timing, target: Target, models: tuple[HCModel, ...]) -> None:
    total = sum(s.duration for s in target.segments)
    if total > timing.window + 1e-9:
        raise ConfigError(
            f"signals.target.segments: must last at most timing.window ({timing.window:g} s), got {total:g} s"
        )
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
        count = s.integer("count", 1, 100_000)
        s.done()
        return tuple(range(first, first + count))
    if not isinstance(value, list) or not value:
        raise ConfigError(
            f"seeds: must be a non-empty list of integers or {{first, count}}, got {fmt(value)}"
        )
    seeds = tuple(integer(v, f"seeds[{i}]", 0, 2**31 - 1) for i, v in enumerate(value))
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"seeds: must not repeat a seed, got {list(seeds)}")
    return seeds


# --------------------------------------------------------------------------- identification


def _window(section: Section, name: str, n_record: int, auto_first: int) -> Window:
    value = section.get(name)
    key = section.key(name)
    if value == "auto":
        return Window(auto_first + 1, n_record)
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


def _stage(data: Any, path: str, defaults: dict, n_record: int) -> StageConfig:
    merged = dict(defaults)
    if data is not None:
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: must be a mapping, got {fmt(data)}")
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
    estimation = _window(s, "estimation", n_record, max_lag)
    validation = _window(s, "validation", n_record, max_lag)
    s.done()
    if estimation.first - 1 < max_lag:
        raise ConfigError(
            f"{path}.estimation: must start after the grid's largest lag ({max_lag} samples), "
            f"i.e. first >= {max_lag + 1}, got {[estimation.first, estimation.last]}"
        )
    n_params = grid.na[1] + grid.nb1[1] + grid.nb2[1] + 2
    if estimation.length < 2 * n_params:
        raise ConfigError(
            f"{path}.estimation: must hold at least {2 * n_params} samples for this grid, "
            f"got {estimation.length}"
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
    stages = []
    for name, spec in stage_specs().items():
        defaults = dict(spec.defaults)
        if spec.defaults_from is not None:
            defaults.update(s.data.get(spec.defaults_from) or {})
        data, options = _stage_options(s.get(name, None), f"identify.{name}", spec.options)
        stage = _stage(data, f"identify.{name}", defaults, timing.record_samples)
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


def _data_section(top: Section, model_names: list[str]) -> DataConfig | None:
    value = top.get("data", None)
    if value is None:
        return None
    s = Section(value, "data")
    name = s.get("name", "data")
    if not isinstance(name, str) or not name.isidentifier() or name in model_names:
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
    cs.done()
    w_raw = s.get("w_report", [0.00715, 0.47])
    if (
        not isinstance(w_raw, list)
        or not w_raw
        or not all(isinstance(w, int | float) and not isinstance(w, bool) and w > 0 for w in w_raw)
    ):
        raise ConfigError(f"data.w_report: must be a non-empty list of W > 0, got {fmt(w_raw)}")
    s.done()
    return DataConfig(name=name, columns=columns, w_report=tuple(float(w) for w in w_raw))


# --------------------------------------------------------------------------- entry points


def parse_config(data: Any, name: str) -> Config:
    """Check a parsed YAML document and build the :class:`Config`.

    Parameters
    ----------
    data : object
        The result of ``yaml.safe_load``.
    name : str
        Study name used when the document has no ``name`` key (the file stem).

    Raises
    ------
    ConfigError
        On the first unknown key, wrong type or out-of-range value, naming it.
    """
    top = Section(data, "")
    study_name = top.get("name", name)
    if not isinstance(study_name, str) or not study_name or "/" in study_name:
        raise ConfigError(f"name: must be a non-empty string without '/', got {fmt(study_name)}")
    models = _models_section(top)
    loop = _loop_section(top)
    disturbance, target = _signals_section(top)
    timing = _timing_section(top)
    _check_against_timing(timing, target, models)
    seeds = _seeds_section(top)
    identify = _identify_section(top, timing)
    selection, selection_raw = _selection_section(top)
    data_cfg = _data_section(top, [m.name for m in models])
    top.done()

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
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config ({exc.strerror})") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}: not valid YAML{where}") from exc
    return parse_config(data, path.stem)
