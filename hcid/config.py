"""Study configuration: YAML parsed once into frozen dataclasses.

A config names the HC models, the loop and remnant parameters, the forcing
functions, the timing, the realization seeds, the identification grids and
windows, and the W grid. :func:`load_config` reads and checks everything at
the entry point; the numerical core only ever sees the dataclasses below.

Every error names the dotted key, what is allowed and what was received, e.g.
``identify.direct.na: must be an integer range [lo, hi] within [1, 30], got [0, 3]``.

Windows are written as in the paper: 1-based inclusive sample numbers at the
output rate (``[129, 1088]``); :meth:`Window.rows` gives the Python slice
(``slice(128, 1088)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hcid._checks import (
    GRID_LOWEST,
    Section,
    checked_grid_range,
    fmt,
    int_range,
    integer,
    number_list,
)
from hcid.errors import ConfigError

__all__ = [
    "Config",
    "DataConfig",
    "Disturbance",
    "Grid",
    "HCModel",
    "IdentifyConfig",
    "Loop",
    "Segment",
    "StageConfig",
    "Target",
    "Timing",
    "Window",
    "load_config",
    "parse_config",
]


# --------------------------------------------------------------------------- dataclasses


@dataclass(frozen=True)
class HCModel:
    """Parameters of one HC model (SPEC section 1). Times in s, gains unitless.

    ``Kpt = 0`` means no feedforward path; ``TI`` and ``tau_pt`` are then unused.
    """

    name: str
    Kpt: float
    TI: float
    tau_pt: float
    Kpe: float
    TL: float
    tau_pe: float

    @property
    def has_feedforward(self) -> bool:
        return self.Kpt != 0.0


@dataclass(frozen=True)
class Loop:
    """Plant, neuromuscular and remnant-filter parameters (rad/s, unitless)."""

    Kc: float
    wb: float
    w_nms: float
    zeta_nms: float
    w_n: float
    zeta_n: float
    remnant_ratio: float


@dataclass(frozen=True)
class Disturbance:
    """Multisine disturbance ``fd(t) = sum A_i sin(k_i wm (t + t0) + phi_i)`` (rad)."""

    base_period: float
    time_offset: float
    k: tuple[int, ...]
    amplitude: tuple[float, ...]
    phase: tuple[float, ...]


@dataclass(frozen=True)
class Segment:
    """One target segment: ``kind`` 'c' (hold) or 'p' (parabola), seconds, step in Kt."""

    kind: str
    duration: float
    step: float


@dataclass(frozen=True)
class Target:
    """Parabola target: segments after the run-in, gain Kt in rad."""

    gain: float
    segments: tuple[Segment, ...]


@dataclass(frozen=True)
class Timing:
    """Simulation and output timing (Hz, s)."""

    sim_rate: float
    output_rate: float
    run_in: float
    window: float
    periods: int

    @property
    def sim_dt(self) -> float:
        return 1.0 / self.sim_rate

    @property
    def period_samples(self) -> int:
        return round((self.run_in + self.window) * self.sim_rate)

    @property
    def window_samples(self) -> int:
        """Samples of the measurement window at the simulation rate."""
        return round(self.window * self.sim_rate)

    @property
    def decimation(self) -> int:
        return round(self.sim_rate / self.output_rate)

    @property
    def record_samples(self) -> int:
        """Samples of one record at the output rate (2048 for the paper)."""
        return self.window_samples // self.decimation


@dataclass(frozen=True)
class Grid:
    """Inclusive integer ranges ``(lo, hi)`` of the five ARX structure integers.

    Input 1 is the shifted target ft; input 2 is e (direct, stage 2) or fd
    (stage 1). ``na >= 1``; ``nb >= 0`` (0 drops the input); ``nk >= 0``.

    Raises
    ------
    ConfigError
        If a range is not two integers ``lo <= hi`` or ``lo`` is below the
        smallest allowed value; the message names the field.
    """

    na: tuple[int, int]
    nb1: tuple[int, int]
    nb2: tuple[int, int]
    nk1: tuple[int, int]
    nk2: tuple[int, int]

    def __post_init__(self) -> None:
        for name, lowest in GRID_LOWEST.items():
            object.__setattr__(self, name, checked_grid_range(name, getattr(self, name), lowest))

    @property
    def max_lag(self) -> int:
        """Largest lag (samples) any candidate uses; an input counts only when its nb_hi > 0.

        The first row whose regressors all lie inside the record (SPEC 3: 29 for
        the paper's stage-1 grid).
        """
        lag = self.na[1]
        if self.nb1[1] > 0:
            lag = max(lag, self.nk1[1] + self.nb1[1] - 1)
        if self.nb2[1] > 0:
            lag = max(lag, self.nk2[1] + self.nb2[1] - 1)
        return lag


@dataclass(frozen=True)
class Window:
    """A 1-based inclusive sample range, as the paper writes windows."""

    first: int
    last: int

    def rows(self) -> slice:
        return slice(self.first - 1, self.last)

    @property
    def length(self) -> int:
        return self.last - self.first + 1


@dataclass(frozen=True)
class StageConfig:
    """One identification step: its grid, estimation and validation windows."""

    grid: Grid
    estimation: Window
    validation: Window


@dataclass(frozen=True)
class IdentifyConfig:
    """Identification settings (SPEC section 3)."""

    target_shift: float
    direct: StageConfig
    stage1: StageConfig
    stage2: StageConfig

    def shift_samples(self, rate: float) -> int:
        return round(self.target_shift * rate)


@dataclass(frozen=True)
class DataConfig:
    """How to read measured data: a label and the names of the columns (or .mat variables).

    ``columns`` maps ft, fd, e, u, time, run and rate to names in the file;
    ``w_report`` are the W values at which the report shows the data's models.
    """

    name: str
    columns: dict[str, str]
    w_report: tuple[float, ...]


_DATA_COLUMNS = {"ft": "ft", "fd": "fd", "e": "e", "u": "u", "time": "t", "run": "run", "rate": "rate"}


@dataclass(frozen=True)
class Config:
    """A whole study."""

    name: str
    models: tuple[HCModel, ...]
    loop: Loop
    disturbance: Disturbance
    target: Target
    timing: Timing
    seeds: tuple[int, ...]
    identify: IdentifyConfig
    w_grid: tuple[float, ...]
    target_rate: float = 0.0
    data: DataConfig | None = None
    raw: dict[str, Any] = field(default_factory=dict, repr=False, compare=False, hash=False)

    def model(self, name: str) -> HCModel:
        for m in self.models:
            if m.name == name:
                return m
        raise ConfigError(f"models: no model named {name!r}, have {[m.name for m in self.models]}")

    def to_yaml(self) -> str:
        """The resolved config (defaults filled in) as YAML text."""
        return yaml.safe_dump(self.raw, sort_keys=False)


# --------------------------------------------------------------------------- sections

_PAPER_DIRECT = {
    "na": [1, 7],
    "nb1": [0, 7],
    "nb2": [0, 7],
    "nk1": [1, 50],
    "nk2": [1, 10],
    "estimation": [129, 1088],
    "validation": [1089, 2048],
}
_PAPER_STAGE1 = {
    "na": [1, 10],
    "nb1": [0, 25],
    "nb2": [0, 10],
    "nk1": [1, 5],
    "nk2": [1, 5],
    "estimation": "auto",
    "validation": "auto",
}


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


def _seeds(value: Any) -> tuple[int, ...]:
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

    models_raw = top.get("models")
    if not isinstance(models_raw, dict) or not models_raw:
        raise ConfigError(
            f"models: must be a non-empty mapping of model name to parameters, got {fmt(models_raw)}"
        )
    models = tuple(_model(k, v) for k, v in models_raw.items())

    ls = top.section("loop")
    loop = Loop(
        Kc=ls.number("Kc", 0.0, 1e3, open_lo=True),
        wb=ls.number("wb", 0.0, 1e3, open_lo=True),
        w_nms=ls.number("w_nms", 0.0, 1e3, open_lo=True),
        zeta_nms=ls.number("zeta_nms", 0.0, 10.0, open_lo=True),
        w_n=ls.number("w_n", 0.0, 1e3, open_lo=True),
        zeta_n=ls.number("zeta_n", 0.0, 10.0, open_lo=True),
        remnant_ratio=ls.number("remnant_ratio", 0.0, 0.9),
    )
    ls.done()

    sig = top.section("signals")
    ds = sig.section("disturbance")
    k = ds.get("k")
    if not isinstance(k, list) or not k:
        raise ConfigError(f"signals.disturbance.k: must be a non-empty list of integers, got {fmt(k)}")
    k_int = tuple(integer(v, f"signals.disturbance.k[{i}]", 1, 100_000) for i, v in enumerate(k))
    disturbance = Disturbance(
        base_period=ds.number("base_period", 0.0, 1e5, open_lo=True),
        time_offset=ds.number("time_offset", -1e5, 1e5),
        k=k_int,
        amplitude=number_list(ds, "amplitude", len(k_int)),
        phase=number_list(ds, "phase", len(k_int)),
    )
    ds.done()

    ts = sig.section("target")
    gain_deg = ts.number("gain_deg", 0.0, 180.0)
    segs_raw = ts.get("segments")
    if not isinstance(segs_raw, list) or not segs_raw:
        raise ConfigError(
            f"signals.target.segments: must be a non-empty list of [kind, seconds, step], got {fmt(segs_raw)}"
        )
    segments = []
    for i, seg in enumerate(segs_raw):
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
        segments.append(Segment(seg[0], float(seg[1]), float(seg[2])))
    target = Target(gain=math.radians(gain_deg), segments=tuple(segments))
    ts.done()
    sig.done()

    tm = top.section("timing")
    timing = Timing(
        sim_rate=tm.number("sim_rate", 1.0, 10_000.0),
        output_rate=tm.number("output_rate", 0.1, 10_000.0),
        run_in=tm.number("run_in", 0.0, 1e4),
        window=tm.number("window", 0.0, 1e4, open_lo=True),
        periods=tm.integer("periods", 1, 100),
    )
    tm.done()
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
    segment_total = sum(s.duration for s in segments)
    if segment_total > timing.window + 1e-9:
        raise ConfigError(
            f"signals.target.segments: must last at most timing.window ({timing.window:g} s), "
            f"got {segment_total:g} s"
        )
    for m in models:
        for key, tau in (("tau_pe", m.tau_pe), ("tau_pt", m.tau_pt)):
            if abs(tau * timing.sim_rate - round(tau * timing.sim_rate)) > 1e-6:
                raise ConfigError(
                    f"models.{m.name}.{key}: must be whole samples at timing.sim_rate "
                    f"({timing.sim_rate:g} Hz), got {tau:g} s"
                )

    seeds = _seeds(top.get("seeds"))

    n_record = timing.record_samples
    ids = top.section("identify", {})
    target_shift = ids.number("target_shift", 0.0, 10.0, 1.0)
    if abs(target_shift * timing.output_rate - round(target_shift * timing.output_rate)) > 1e-9:
        raise ConfigError(
            f"identify.target_shift: must be whole samples at timing.output_rate "
            f"({timing.output_rate:g} Hz), got {target_shift:g} s"
        )
    direct = _stage(ids.get("direct", None), "identify.direct", _PAPER_DIRECT, n_record)
    stage1 = _stage(ids.get("stage1", None), "identify.stage1", _PAPER_STAGE1, n_record)
    stage2_raw = ids.get("stage2", None)
    stage2_defaults = {**_PAPER_DIRECT, **(ids.data.get("direct") or {})}
    stage2 = _stage(stage2_raw, "identify.stage2", stage2_defaults, n_record)
    ids.done()
    identify = IdentifyConfig(target_shift=target_shift, direct=direct, stage1=stage1, stage2=stage2)

    sel = top.section("selection", {})
    wg = sel.section("w_grid", {"min": 1e-4, "max": 2.0, "points": 241})
    w_min = wg.number("min", 0.0, 1e3, open_lo=True)
    w_max = wg.number("max", 0.0, 1e3, open_lo=True)
    points = wg.integer("points", 2, 100_000)
    wg.done()
    target_rate = sel.number("target_rate", 0.0, 0.5, 0.0)
    sel.done()
    if w_max <= w_min:
        raise ConfigError(f"selection.w_grid.max: must be > selection.w_grid.min ({w_min:g}), got {w_max:g}")
    data_cfg = _data(top.get("data", None), [m.name for m in models])
    top.done()

    w_grid = tuple(
        float(10 ** (math.log10(w_min) + i * (math.log10(w_max) - math.log10(w_min)) / (points - 1)))
        for i in range(points)
    )
    raw = dict(data)
    raw["name"] = study_name
    raw["identify"] = {
        "target_shift": target_shift,
        "direct": _stage_raw(direct),
        "stage1": _stage_raw(stage1),
        "stage2": _stage_raw(stage2),
    }
    raw["selection"] = {"w_grid": {"min": w_min, "max": w_max, "points": points}, "target_rate": target_rate}
    return Config(
        name=study_name,
        models=models,
        loop=loop,
        disturbance=disturbance,
        target=target,
        timing=timing,
        seeds=seeds,
        identify=identify,
        w_grid=w_grid,
        target_rate=target_rate,
        data=data_cfg,
        raw=raw,
    )


def _data(value: Any, model_names: list[str]) -> DataConfig | None:
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


def _stage_raw(stage: StageConfig) -> dict:
    g = stage.grid
    return {
        "na": list(g.na),
        "nb1": list(g.nb1),
        "nb2": list(g.nb2),
        "nk1": list(g.nk1),
        "nk2": list(g.nk2),
        "estimation": [stage.estimation.first, stage.estimation.last],
        "validation": [stage.validation.first, stage.validation.last],
    }


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
