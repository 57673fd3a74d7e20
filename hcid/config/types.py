"""The dataclasses a study config is parsed into (frozen; the core never sees a raw dict).

Windows are written as in the paper: 1-based inclusive sample numbers at the
output rate (``[129, 1088]``); :meth:`Window.rows` gives the Python slice
(``slice(128, 1088)``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

from hcid.config._checks import GRID_LOWEST, checked_grid_range
from hcid.config.fit_settings import FitSettings
from hcid.config.plant import Plant, PlantByFactor
from hcid.errors import ConfigError

__all__ = [
    "Config",
    "DataConfig",
    "FileSignal",
    "Forcing",
    "Grid",
    "HCModel",
    "IdentifyConfig",
    "Loop",
    "Multisine",
    "Plant",
    "PlantByFactor",
    "Segment",
    "Segments",
    "SelectionConfig",
    "StageConfig",
    "Timing",
    "Window",
]


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
    """Plant, neuromuscular and remnant-filter parameters (rad/s, unitless).

    ``plant`` is the controlled element (a config's ``loop.plant``, or the paper's
    ``Kc wb / (s (s + wb))`` from ``loop.Kc`` and ``loop.wb``), or a plant per level of a data
    factor (a measured study's: :meth:`Config.with_plant` gives a level's loop). ``disturbance_at``
    is ``output`` (the paper: ``theta = Yc u + fd``) or ``input`` (``theta = Yc (u + fd)``).
    """

    plant: Plant | PlantByFactor
    w_nms: float
    zeta_nms: float
    w_n: float
    zeta_n: float
    remnant_ratio: float
    disturbance_at: str = "output"
    #: Kn itself (white noise of unit variance at the simulation rate), when the config gives it
    #: instead of ``remnant_ratio``: a twin given the remnant a person showed.
    remnant_gain: float | None = None


@dataclass(frozen=True)
class Multisine:
    """Sum of sines ``f(t) = sum A_i sin(k_i wm (t + t0) + phi_i)`` (rad), ``wm = 2 pi / base_period``.

    The paper's disturbance (SPEC 2); periodic in ``base_period``.
    """

    base_period: float
    time_offset: float
    k: tuple[int, ...]
    amplitude: tuple[float, ...]
    phase: tuple[float, ...]

    @property
    def band(self) -> tuple[float, float]:
        """Lowest and highest frequency (rad/s); for the disturbance, where identified models are
        expected to be accurate (SPEC 5: 0.23..17.33 rad/s for the paper's 20 sines).

        Examples
        --------
        >>> Multisine(81.92, 8.09, (3, 226), (1.0, 1.0), (0.0, 0.0)).band
        (0.23009711818284617, 17.333982903107746)
        """
        base = 2.0 * math.pi / self.base_period
        return float(min(self.k) * base), float(max(self.k) * base)


@dataclass(frozen=True)
class Segment:
    """One segment: ``kind`` 'c' (hold), 'p' (parabola) or 'r' (ramp), seconds, step in units of the gain."""

    kind: str
    duration: float
    step: float


@dataclass(frozen=True)
class Segments:
    """Segments after each period's run-in (the paper's target, SPEC 2), gain in rad."""

    gain: float
    segments: tuple[Segment, ...]


@dataclass(frozen=True)
class FileSignal:
    """A forcing function read from a column of a data file (CSV, Parquet or .mat).

    ``values`` (rad) are the column's samples at ``rate`` Hz (of run ``run`` when
    given, told apart by ``run_column``), None until the file is read
    (:func:`hcid.assembly.resolve.resolve_config`); the measurement window starts ``start``
    s into them and is taken as one period of the signal.
    """

    path: str
    column: str
    rate: float
    start: float
    run: int | None = None
    run_column: str = "run"
    values: np.ndarray | None = field(default=None, repr=False, compare=False, hash=False)


#: A forcing function (target or disturbance): one of the kinds of ``signals.<name>.kind``.
Forcing = Multisine | Segments | FileSignal


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
    def n_candidates(self) -> int:
        """Number of distinct candidates: a dropped input (nb = 0) is enumerated once.

        Examples
        --------
        >>> Grid(na=(1, 7), nb1=(0, 7), nb2=(0, 7), nk1=(1, 50), nk2=(1, 10)).n_candidates  # SPEC 3
        174447
        """

        def delays(nb: tuple[int, int], nk: tuple[int, int]) -> int:
            used = nb[1] - max(nb[0], 1) + 1 if nb[1] > 0 else 0
            return max(used, 0) * (nk[1] - nk[0] + 1) + (1 if nb[0] == 0 else 0)

        return (self.na[1] - self.na[0] + 1) * delays(self.nb1, self.nk1) * delays(self.nb2, self.nk2)

    @property
    def max_lag(self) -> int:
        """Largest lag (samples) any candidate uses; an input counts only when its nb_hi > 0.

        The first row whose regressors all lie inside the record (SPEC 3: 29 for
        the paper's stage-1 grid).

        Examples
        --------
        >>> Grid(na=(1, 10), nb1=(0, 25), nb2=(0, 10), nk1=(1, 5), nk2=(1, 5)).max_lag
        29
        """
        lag = self.na[1]
        if self.nb1[1] > 0:
            lag = max(lag, self.nk1[1] + self.nb1[1] - 1)
        if self.nb2[1] > 0:
            lag = max(lag, self.nk2[1] + self.nb2[1] - 1)
        return lag


@dataclass(frozen=True)
class Window:
    """A 1-based inclusive sample range, as the paper writes windows.

    Examples
    --------
    >>> Window(129, 1088).rows(), Window(129, 1088).length
    (slice(128, 1088, None), 960)
    """

    first: int
    last: int

    def rows(self) -> slice:
        return slice(self.first - 1, self.last)

    @property
    def length(self) -> int:
        return self.last - self.first + 1


@dataclass(frozen=True)
class StageConfig:
    """One identification stage: its grid, estimation and validation windows.

    ``options`` holds the stage's further keys (declared by its method,
    :attr:`hcid.methods.StageSpec.options`) whose configured value differs from
    the default, as ``(name, value)`` pairs; empty for the SPEC behaviour.
    """

    grid: Grid
    estimation: Window
    validation: Window
    options: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class IdentifyConfig:
    """Identification settings (SPEC section 3): the target shift and the stages by name.

    ``sections`` are the config's stage sections as given and ``windows_in`` the
    unit of their windows; ``stages`` are the built stages of the methods a
    command uses (:func:`hcid.config.stages.build_stages`, through
    :func:`hcid.assembly.resolve.resolve_config`): ``direct``, ``stage1`` and ``stage2`` for
    the paper's two methods. A stage not built is not in ``stages``.
    """

    target_shift: float
    stages: tuple[tuple[str, StageConfig], ...]
    sections: tuple[tuple[str, Any], ...] = field(default=(), compare=False, hash=False)
    windows_in: str = field(default="samples", compare=False)

    def stage(self, name: str) -> StageConfig:
        for key, stage in self.stages:
            if key == name:
                return stage
        raise ConfigError(
            f"identify.{name}: not resolved for this command, have {[k for k, _ in self.stages]}"
        )

    def shift_samples(self, rate: float) -> int:
        return round(self.target_shift * rate)


@dataclass(frozen=True)
class SelectionConfig:
    """Model selection settings (SPEC sections 4 and 9).

    ``w_grid`` is the log-spaced grid of penalties W; ``criteria`` the named
    criteria (:mod:`hcid.selection.criteria`) with their constants, marked in the thresholds
    table, the report and the CLI; ``target_rate`` the largest false-positive and
    false-negative rate a W calibration accepts.
    """

    w_grid: tuple[float, ...]
    target_rate: float
    criteria: tuple[tuple[str, tuple[tuple[str, float], ...]], ...]


@dataclass(frozen=True)
class DataConfig:
    """How to read measured data: a label and the names of the columns (or .mat variables).

    ``columns`` maps ft, fd, e, u, theta, time, run and rate to names in the file
    (defaults: the same names, time ``t``; ``e`` may be missing when ``theta``, the
    system output, is there: then ``e = ft - theta``); ``time_default`` says the
    time column was not named, so ``time`` is accepted too. ``w_report`` are the W
    values at which the report shows the data's models; ``lead_in`` (s, whole
    samples at the analysis rate) is skipped at the start of every run, after the
    data are resampled to the analysis rate. A column given as an integer is a CSV
    column's position (1 for the first). ``pattern`` (e.g.
    ``{subject}_{condition}_{trial}.csv``, or ``{subject}/{trial}.csv`` with the folder) gives
    each file's factors from its name.
    """

    name: str
    columns: dict[str, str | int]
    w_report: tuple[float, ...]
    lead_in: float = 0.0
    time_default: bool = False
    pattern: str | None = None
    #: File-name globs (``fnmatch``; with ``/``, over the name and the folders it sits in) of files
    #: a folder or glob of ``--data`` finds that are not runs (a logger's reset segments): left out,
    #: and listed as skipped with the glob that left each out.
    exclude: tuple[str, ...] = ()
    #: A MATLAB file's struct variable holding the signals as fields (None: plain variables).
    struct: str | None = None
    #: The axes of a MATLAB file's N-D arrays: ``sample`` and one factor per other axis, e.g.
    #: ``("sample", "trial", "subject")`` for arrays of samples x repeats x participants.
    dimensions: tuple[str, ...] | None = None
    #: Check every run against the configured plant (theta = ft - e against Yc at the forcing
    #: lines); False for recordings the plant does not describe whole (a display delay it leaves out).
    plant_check: bool = True


@dataclass(frozen=True)
class Config:
    """A whole study, or a data-only config (no models, loop, signals or seeds: ``simulates`` is False).

    ``data`` is always set after parsing (the default column names when the config has
    no ``data`` section)."""

    name: str
    models: tuple[HCModel, ...]
    loop: Loop | None
    disturbance: Forcing | None
    target: Forcing | None
    timing: Timing
    seeds: tuple[int, ...]
    identify: IdentifyConfig
    selection: SelectionConfig
    data: DataConfig | None = None
    #: The parametric HC fit's settings (config section ``fit_hc``).
    fit_hc: FitSettings | None = None
    #: The remnant's white-noise stream (``seeds: {first, count, stream}``): 0, each seed's own
    #: stream (numpy's ``default_rng(seed)``); else ``default_rng([stream, seed])``. hcid's twins
    #: take a digest of their group and its data (:attr:`hcid.pipeline.twins.TwinSource.noise_stream`).
    noise_stream: int = 0
    raw: dict[str, Any] = field(default_factory=dict, repr=False, compare=False, hash=False)

    @property
    def simulates(self) -> bool:
        """Whether the config holds the simulation sections (models, loop, signals, seeds); a
        measured study's config may hold a loop (its plant) and still not simulate."""
        return bool(self.models)

    def require_simulation(self, command: str) -> None:
        """Refuse a command that simulates on a data-only config.

        Raises
        ------
        ConfigError
            Naming the missing sections and the command.
        """
        if not self.simulates:
            missing = (
                "models, signals, timing, seeds"
                if self.loop is not None
                else "models, loop, signals, timing, seeds"
            )
            hint = (
                "; for a measured study, `hcid analyse` calibrates W on twins of the data's own fitted model"
            )
            raise ConfigError(
                f"{missing}: missing; `hcid {command}` simulates and needs them (this config describes "
                f"measured data only{hint if self.loop is not None else ''})"
            )

    @property
    def plant_factor(self) -> str | None:
        """The data factor whose levels have a plant each (``loop.plant.by``); None for one plant."""
        plant = None if self.loop is None else self.loop.plant
        return plant.by if isinstance(plant, PlantByFactor) else None

    def with_plant(self, level: str) -> Config:
        """This config with the plant of ``level`` (of :attr:`plant_factor`) as its one plant, in
        ``raw`` too (the twins' configs copy ``raw``'s plant): what a run of that level is analysed
        with, the same as a config giving that plant alone.

        Raises
        ------
        ConfigError
            For a config of one plant, or a level ``loop.plant.levels`` does not give.
        """
        if self.plant_factor is None:
            raise ConfigError(f"loop.plant: gives one plant, not one per level (asked for {level!r})")
        plant = self.loop.plant.of(level)
        raw_loop = dict(self.raw.get("loop", {}))
        raw_loop["plant"] = raw_loop["plant"]["levels"][level]
        loop = dataclasses.replace(self.loop, plant=plant)
        return dataclasses.replace(self, loop=loop, raw={**self.raw, "loop": raw_loop})

    def require_one_plant(self, what: str) -> None:
        """Refuse a plant per level where ``what`` (a command) needs one plant.

        Raises
        ------
        ConfigError
            Naming ``loop.plant.by`` and its levels.
        """
        by = self.plant_factor
        if by is not None:
            raise ConfigError(
                f"loop.plant.by: {what} needs one plant; this config gives one per level of {by!r} "
                f"({', '.join(self.loop.plant.names)}): give each plant a config of its own"
            )

    @staticmethod
    def band_of(disturbance: Forcing | None, timing: Timing) -> tuple[float, float]:
        """The disturbance band (rad/s) where identified models are expected to be accurate:
        a multisine's lowest and highest frequency (SPEC 5: 0.23..17.33 rad/s for the paper);
        for any other disturbance, or none, the window's fundamental to the analysis Nyquist."""
        if isinstance(disturbance, Multisine):
            return disturbance.band
        return 2 * math.pi / timing.window, math.pi * timing.output_rate

    @property
    def disturbance_band(self) -> tuple[float, float]:
        """:meth:`band_of` this config's disturbance and timing."""
        return self.band_of(self.disturbance, self.timing)

    def model(self, name: str) -> HCModel:
        for m in self.models:
            if m.name == name:
                return m
        raise ConfigError(f"models: no model named {name!r}, have {[m.name for m in self.models]}")

    def to_yaml(self) -> str:
        """The resolved config (defaults filled in) as YAML text."""
        return yaml.safe_dump(self.raw, sort_keys=False)
