"""The public API: read records, describe the experiment, identify, select at W, fit the HC model.

Everything a notebook needs, with no YAML and no run directory::

    import numpy as np
    import hcid

    records = hcid.read_records("trials.csv", columns={"ft": "target", "e": "error"})
    result = hcid.identify(records[1], method="direct")      # every candidate of the grid
    model = result.select(result.w_bic)                       # the model MSC selects at W
    paths = model.frequency_response(np.logspace(-1, 1.5))   # {"ft": Hft, "e": He}
    fit = hcid.fit_hc(model, records[1], hcid.Experiment(hcid.Plant.integrator(1.5)))

The command-line tool runs the same functions over many records (:mod:`hcid.pipeline`).
"""

from __future__ import annotations

import dataclasses
import numbers
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from hcid import hcfit, methods, tables
from hcid.analysis.fourier import forcing_lines, is_other_plant, plant_mismatch
from hcid.assembly.resolve import resolve_identify
from hcid.config import Config, DataConfig, Forcing, IdentifyConfig, Plant
from hcid.config.parse import data_identify_defaults, default_data
from hcid.config.stages import record_timing
from hcid.errors import ConfigError, DataError, IdentificationError, checked_rate
from hcid.hcfit.selected import SelectedModel, fit_selected
from hcid.io.measured import TIME_JITTER, check_signal, read_runs, time_rate
from hcid.loop.hcmodel import transfer_function
from hcid.selection import criteria
from hcid.selection.frontier import Frontier
from hcid.selection.over_w import SelectionPath

__all__ = [
    "Experiment",
    "IdentificationResult",
    "Record",
    "fit_hc",
    "identification_settings",
    "identify",
    "read_records",
]


@dataclass(frozen=True)
class Record:
    """One run of a tracking task at its analysis rate.

    Attributes
    ----------
    run : int
        The run's id, as its file gives it.
    rate : float
        Sample rate (Hz).
    t : ndarray, shape (N,)
        Time (s), 0 at the first sample kept (after any lead-in).
    ft, fd, e, u : ndarray, shape (N,)
        Target, disturbance, error ``ft - theta`` and the human's output (rad).
    """

    run: int
    rate: float
    t: np.ndarray = field(repr=False)
    ft: np.ndarray = field(repr=False)
    fd: np.ndarray = field(repr=False)
    e: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        checked_rate(self.rate, DataError)
        n = None
        for name in ("ft", "t", "fd", "e", "u"):  # ft first: every other has its length
            x = check_signal(getattr(self, name), f"record {name}")
            if x.ndim != 1 or (n is not None and x.size != n):
                want = "1-D" if n is None else f"1-D with the length of ft ({n})"
                raise DataError(f"record {name}: must be {want}, got shape {x.shape}")
            n = x.size if name == "ft" else n
            object.__setattr__(self, name, x)
        object.__setattr__(self, "rate", float(self.rate))
        time_rate(self.t, "record t", default=self.rate)  # uniform and increasing, as a file's time
        off = np.abs(np.diff(self.t) * self.rate - 1.0) > TIME_JITTER  # and each step 1/rate
        if off.any():
            k = int(np.argmax(off))
            raise DataError(
                f"record t: step {self.t[k + 1] - self.t[k]:.6g} s at sample {k + 1}, not 1/rate "
                f"({1 / self.rate:.6g} s)"
            )

    @property
    def signals(self) -> dict[str, np.ndarray]:
        """``{"ft", "fd", "e", "u"}``: the record as the methods read it."""
        return {name: getattr(self, name) for name in tables.SIGNALS}

    def to_arrow(self) -> pa.Table:
        """One row per sample: run, k, t, ft, fd, e, u."""
        n = self.ft.size
        columns = {
            "run": np.full(n, self.run, dtype=np.int64),
            "k": np.arange(n, dtype=np.int64),
            "t": self.t,
        }
        return pa.table({**columns, **self.signals})


