"""What an identification method is: its stages, and what running it on one record returns.

A method is a :class:`Method`: a name, the stages it runs (each a
:class:`StageSpec`: the config section under ``identify``, the signals it maps,
the SPEC defaults of its grid and windows), which stage's estimation rows define
``Nf`` for the selection criteria, and a ``run`` function from a record to a
:class:`MethodResult`. The last stage's frontier is what model selection works
on; earlier stages each hand on one chosen model (:class:`StageChoice`, stored
in the table named after the stage).

Pure functions over arrays; no I/O.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hcid.arx.engine import GridFit, best, fit_grid
from hcid.config.types import Grid, IdentifyConfig, StageConfig
from hcid.errors import ConfigError, IdentificationError

__all__ = [
    "Method",
    "MethodResult",
    "StageChoice",
    "StageOption",
    "StageSpec",
    "choose",
    "fit_stage",
    "one_of",
    "refit",
    "shift_forward",
]


@dataclass(frozen=True)
class StageOption:
    """A key of a stage's config section beyond its grid and windows (e.g. stage 1's ``rows``).

    ``parse(value, key)`` checks a configured value and returns it as stored
    (hashable: lists become tuples), raising :class:`hcid.errors.ConfigError`
    that names ``key`` (the dotted path) otherwise. The default reproduces SPEC.
    """

    default: Any
    parse: Callable[[Any, str], Any]
    help: str = ""


def one_of(*choices: str) -> Callable[[Any, str], str]:
    """A :attr:`StageOption.parse` accepting one of the given words."""

    def parse(value: Any, key: str) -> str:
        if value not in choices:
            raise ConfigError(f"{key}: must be one of {', '.join(choices)}, got {value!r}")
        return value

    return parse


@dataclass(frozen=True)
class StageSpec:
    """One stage of a method, as the config and the tables see it.

    Attributes
    ----------
    name : str
        Its config section, ``identify.<name>``, and the name of its table when
        it is not the final stage (``<name>.parquet``).
    inputs : tuple of str
        Names of ARX inputs 1 and 2 and of the output, e.g. ``("ft", "e", "u")``;
        they name the columns ``nb_<input>`` and ``nk_<input>`` of its tables.
    defaults : mapping
        Grid ranges and windows used for keys the config leaves out (SPEC 3).
    defaults_from : str or None
        A stage whose keys, as given in the config, override ``defaults``
        (stage 2 of the indirect method takes the direct method's grid).
    options : mapping of str to StageOption
        Further keys its config section may hold, with their defaults; the
        config keeps the values that differ from the default
        (:attr:`hcid.config.StageConfig.options`), read back with :meth:`option`.
    """

    name: str
    inputs: tuple[str, str, str]
    defaults: Mapping[str, Any]
    defaults_from: str | None = None
    options: Mapping[str, StageOption] = field(default_factory=dict)

    def option(self, stage: StageConfig, name: str) -> Any:
        """The value of option ``name`` in a parsed stage: as configured, else its default."""
        return dict(stage.options).get(name, self.options[name].default)


@dataclass(frozen=True)
class StageChoice:
    """The model a non-final stage hands on: its structure, V and candidate counts.

    ``signal`` is its simulated output over the whole record, the signal it
    hands on (e_r for the indirect method's stage 1); not tabulated with the
    choice, but compared with the noise-free simulated signal where one is known.
    """

    stage: str
    na: int
    nb1: int
    nb2: int
    nk1: int
    nk2: int
    v: float
    n_candidates: int
    n_unstable: int
    seconds: float
    signal: np.ndarray | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class MethodResult:
    """Frontier of a method's final stage on one record, with the earlier stages' choices."""

    method: str
    fit: GridFit
    choices: tuple[StageChoice, ...]
    seconds: float


#: ``run(record, settings, shift, threads)``: ``record`` holds ft, fd, e, u (rad) at the
#: analysis rate, ``shift`` is the target shift in samples.
RunFunction = Callable[[Mapping[str, np.ndarray], IdentifyConfig, int, int], MethodResult]
#: ``signals(record, settings, shift, choices)``: the final stage's ``(i1, i2, o)`` on a
#: record, given the earlier stages' choices (in the order of ``choice_stages``).
SignalsFunction = Callable[
    [Mapping[str, np.ndarray], IdentifyConfig, int, tuple[StageChoice, ...]],
    tuple[np.ndarray, np.ndarray, np.ndarray],
]


@dataclass(frozen=True)
class Method:
    """An identification method: its stages in order and how to run it.

    ``nf_stage`` names the stage whose estimation rows give ``Nf``, the number
    the criteria's penalties W(Nf) depend on (the final stage when None).
    ``signals`` rebuilds the final stage's inputs and output from a record and
    the earlier stages' stored choices (for residuals of a selected model); a
    one-stage method may leave it None (:meth:`final_signals`).
    """

    name: str
    stages: tuple[StageSpec, ...]
    run: RunFunction
    nf_stage: str | None = None
    signals: SignalsFunction | None = None

    @property
    def final_stage(self) -> StageSpec:
        return self.stages[-1]

    @property
    def choice_stages(self) -> tuple[StageSpec, ...]:
        """The stages before the final one: each hands on one model, kept in its own table."""
        return self.stages[:-1]

    def final_signals(
        self,
        record: Mapping[str, np.ndarray],
        settings: IdentifyConfig,
        shift: int,
        choices: tuple[StageChoice, ...] = (),
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The final stage's ``(i1, i2, o)`` on ``record``: what its frontier was fitted to.

        Without a ``signals`` function (a one-stage method), i1 is ft shifted
        forward by ``shift`` samples (SPEC 3) and i2, o are the record's signals
        named by the final stage's inputs.
        """
        if self.signals is not None:
            return self.signals(record, settings, shift, tuple(choices))
        if self.choice_stages:
            raise IdentificationError(
                f"method {self.name}: has earlier stages, so it must give a signals function"
            )
        i1, i2, o = self.final_stage.inputs
        return shift_forward(record[i1], shift), record[i2], record[o]

    def nf(self, settings: IdentifyConfig) -> int:
        """Nf: the estimation rows of the stage that defines it (SPEC 4 and 7)."""
        return settings.stage(self.nf_stage or self.final_stage.name).estimation.length


def shift_forward(x: np.ndarray, n: int) -> np.ndarray:
    """``x(k + n)`` with zeros after the record (SPEC 3: ``ft_s(k) = ft(k + 25)``).

    Examples
    --------
    >>> shift_forward(np.array([1.0, 2.0, 3.0, 4.0]), 1)
    array([2., 3., 4., 0.])
    """
    if n == 0:
        return x.copy()
    return np.concatenate([x[n:], np.zeros(n)])


def fit_stage(stage: StageConfig, i1: np.ndarray, i2: np.ndarray, o: np.ndarray, threads: int) -> GridFit:
    """Fit every candidate of a stage's grid on its windows (:func:`hcid.arx.fit_grid`)."""
    return fit_grid(i1, i2, o, stage.grid, stage.estimation.rows(), stage.validation.rows(), threads=threads)


def refit(
    choice: StageChoice, i1: np.ndarray, i2: np.ndarray, o: np.ndarray, estimation: slice, validation: slice
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(a, b1, b2)`` of a stage's chosen candidate, fitted again on the rows it was chosen on.

    The one candidate of ``choice`` is estimated alone (a one-point grid), which
    gives the grid fit's coefficients up to rounding (:func:`hcid.arx.fit_grid`,
    Notes); its V is checked against the stored ``choice.v``.

    Raises
    ------
    hcid.errors.IdentificationError
        If the refit's V differs from ``choice.v`` by more than 1e-6 relative
        (the record is not the one the choice was made on).
    """
    grid = Grid(
        na=(choice.na, choice.na),
        nb1=(choice.nb1, choice.nb1),
        nb2=(choice.nb2, choice.nb2),
        nk1=(choice.nk1, choice.nk1),
        nk2=(choice.nk2, choice.nk2),
    )
    fit = fit_grid(i1, i2, o, grid, estimation, validation)
    v = float(fit.v[0])
    if not (np.isfinite(v) and abs(v - choice.v) <= 1e-6 * abs(choice.v)):
        raise IdentificationError(
            f"{choice.stage}: refitting the chosen candidate gives V = {v:.6g}, stored {choice.v:.6g}; "
            "the record is not the one it was chosen on"
        )
    return fit.a[0], fit.b1[0], fit.b2[0]


def choose(name: str, fit: GridFit, start: float) -> tuple[int, StageChoice]:
    """The smallest-V row of a stage's frontier and its :class:`StageChoice`."""
    row = best(fit)
    choice = StageChoice(
        stage=name,
        na=int(fit.na[row]),
        nb1=int(fit.nb1[row]),
        nb2=int(fit.nb2[row]),
        nk1=int(fit.nk1[row]),
        nk2=int(fit.nk2[row]),
        v=float(fit.v[row]),
        n_candidates=fit.n_candidates,
        n_unstable=fit.n_unstable_total,
        seconds=time.perf_counter() - start,
    )
    return row, choice
