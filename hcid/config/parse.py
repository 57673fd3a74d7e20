"""Describe a YAML study config as a :class:`~hcid.config.types.Config`, one section at a time.

Each ``_section`` function checks one top-level section and returns its
dataclass; :func:`describe_config` runs them in order and checks what spans
sections (timing against the target, delays against the simulation rate).
The forcing functions and timing are parsed in :mod:`hcid.config.forcing`, the
``identify`` section in :mod:`hcid.config.stages`, ``loop.plant`` in :mod:`hcid.config.plant`.
Nothing is read from disk: :mod:`hcid.assembly.resolve` reads what a config names and builds the
methods' stages.
"""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path
from typing import Any

from hcid.config._checks import LIMITS, RESERVED_FACTORS, Section, fmt, integer
from hcid.config.fit_settings import FitSettings, parse_fit_settings
from hcid.config.forcing import check_against_timing, signals_section, timing_section
from hcid.config.plant import PLANTS, plant_section
from hcid.config.stages import MOST_LAGS, identify_section
from hcid.config.types import (
    Config,
    DataConfig,
    FileSignal,
    HCModel,
    Loop,
    Plant,
    SelectionConfig,
    Timing,
)
from hcid.errors import ConfigError

__all__ = ["DISTURBANCE_POINTS", "LIMITS", "PLANTS", "default_data", "describe_config"]

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
#: A data config may hold a ``loop`` (its plant, for the parametric fit and the twins): these
#: are the sections that make a config a simulating one.
_SIMULATING = ("models", "signals", "seeds")


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
        tau_pt=s.number("tau_pt", -2.0, 2.0, 0.0),  # negative: anticipation of the target
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


#: Where the disturbance enters: at the plant's output (the paper) or its input.
DISTURBANCE_POINTS = ("output", "input")


#: A measured study's loop needs only its plant: the rest is the simulations' (SPEC 1's values).
_LOOP_DEFAULTS = {"w_nms": 10.1, "zeta_nms": 0.35, "w_n": 12.7, "zeta_n": 0.26, "remnant_ratio": 0.15}


def _loop_section(top: Section, plant_only: bool = False) -> Loop:
    """``loop``; with ``plant_only`` (a measured study) every key but the plant may be left out,
    and the plant may be one per level of a data factor."""
    s = top.section("loop")
    if "plant" in s.data:
        both = [k for k in ("Kc", "wb") if k in s.data]
        if both:
            raise ConfigError(
                f"loop.{both[0]}: give the plant either as loop.Kc and loop.wb (the paper's "
                "Kc wb / (s (s + wb))) or as loop.plant, not both"
            )
        plant = plant_section(s, per_level=plant_only)
    else:
        Kc = s.number("Kc", 0.0, 1e3, open_lo=True)
        plant = Plant.second_order(Kc, s.number("wb", 0.0, 1e3, open_lo=True))
    point = s.get("disturbance_at", "output")
    if point not in DISTURBANCE_POINTS:
        raise ConfigError(
            f"loop.disturbance_at: must be one of {', '.join(DISTURBANCE_POINTS)}, got {fmt(point)}"
        )

    def number(key: str, lo: float, hi: float, **kw) -> float:
        if plant_only:
            return s.number(key, lo, hi, _LOOP_DEFAULTS[key], **kw)
        return s.number(key, lo, hi, **kw)

    loop = Loop(
        plant=plant,
        w_nms=number("w_nms", 0.0, 1e3, open_lo=True),
        zeta_nms=number("zeta_nms", 0.0, 10.0, open_lo=True),
        w_n=number("w_n", 0.0, 1e3, open_lo=True),
        zeta_n=number("zeta_n", 0.0, 10.0, open_lo=True),
        remnant_ratio=number("remnant_ratio", 0.0, 0.9) if "remnant_gain" not in s.data else 0.0,
        disturbance_at=point,
        remnant_gain=s.number("remnant_gain", 0.0, 1e3) if "remnant_gain" in s.data else None,
    )
    if "remnant_gain" in s.data and "remnant_ratio" in s.data:
        raise ConfigError(
            "loop.remnant_gain: give the remnant either as loop.remnant_ratio (var(n)/var(u) in the "
            "disturbance-only task) or as loop.remnant_gain (Kn), not both"
        )
    s.done()
    return loop