def read_records(
    path: str | Path,
    *,
    columns: Mapping[str, str] | None = None,
    rate: float | None = None,
    lead_in: float = 0.0,
) -> dict[int, Record]:
    """Read a measured-data file (CSV, Parquet or MATLAB ``.mat``) into records, by run id.

    Parameters
    ----------
    path : str or Path
        The file; at most 1 GiB. Several runs are told apart by a run column.
    columns : mapping, optional
        The file's names (str), or its column positions (int, 1 for the first column, as a
        config's ``data.columns``), of ``ft``, ``fd``, ``e``, ``u``, ``theta`` (system output, for
        ``e = ft - theta``), ``time``, ``run`` and ``rate``; unnamed ones keep their
        default names (``t`` or ``time``, ``ft``, ``fd``, ``e``, ``u``, ``run``).
    rate : float, optional
        Analysis rate (Hz): a run recorded faster is resampled to it once (zero
        phase). Default: the file's own rate.
    lead_in : float
        Seconds skipped at the start of every run (after resampling).

    Returns
    -------
    dict of int to Record

    Raises
    ------
    DataError
        One line naming the file and what is wrong.
    """
    if not isinstance(path, str | Path):
        raise DataError(f"path: must be a file's path (str or Path), got {type(path).__name__}")
    data = default_data()
    given = dict(columns or {})
    unknown = sorted(set(given) - set(data.columns))
    if unknown:
        raise ConfigError(f"columns: unknown signal {unknown[0]!r} (allowed: {', '.join(data.columns)})")
    if not (isinstance(lead_in, int | float) and 0 <= lead_in < 1e4):
        raise ConfigError(f"lead_in: must be a number of seconds in [0, 10000), got {lead_in!r}")
    if rate is not None:
        checked_rate(rate)
    data = DataConfig(
        name="data",
        columns={**data.columns, **given},
        w_report=data.w_report,
        lead_in=float(lead_in),
        time_default="time" not in given,
    )
    runs, found = read_runs(path, data, rate)
    return {run: Record(run=run, rate=found, **r) for run, r in runs.items()}


@dataclass(frozen=True)
class Experiment:
    """The tracking task a record comes from (SPEC 7).

    Attributes
    ----------
    plant : Plant
        The controlled element ``Yc`` (``Plant.second_order(2.75, 2.0)`` for the paper,
        ``Plant.integrator(K)``, ``Plant.double_integrator(K)``, ``Plant.tf(num, den)``).
    disturbance_at : str
        ``output`` (``theta = Yc u + fd``, the paper) or ``input`` (``theta = Yc (u + fd)``).
    target, disturbance : Forcing, optional
        The forcing functions, where known (a multisine disturbance sets the
        frequency band of the parametric fit).
    """

    plant: Plant
    disturbance_at: str = "output"
    target: Forcing | None = None
    disturbance: Forcing | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.plant, Plant):
            raise ConfigError(f"plant: must be a hcid.Plant, got {type(self.plant).__name__}")
        if self.disturbance_at not in ("output", "input"):
            raise ConfigError(f"disturbance_at: must be 'output' or 'input', got {self.disturbance_at!r}")

    @classmethod
    def from_config(cls, config: Config) -> Experiment:
        """The experiment a study config simulates."""
        config.require_simulation("Experiment.from_config")
        return cls(config.loop.plant, config.loop.disturbance_at, config.target, config.disturbance)


def identification_settings(
    rate: float, n_samples: int, identify: Mapping[str, Any] | None = None
) -> IdentifyConfig:
    """The stages (grids, windows) and target shift for records of ``n_samples`` at ``rate`` Hz.

    ``identify`` is a config's ``identify`` section as a mapping (its keys and
    defaults: SPEC 3, ``docs/configuration.md``), read as a config reads it: the keys it
    leaves out take SPEC 3's values, windows in samples, not the scaled ones below (give
    ``windows_in: seconds`` and the windows for a shorter record). None gives what ``hcid analyse`` uses for
    a measured study without one: SPEC 3's grids and windows in seconds, scaled to the rate
    and the record (:func:`hcid.config.parse.data_identify_defaults`: delays up to 2 s on ft
    and 0.4 s on e, estimation and validation the paper's shares of the record); at 25 Hz
    and 2048 samples that is SPEC 3's section exactly.

    Examples
    --------
    >>> s = identification_settings(25.0, 1000)          # a 40 s record at 25 Hz
    >>> s.stage("direct").grid.nk1, s.stage("direct").estimation, s.stage("direct").validation
    ((1, 50), Window(first=63, last=531), Window(first=532, last=1000))
    """
    if identify is not None and not isinstance(identify, Mapping):
        raise ConfigError(
            f"identify: must be a mapping (a config's identify section), got {type(identify).__name__}"
        )
    timing = record_timing(rate, n_samples)
    if identify is None:
        identify = data_identify_defaults(timing, where="rate")
    return resolve_identify(dict(identify), rate, n_samples)


