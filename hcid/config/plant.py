"""The controlled element of a study: one plant (:class:`Plant`), or a plant per level of a data
factor (:class:`PlantByFactor`, a measured study of several plants: ``hcid analyse``), and the
config's ``loop.plant`` section that gives them (:func:`plant_section`, :data:`PLANTS`)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hcid.config._checks import RESERVED_FACTORS, Section, fmt, number_list
from hcid.errors import ConfigError

__all__ = [
    "MAX_INVERTIBLE_DEGREE",
    "MAX_PLANT_COEFFICIENTS",
    "Plant",
    "PlantByFactor",
    "PLANTS",
    "check_plant",
    "plant_section",
    "relative_degree",
]


@dataclass(frozen=True)
class Plant:
    """The controlled element ``Yc(s) = num(s) / den(s)``, theta per u.

    ``num`` and ``den`` are polynomial coefficients in s, highest power first;
    ``kind`` is the shorthand it was written as (``second_order``, ``integrator``,
    ``double_integrator``) or ``tf``; ``text`` is how the report prints it.

    Examples
    --------
    >>> Plant.second_order(2.75, 2.0).den
    (1.0, 2.0, 0.0)
    """

    kind: str
    num: tuple[float, ...]
    den: tuple[float, ...]
    text: str

    def __post_init__(self) -> None:
        check_plant(self.num, self.den, "plant")

    @classmethod
    def second_order(cls, K: float, wb: float) -> Plant:
        """The paper's plant ``K wb / (s (s + wb))``."""
        K, wb = _real(K, "K"), _real(wb, "wb")
        return cls("second_order", (K * wb,), (1.0, wb, 0.0), f"{K:g}*{wb:g}/(s (s + {wb:g}))")

    def response(self, omega: np.ndarray) -> np.ndarray:
        """``Yc(j omega)`` at the frequencies ``omega`` (rad/s), complex, theta per u.

        Examples
        --------
        >>> Plant.integrator(2.0).response(np.array([4.0]))
        array([0.-0.5j])
        """
        s = 1j * np.asarray(omega, dtype=np.float64)
        return np.polyval(self.num, s) / np.polyval(self.den, s)

    @property
    def relative_degree(self) -> int:
        """Degree of ``den`` minus degree of ``num`` (leading zeros ignored): >= 0, as a plant is proper.

        Examples
        --------
        >>> Plant.integrator(1.0).relative_degree, Plant.tf([1.0, 1.0], [1.0, 3.0]).relative_degree
        (1, 0)
        """
        return relative_degree(self.num, self.den)

    @classmethod
    def integrator(cls, K: float) -> Plant:
        """``K / s``."""
        K = _real(K, "K")
        return cls("integrator", (K,), (1.0, 0.0), f"{K:g}/s")

    @classmethod
    def double_integrator(cls, K: float) -> Plant:
        """``K / s^2``."""
        K = _real(K, "K")
        return cls("double_integrator", (K,), (1.0, 0.0, 0.0), f"{K:g}/s^2")

    @classmethod
    def tf(cls, num: Sequence[float], den: Sequence[float]) -> Plant:
        """Any transfer function ``num(s) / den(s)`` (coefficients highest power first).

        Examples
        --------
        >>> Plant.tf([0, 2.0], [1.0, 3.0, 0.0]).text
        '(2) / (1 s^2 + 3 s)'
        """
        check_plant(num, den, "plant")  # before float() could take "1" or True for a number
        num = tuple(float(c) for c in num)
        num = num[next((i for i, c in enumerate(num) if c != 0), len(num)) :]
        den = tuple(float(c) for c in den)
        return cls("tf", num, den, f"({_poly_text(num)}) / ({_poly_text(den)})")