def _seeds_section(top: Section) -> tuple[tuple[int, ...], int]:
    """The seeds and the noise stream (``stream``, 0 where not given: :attr:`Config.noise_stream`)."""
    value = top.get("seeds")
    if isinstance(value, dict):
        s = Section(value, "seeds")
        first = s.integer("first", 0, 2**31 - 1)
        count = s.integer("count", 1, LIMITS["seeds"])
        stream = s.integer("stream", 0, 2**63 - 1, 0)
        s.done()
        return tuple(range(first, first + count)), stream
    if not isinstance(value, list) or not value:
        raise ConfigError(
            f"seeds: must be a non-empty list of integers or {{first, count}}, got {fmt(value)}"
        )
    if len(value) > LIMITS["seeds"]:
        raise ConfigError(f"seeds: must hold at most {LIMITS['seeds']:,} seeds, got {len(value):,}")
    seeds = tuple(integer(v, f"seeds[{i}]", 0, 2**31 - 1) for i, v in enumerate(value))
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"seeds: must not repeat a seed, got {list(seeds)}")
    return seeds, 0


# --------------------------------------------------------------------------- selection and data


#: The criteria marked when a config names none (:data:`hcid.selection.criteria.DEFAULT`, resolved there).
DEFAULT_CRITERIA = ("aic", "bic", "mbic")


def _criteria(s: Section) -> tuple[tuple[str, tuple[tuple[str, float], ...]], ...]:
    """The criteria as given: names and constants (checked against the registry on resolution)."""
    raw = s.get("criteria", {name: {} for name in DEFAULT_CRITERIA})
    if isinstance(raw, list):
        raw = {name: {} for name in raw}
    if not isinstance(raw, dict) or not raw:
        raise ConfigError(
            f"selection.criteria: must be a non-empty mapping of criterion name to constants, got {fmt(raw)}"
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
        out.append((str(name), tuple((str(k), float(v)) for k, v in constants.items())))
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


def data_identify_defaults(timing: Timing, where: str = "data.analysis_rate") -> dict:
    """The identify section of a measured study that gives none: SPEC 3's grids and windows in
    seconds, scaled to the analysis rate and the record.

    Delays: direct and final stages ``nk_ft`` up to 2 s and ``nk_e`` up to 0.4 s, stage 1 both up
    to 0.2 s (at least one sample); orders as SPEC 3, stage 1's nb1 up to 1 s of lags above 25 Hz
    (its ft_s lags must reach the target shift); estimation ``[W/16, 17 W/32)`` and
    validation ``[17 W/32, W)`` of the window W (the paper's 129..1088 and 1089..2048 of 2048
    samples); target shift 1 s. At 25 Hz and W = 81.92 s this is SPEC 3's section exactly. Up to
    60 Hz: stage 1's 1 s of lags is then the most a grid holds (:data:`MOST_LAGS`); above it, a
    ConfigError naming ``where`` (analyse at a lower rate, or give the identify section).

    Examples
    --------
    >>> d = data_identify_defaults(Timing(20.0, 20.0, 0.0, 40.0, 1))
    >>> d["direct"]["nk1"], d["direct"]["nk2"], d["direct"]["estimation"], d["direct"]["validation"]
    ([1, 40], [1, 8], [2.5, 21.25], [21.25, 40.0])
    """
    rate, window = timing.output_rate, timing.window
    n = round(window * rate)

    def samples(seconds: float) -> int:
        return max(1, round(seconds * rate))

    if samples(1.0) > MOST_LAGS:
        raise ConfigError(
            f"{where}: the default identification grids (SPEC 3's in seconds) reach {MOST_LAGS / 1.0:g} Hz "
            f"(stage 1's 1 s of lags, at most {MOST_LAGS}), got {rate:g} Hz; analyse at a lower rate "
            "(25 Hz is the paper's) or give the identify section"
        )
    cut = (round(n / 16) / rate, round(17 * n / 32) / rate)
    final = {
        "na": [1, 7],
        "nb1": [0, 7],
        "nb2": [0, 7],
        "nk1": [1, samples(2.0)],
        "nk2": [1, samples(0.4)],
        "estimation": [cut[0], cut[1]],
        "validation": [cut[1], n / rate],
    }
    return {
        "target_shift": round(rate) / rate,
        "windows_in": "seconds",
        "direct": dict(final),
        # Stage 1's ft_s lags must reach the 1 s target shift (ft enters e at lag 0): nb1 grows
        # with the rate above 25 Hz.
        "stage1": {
            "na": [1, 10],
            "nb1": [0, max(25, samples(1.0))],
            "nb2": [0, 10],
            "nk1": [1, samples(0.2)],
            "nk2": [1, samples(0.2)],
            "estimation": "auto",
            "validation": "auto",
        },
        "stage2": dict(final),
    }


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
    columns, time_default = _data_columns(s.section("columns", {}))
    w_raw = s.get("w_report", [0.00715, 0.47])
    if (
        not isinstance(w_raw, list)
        or not w_raw
        or not all(isinstance(w, int | float) and not isinstance(w, bool) and w > 0 for w in w_raw)
    ):
        raise ConfigError(f"data.w_report: must be a non-empty list of W > 0, got {fmt(w_raw)}")
    pattern = s.get("pattern", None)
    if pattern is not None:
        check_pattern(pattern, "data.pattern")
    exclude = s.get("exclude", [])
    if isinstance(exclude, str):
        exclude = [exclude]
    if not isinstance(exclude, list) or not all(
        isinstance(x, str) and x.strip() and not {".", ".."} & set(x.split("/")) for x in exclude
    ):
        raise ConfigError(
            "data.exclude: must be a list of file-name globs such as ['*_rst?.csv', 'desktop.ini'] "
            f"(with '/', over the folders too; no '.' or '..' part), got {fmt(exclude)}"
        )
    struct = s.get("struct", None)
    if struct is not None and (not isinstance(struct, str) or not struct.isidentifier()):
        raise ConfigError(f"data.struct: must be a MATLAB variable name, got {fmt(struct)}")
    dimensions = _data_dimensions(s.get("dimensions", None))
    plant_check = s.get("plant_check", True)
    if not isinstance(plant_check, bool):
        raise ConfigError(f"data.plant_check: must be true or false, got {fmt(plant_check)}")
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
        pattern=pattern,
        exclude=tuple(exclude),
        struct=struct,
        dimensions=dimensions,
        plant_check=plant_check,
    )


