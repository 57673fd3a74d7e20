"""The dataclasses a study config is parsed into (frozen; the core never sees a raw dict).

Windows are written as in the paper: 1-based inclusive sample numbers at the
output rate (``[129, 1088]``); :meth:`Window.rows` gives the Python slice
(``slice(128, 1088)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import yaml

from hcid.config._checks import GRID_LOWEST, checked_grid_range
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
    "SelectionConfig",
    "StageConfig",
    "Target",
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
    """Identification settings (SPEC section 3): the target shift and every stage by name.

    The stage names are those the registered methods declare
    (:mod:`hcid.methods`): ``direct``, ``stage1`` and ``stage2`` for the paper's two.
    """

    target_shift: float
    stages: tuple[tuple[str, StageConfig], ...]

    def stage(self, name: str) -> StageConfig:
        for key, stage in self.stages:
            if key == name:
                return stage
        raise ConfigError(f"identify.{name}: no such stage, have {[k for k, _ in self.stages]}")

    def shift_samples(self, rate: float) -> int:
        return round(self.target_shift * rate)


@dataclass(frozen=True)
class SelectionConfig:
    """Model selection settings (SPEC sections 4 and 9).

    ``w_grid`` is the log-spaced grid of penalties W; ``criteria`` the named
    criteria (:mod:`hcid.criteria`) with their constants, marked in the thresholds
    table, the report and the CLI; ``target_rate`` the largest false-positive and
    false-negative rate a W calibration accepts.
    """

    w_grid: tuple[float, ...]
    target_rate: float
    criteria: tuple[tuple[str, tuple[tuple[str, float], ...]], ...]


@dataclass(frozen=True)
class DataConfig:
    """How to read measured data: a label and the names of the columns (or .mat variables).

    ``columns`` maps ft, fd, e, u, time, run and rate to names in the file;
    ``w_report`` are the W values at which the report shows the data's models.
    """

    name: str
    columns: dict[str, str]
    w_report: tuple[float, ...]


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
    selection: SelectionConfig
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