def _real(x: Any, name: str) -> float:
    """A shorthand's gain or break frequency as a float: a finite number > 0, as a config's is."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real) or not (math.isfinite(x) and x > 0):
        raise ConfigError(f"plant.{name}: must be a finite number > 0, got {x!r}")
    return float(x)


#: The most coefficients of ``num`` or of ``den`` (degree 10).
MAX_PLANT_COEFFICIENTS = 11


def check_plant(num: Sequence[float], den: Sequence[float], where: str) -> None:
    """Refuse a plant that is no proper transfer function: coefficients not finite, more than
    :data:`MAX_PLANT_COEFFICIENTS`, ``num`` or ``den`` all zero, or ``num`` of higher degree
    than ``den`` (leading zeros ignored).

    Examples
    --------
    >>> check_plant((float("nan"),), (1.0, 0.0), "plant")
    Traceback (most recent call last):
    ...
    hcid.errors.ConfigError: plant.num: must be finite numbers, got [nan]
    """
    for key, coefs in (("num", num), ("den", den)):
        if not all(
            isinstance(c, numbers.Real) and not isinstance(c, bool) and math.isfinite(c) for c in coefs
        ):
            raise ConfigError(f"{where}.{key}: must be finite numbers, got {list(coefs)}")
        if len(coefs) > MAX_PLANT_COEFFICIENTS:
            raise ConfigError(
                f"{where}.{key}: must hold at most {MAX_PLANT_COEFFICIENTS} coefficients (degree 10), "
                f"got {len(coefs)}"
            )
    for key, coefs in (("num", num), ("den", den)):
        if not any(c != 0 for c in coefs):
            raise ConfigError(f"{where}.{key}: must not be all zero")
    if relative_degree(num, den) < 0:
        raise ConfigError(
            f"{where}: must be proper (degree of num <= degree of den), got degrees {_degree(num)} and "
            f"{_degree(den)}"
        )


#: The largest relative degree of a plant with an Inverse Feedforward Model (SPEC 7):
#: ``Ynms Kpt / Yc / (TI s + 1)^2`` is proper exactly up to it.
MAX_INVERTIBLE_DEGREE = 4


def relative_degree(num: Sequence[float], den: Sequence[float]) -> int:
    """Degree of ``den`` minus degree of ``num`` (in s, highest power first; leading zeros ignored).

    Examples
    --------
    >>> relative_degree([1.0], [1.0, 0.0]), relative_degree([1.0, 0.0, 0.0], [0.0, 1.0, 1.0])
    (1, -1)
    """
    return _degree(den) - _degree(num)


def _degree(coefs: Sequence[float]) -> int:
    first = next((i for i, c in enumerate(coefs) if c != 0), len(coefs))
    return len(coefs) - first - 1


def _poly_text(coefs: tuple[float, ...]) -> str:
    n = len(coefs) - 1
    terms = [
        f"{c:g}" + ("" if i == n else " s" if i == n - 1 else f" s^{n - i}")
        for i, c in enumerate(coefs)
        if c != 0
    ]
    return " + ".join(terms).replace("+ -", "- ")


@dataclass(frozen=True)
class PlantByFactor:
    """A plant per level of a data factor: each run's plant is that of its value of ``by``
    (``loop.plant: {by: plant, levels: {fo: {kind: integrator, K: 1}, so: {...}}}``).

    ``levels`` are ``(level, plant)`` pairs in the config's order. Only a measured study takes
    it (``hcid analyse``, ``hcid identify --data``): a command that simulates or fits with one
    plant refuses it (:meth:`hcid.config.Config.require_one_plant`).

    Examples
    --------
    >>> so = Plant.tf([1.0], [1.0, 1.0, 0.0])
    >>> two = PlantByFactor("plant", (("fo", Plant.integrator(1.0)), ("so", so)))
    >>> two.of("so").den, two.text
    ((1.0, 1.0, 0.0), 'plant=fo: 1/s; plant=so: (1) / (1 s^2 + 1 s)')
    """

    by: str
    levels: tuple[tuple[str, Plant], ...]

    @property
    def names(self) -> tuple[str, ...]:
        """The levels, in the config's order."""
        return tuple(name for name, _ in self.levels)

    def of(self, level: str) -> Plant:
        """The plant of ``level``.

        Raises
        ------
        ConfigError
            For a level ``loop.plant.levels`` does not give, naming the levels it does.
        """
        for name, plant in self.levels:
            if name == level:
                return plant
        raise ConfigError(
            f"loop.plant.levels: gives no plant for {self.by} {level!r} (it has {', '.join(self.names)})"
        )

    @property
    def text(self) -> str:
        """How the report prints it: each level's plant."""
        return "; ".join(f"{self.by}={name}: {plant.text}" for name, plant in self.levels)