def _data_columns(cs: Section) -> tuple[dict[str, str | int], bool]:
    """``data.columns``: each signal's column (a name, or a CSV position from 1), and whether the
    time column is the default's (the file may then have none)."""
    columns = {}
    for key, default in _DATA_COLUMNS.items():
        col = cs.get(key, default)
        position = isinstance(col, int) and not isinstance(col, bool) and 1 <= col <= 10_000
        if not position and (not isinstance(col, str) or not col):
            raise ConfigError(
                f"data.columns.{key}: must be a column or variable name, or a CSV column's position "
                f"(1 for the first), got {fmt(col)}"
            )
        columns[key] = col
    time_default = "time" not in cs.data
    cs.done()
    return columns, time_default


def _data_dimensions(dimensions) -> tuple[str, ...] | None:
    """``data.dimensions`` (a MATLAB array's axes): each named once, ``sample`` among them, the
    others factor names."""
    if dimensions is None:
        return None
    ok = isinstance(dimensions, list) and all(isinstance(d, str) for d in dimensions)
    if not ok or dimensions.count("sample") != 1 or len(set(dimensions)) != len(dimensions):
        raise ConfigError(
            f"data.dimensions: must name each axis once, 'sample' among them (e.g. [sample, trial, "
            f"subject]), got {fmt(dimensions)}"
        )
    for d in dimensions:
        if d != "sample" and (not d.isidentifier() or d in RESERVED_FACTORS):
            raise ConfigError(
                f"data.dimensions: factor {fmt(d)} must be an identifier other than "
                f"{', '.join(RESERVED_FACTORS)}"
            )
    return tuple(dimensions)


_PLACEHOLDER = re.compile(r"\{([^{}]*)\}")