@dataclass(frozen=True)
class IdentificationResult:
    """Every order triple's best candidate of one record and method (the frontier), and what selects it.

    Attributes
    ----------
    method : str
        The method (``direct``, ``indirect``, ...: :data:`hcid.methods.METHODS`).
    rate : float
        The record's sample rate (Hz).
    settings : IdentifyConfig
        The stages and target shift used.
    frontier : Frontier
        One row per order triple, as arrays: na, nb_ft, nb_e, nk_ft, nk_e, d, v, VAFs,
        unstable counts, coefficients (:meth:`to_arrow` gives ``frontier.parquet``'s
        columns without model and seed).
    choices : tuple of StageChoice
        The earlier stages' chosen models (the indirect method's stage 1).
    seconds : float
        Wall time of the identification (s).
    """

    method: str
    rate: float
    settings: IdentifyConfig
    frontier: Frontier = field(repr=False)
    choices: tuple[methods.StageChoice, ...] = field(repr=False)
    seconds: float = 0.0

    @property
    def nf(self) -> int:
        """Estimation rows of the final stage: the N of the criteria's W."""
        return methods.get(self.method).nf(self.settings)

    @property
    def w_aic(self) -> float:
        """W of Akaike's criterion at this Nf (SPEC 4)."""
        return criteria.w_aic(self.nf)

    @property
    def w_bic(self) -> float:
        """W of the Bayesian criterion at this Nf (SPEC 4)."""
        return criteria.w_bic(self.nf)

    def selection_path(self) -> SelectionPath:
        """The exact selection over W: ``frontier`` row ``index[i]`` for ``w_from[i] <= W < w_to[i]``."""
        return self.frontier.path()

    def select(self, w: float) -> SelectedModel:
        """The model ``MSC = log V + W d`` selects at ``w`` (ties: SPEC 4's rule).

        Raises
        ------
        IdentificationError
            If ``w`` is not a finite number >= 0, or every candidate is unstable.
        """
        if isinstance(w, bool) or not isinstance(w, numbers.Real) or not (np.isfinite(w) and w >= 0):
            raise IdentificationError(f"w: must be a finite number >= 0, got {w!r}")
        row = int(self.selection_path().at(np.array([float(w)]))[0])
        stage = self.settings.stage(methods.get(self.method).final_stage.name)
        return SelectedModel.from_frontier(
            self.frontier, row, w, rate=self.rate, target_shift=self.settings.target_shift, stage=stage
        )

    def to_arrow(self) -> pa.Table:
        """The frontier as a table: ``frontier.parquet``'s columns without model and seed."""
        return self.frontier.to_arrow()


def identify(
    record: Record,
    method: str = "direct",
    settings: IdentifyConfig | None = None,
    *,
    threads: int = 1,
) -> IdentificationResult:
    """Identify one record by one method over its grid of orders and delays (SPEC 3).

    Parameters
    ----------
    record : Record
        From :func:`read_records` (or built from arrays at their rate).
    method : str
        A registered method: ``direct`` or ``indirect``.
    settings : IdentifyConfig, optional
        Default: :func:`identification_settings` for the record's rate and length
        (SPEC 3's grids and windows in seconds, as ``hcid analyse`` uses them).
    threads : int
        Threads of the ARX engine (at least 1).
    """
    if not isinstance(record, Record):
        raise IdentificationError(f"record: must be a hcid.Record, got {type(record).__name__}")
    methods.get(method)
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise IdentificationError(f"threads: must be an integer >= 1, got {threads!r}")
    if settings is None:
        settings = identification_settings(record.rate, record.ft.size)
    elif not isinstance(settings, IdentifyConfig):
        raise IdentificationError(
            f"settings: must come from hcid.identification_settings(rate, n_samples, identify), "
            f"got {type(settings).__name__}"
        )
    found = methods.identify(record.signals, settings, method, rate=record.rate, threads=threads)
    frontier = Frontier.from_grid_fit(found.fit, method)
    return IdentificationResult(method, record.rate, settings, frontier, found.choices, found.seconds)