# --------------------------------------------------------------------------- the loop.plant section


def _integrator(s: Section) -> Plant:
    return Plant.integrator(s.number("K", 0.0, 1e4, open_lo=True))


def _double_integrator(s: Section) -> Plant:
    return Plant.double_integrator(s.number("K", 0.0, 1e4, open_lo=True))


def _second_order(s: Section) -> Plant:
    return Plant.second_order(s.number("K", 0.0, 1e4, open_lo=True), s.number("wb", 0.0, 1e4, open_lo=True))


def _transfer_function(s: Section) -> Plant:
    num, den = number_list(s, "num"), number_list(s, "den")
    if den and den[0] == 0 and any(den):  # a config writes den from its leading power: a 0 is a slip
        raise ConfigError(f"{s.key('den')}: the leading coefficient must not be 0, got {list(den)}")
    check_plant(num, den, s.path)
    return Plant.tf(num, den)


#: Plant shorthands of ``loop.plant.kind``, each a builder from its section (SPEC 7);
#: ``tf`` takes any proper transfer function in s. Add a shorthand here.
PLANTS = {
    "second_order": _second_order,
    "integrator": _integrator,
    "double_integrator": _double_integrator,
    "tf": _transfer_function,
}


def _one_plant(s: Section) -> Plant:
    kind = s.get("kind")
    try:
        builder = PLANTS[kind]
    except (KeyError, TypeError):
        raise ConfigError(
            f"{s.key('kind')}: unknown plant shorthand {fmt(kind)} (allowed: {', '.join(PLANTS)})"
        ) from None
    plant = builder(s)
    s.done()
    return plant


def plant_section(loop: Section, per_level: bool) -> Plant | PlantByFactor:
    """``loop.plant``: one plant, or (``by`` and ``levels``) one per level of a data factor, which
    only a measured study (``per_level``) takes."""
    s = loop.section("plant")
    if "by" not in s.data:
        return _one_plant(s)
    by = s.get("by")
    if not per_level:
        raise ConfigError(
            "loop.plant.by: a plant per level of a data factor is for a measured study (hcid analyse); "
            "a config that simulates (models, signals, seeds) needs one plant"
        )
    if not isinstance(by, str) or not by.isidentifier() or by in RESERVED_FACTORS:
        raise ConfigError(
            f"loop.plant.by: must be a data factor's name (an identifier other than "
            f"{', '.join(RESERVED_FACTORS)}), got {fmt(by)}"
        )
    raw = s.get("levels")
    if not isinstance(raw, dict) or not raw:
        raise ConfigError(
            f"loop.plant.levels: must be a non-empty mapping of each level of {by!r} to its plant, "
            f"got {fmt(raw)}"
        )
    unnamed = [k for k in raw if not isinstance(k, str) or not k]
    if unnamed:  # a factor's values are text (file names): YAML's 1 is not the file's '1'
        raise ConfigError(
            f"loop.plant.levels: each level must be a factor value as text (quote a number: "
            f"'1'), got {fmt(unnamed[0])}"
        )
    levels = s.section("levels")
    plants = tuple((name, _one_plant(levels.section(name))) for name in raw)
    levels.done()
    s.done()
    return PlantByFactor(by, plants)