def check_pattern(pattern: object, key: str) -> tuple[str, ...]:
    """The factor names of a file-name pattern such as ``{subject}_{condition}_{trial}.csv``; a
    pattern with ``/`` matches the file's name and the folders it sits in
    (``{subject}/{stamp}_{trial}.csv``: the subject from the file's folder).

    Raises
    ------
    ConfigError
        For a pattern that is not a string, holds no ``{factor}``, a factor that is not an
        identifier or is reserved (:data:`RESERVED_FACTORS`), a repeated factor, two factors
        with nothing between them, a backslash, or an empty, ``.`` or ``..`` folder part.
    """
    if not isinstance(pattern, str) or not pattern:
        raise ConfigError(
            f"{key}: must be a file-name pattern such as '{{subject}}_{{trial}}.csv', got {fmt(pattern)}"
        )
    names = _PLACEHOLDER.findall(pattern)
    if not names:
        raise ConfigError(f"{key}: names no factor ({{subject}}, {{condition}}, ...): {fmt(pattern)}")
    for name in names:
        if not name.isidentifier() or name in RESERVED_FACTORS:
            raise ConfigError(
                f"{key}: factor {fmt(name)} must be an identifier other than {', '.join(RESERVED_FACTORS)}"
            )
    if len(set(names)) != len(names):
        raise ConfigError(f"{key}: a factor appears twice in {fmt(pattern)}")
    if "}{" in pattern:
        raise ConfigError(
            f"{key}: two factors with nothing between them cannot be told apart: {fmt(pattern)}"
        )
    parts = pattern.split("/")
    if "\\" in pattern or any(p in ("", ".", "..") for p in parts):
        raise ConfigError(
            f"{key}: matches a file's name and the folders it sits in, separated by '/' (e.g. "
            f"'{{subject}}/{{trial}}.csv'), with no empty, '.' or '..' part: {fmt(pattern)}"
        )
    return tuple(names)


def _fit_hc_section(top: Section, band: tuple[float, float], timing: Timing) -> FitSettings:
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


def describe_config(data: Any, name: str, base: Path | None = None) -> Config:
    """Check a parsed YAML document and describe it as a :class:`Config`, reading nothing.

    What needs other layers is left for :func:`hcid.assembly.resolve.resolve_config`: the
    columns of forcing files (``FileSignal.values`` is None), the stages of the
    methods (``identify.stages`` is empty; each section is kept as given), the
    criteria's registry and the closed loops' stability.

    Parameters
    ----------
    data : object
        The result of ``yaml.safe_load``; not modified.
    name : str
        Study name used when the document has no ``name`` key (the file stem).
    base : Path, optional
        Folder that relative file paths in the config are relative to (the config's own).

    Raises
    ------
    ConfigError
        On the first unknown key, wrong type or out-of-range value, naming it.
    """
    top = Section(data, "")
    study_name = _study_name(top.get("name", name))
    simulates = "data" not in top.data or any(k in top.data for k in _SIMULATING)
    given_data = data.get("data") if isinstance(data.get("data"), dict) else {}
    if not simulates and "timing" in data and ({"analysis_rate", "window"} & set(given_data)):
        raise ConfigError(
            "timing: a measured study's timing is data.analysis_rate and data.window, or a timing "
            "section (sim_rate, output_rate, run_in, window, periods), not both; leave timing out"
        )
    if not simulates and "identify" not in top.data:
        # A measured study without an identify section: the paper's grids and windows in
        # seconds, scaled to the analysis rate and the record (data_identify_defaults).
        given = Section(data, "")
        timing = timing_section(given) if "timing" in data else _data_timing(given)
        where = "timing.output_rate" if "timing" in data else "data.analysis_rate"
        data = {**data, "identify": data_identify_defaults(timing, where)}
        top = Section(data, "")
        top.get("name", name)
    if simulates:
        models = _models_section(top)
        loop = _loop_section(top)
        disturbance, target = signals_section(top, base)
        timing = timing_section(top)
        check_against_timing(timing, (disturbance, target), models)
        seeds, noise_stream = _seeds_section(top)
    else:
        models, disturbance, target, seeds, noise_stream = (), None, None, (), 0
        top.get("loop", None), top.get("timing", None)  # optional: named among the allowed keys
        loop = _loop_section(top, plant_only=True) if "loop" in top.data else None
        timing = timing_section(top) if "timing" in top.data else _data_timing(top)
    identify = identify_section(top, timing)
    selection, selection_raw = _selection_section(top)
    data_cfg = _data_section(top, [m.name for m in models], timing)
    fit_hc = _fit_hc_section(top, Config.band_of(disturbance, timing), timing)
    top.done()
    raw = copy.deepcopy(data)
    raw["name"] = study_name
    raw["selection"] = selection_raw
    for key, spec in (("disturbance", disturbance), ("target", target)):
        if isinstance(spec, FileSignal):
            # The run's config.yaml (read back by `hcid report` from the run directory)
            # names the file by its absolute path.
            raw["signals"][key]["path"] = str(Path(spec.path).resolve())
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
        noise_stream=noise_stream,
        raw=raw,
    )