def fit_hc(
    model: SelectedModel,
    record: Record,
    experiment: Experiment,
    *,
    target: str = "auto",
    settings: hcfit.FitSettings | None = None,
    plant_check: bool = True,
) -> hcfit.HCFit | None:
    """Fit the parametric HC model (SPEC 8) to a selected model and its record.

    Parameters
    ----------
    model : SelectedModel
        From :meth:`IdentificationResult.select`; its ``nb_ft > 0`` decides whether
        the feedforward parameters are fitted.
    record : Record
        The record the model was identified on.
    experiment : Experiment
        The plant (the feedforward path inverts it) and where the disturbance
        enters (the closed-loop target's loop).
    target : str
        ``auto`` (the default, as ``hcid analyse`` and ``hcid fit-hc``: ``lines`` where the
        record's forcing functions are multisines on disjoint lines with enough disturbance
        lines, else ``time``), ``lines`` (the paths at the forcing lines, from the record's
        Fourier coefficients), ``time`` (u simulated from the measured ft and e),
        ``closed_loop`` (the model in closed loop with the plant, driven by the measured ft
        and fd) or ``frequency`` (the ARX model's paths); ignored when ``settings`` is given.
        docs/parametric-fit.md compares them.
    settings : FitSettings, optional
        Bounds, starts and seed (:func:`hcid.hcfit.parse_fit_settings`); the
        band defaults to the disturbance's (a multisine's) or the record's.
    plant_check : bool
        Refuse a record the experiment's plant does not describe (``hcid analyse``'s check:
        more than 30% (RMS) of ``theta = ft - e`` at the forcing lines unexplained); False
        where the plant leaves out, say, a display delay. It reads the forcing lines over the
        whole record: where the forcing functions are no multisines over (nearly) whole
        periods of it, it warns that the plant was not checked, and ``auto`` fits by ``time``.

    Returns
    -------
    HCFit or None
        None for a frequency fit of a model without feedback path.

    Raises
    ------
    DataError
        A record of another plant (``plant_check``).
    """
    for name, value, kind in (("model", model, SelectedModel), ("record", record, Record),
                              ("experiment", experiment, Experiment)):  # fmt: skip
        if not isinstance(value, kind):
            raise IdentificationError(f"{name}: must be a hcid.{kind.__name__}, got {type(value).__name__}")
    if plant_check:
        _check_plant(record, experiment)
    band = Config.band_of(experiment.disturbance, record_timing(record.rate, record.ft.size))
    if settings is None:
        settings = hcfit.parse_fit_settings({"target": target}, "fit_hc", default_band=band)
    elif settings.band is None:
        settings = dataclasses.replace(settings, band=band)
    return fit_selected(
        model, record.signals, transfer_function(experiment.plant), settings, experiment.disturbance_at
    )


def _check_plant(record: Record, experiment: Experiment) -> None:
    """Refuse a record that ``experiment``'s plant leaves more than
    :data:`~hcid.analysis.fourier.PLANT_MISMATCH_LIMIT` of theta unexplained at its forcing lines;
    a warning where its forcing functions have no lines over the record (nothing to check at)."""
    plant = experiment.plant
    found = plant_mismatch(record.signals, record.rate, plant.num, plant.den, experiment.disturbance_at)
    if found is None:
        why = forcing_lines(record.ft, record.fd, record.rate).problem
        warnings.warn(
            f"record {record.run}: the plant was not checked over its {record.ft.size} samples: {why} "
            "(plant_check=False: unchecked, no warning)",
            stacklevel=3,
        )
    if is_other_plant(found):
        raise DataError(
            f"record {record.run}: is not the experiment's plant: {found:.0%} (RMS) of its theta = ft - e "
            f"at the forcing lines is not what {plant.text} with the disturbance at its "
            f"{experiment.disturbance_at} gives; check Experiment(plant, disturbance_at), or pass "
            "plant_check=False where the plant leaves out a display delay"
        )
