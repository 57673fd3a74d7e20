"""Selection criteria as penalties per parameter: ``MSC = log V + W d`` with ``W = W(Nf)``.

SPEC sections 4 and 9. A criterion is a :class:`Criterion`: a name (its
config key and the ``w_<name>`` column of ``thresholds.parquet``), a label for
reports, its constants, and its penalty as a function of Nf, the estimation
rows of the stage that defines it. The thresholds table, the report's W marks
and the CLI printout iterate over the configured criteria. To add one, add an
entry to :data:`CRITERIA`.

Pure functions; no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from hcid.errors import ConfigError

__all__ = ["CRITERIA", "Criterion", "CriterionKind", "build", "configured", "w_aic", "w_bic"]


def w_aic(nf: int) -> float:
    """AIC penalty ``2 / Nf`` (SPEC 4).

    Examples
    --------
    >>> round(w_aic(960), 6)
    0.002083
    """
    return 2.0 / nf


def w_bic(nf: int) -> float:
    """BIC penalty ``ln(Nf) / Nf`` (SPEC 4).

    Examples
    --------
    >>> round(w_bic(960), 6)  # SPEC 4: 7.15e-3
    0.007153
    """
    return math.log(nf) / nf


@dataclass(frozen=True)
class Criterion:
    """A configured criterion: name, label, constants and its penalty ``W(Nf)``."""

    name: str
    label: str
    constants: tuple[tuple[str, float], ...]
    penalty: Callable[[int], float]

    def w(self, nf: int) -> float:
        """The penalty per parameter W at ``nf`` estimation rows."""
        return float(self.penalty(nf))

    @property
    def column(self) -> str:
        """Its column in ``thresholds.parquet``."""
        return f"w_{self.name}"


@dataclass(frozen=True)
class CriterionKind:
    """A registered criterion: its constants with defaults and allowed ranges, and how to build it."""

    description: str
    constants: Mapping[str, tuple[float, float, float]]  # name -> (default, lo, hi)
    make: Callable[[Mapping[str, float]], tuple[str, Callable[[int], float]]]  # -> (label, penalty)


#: Registered criteria by config name, in the order they are listed everywhere.
CRITERIA: dict[str, CriterionKind] = {
    "aic": CriterionKind("Akaike: W = 2/Nf", {}, lambda c: ("W_AIC", w_aic)),
    "bic": CriterionKind("Bayesian: W = ln(Nf)/Nf", {}, lambda c: ("W_BIC", w_bic)),
    "mbic": CriterionKind(
        "modified BIC of the authors' follow-up: W = c ln(Nf)/Nf (SPEC 9)",
        {"c": (3.0, 0.0, 1000.0)},
        lambda c: (f"W_mBIC (c = {c['c']:g})", lambda nf, k=c["c"]: k * w_bic(nf)),
    ),
}

#: Criteria of a config that names none.
DEFAULT = ("aic", "bic", "mbic")


def build(name: str, constants: Mapping[str, float] | None = None) -> Criterion:
    """The criterion ``name`` with its constants (defaults for those not given).

    Examples
    --------
    >>> round(build("mbic").w(960), 5)  # SPEC 9: c = 3 gives W = 0.0214 at Nf = 960
    0.02146
    """
    try:
        kind = CRITERIA[name]
    except KeyError:
        raise ConfigError(
            f"selection.criteria.{name}: unknown criterion (allowed: {', '.join(CRITERIA)})"
        ) from None
    given = dict(constants or {})
    values = {}
    for key, (default, lo, hi) in kind.constants.items():
        value = float(given.pop(key, default))
        if not lo <= value <= hi:
            raise ConfigError(
                f"selection.criteria.{name}.{key}: must be a number in [{lo:g}, {hi:g}], got {value:g}"
            )
        values[key] = value
    if given:
        raise ConfigError(
            f"selection.criteria.{name}.{next(iter(given))}: unknown key "
            f"(allowed: {', '.join(kind.constants) or 'none'})"
        )
    label, penalty = kind.make(values)
    return Criterion(name=name, label=label, constants=tuple(values.items()), penalty=penalty)


def configured(chosen: tuple[tuple[str, tuple[tuple[str, float], ...]], ...]) -> tuple[Criterion, ...]:
    """The criteria of a config's ``selection.criteria`` (:attr:`hcid.config.SelectionConfig.criteria`)."""
    return tuple(build(name, dict(constants)) for name, constants in chosen)
