"""Checks of parsed YAML values, naming the dotted key, the allowed range and the value.

Private to :mod:`hcid.config`.
"""

from __future__ import annotations

import math
import operator
from typing import Any

from hcid.errors import QUOTE, ConfigError
from hcid.errors import quote as fmt

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


#: Names a file-name pattern's factors may not take: hcid's own columns in the tables.
RESERVED_FACTORS = ("model", "seed", "run", "file", "file_run", "method", "w", "k", "t")


class Section:
    """A mapping under a dotted path; every key taken is checked, leftovers are errors."""

    def __init__(self, data: Any, path: str):
        if not isinstance(data, dict):
            raise ConfigError(f"{path or '<top>'}: must be a mapping, got {fmt(data)}")
        self.data = data
        self.path = path
        self.seen: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def get(self, name: str, default: Any = ...) -> Any:
        self.seen.add(name)
        if name not in self.data:
            if default is ...:
                raise ConfigError(f"{self.key(name)}: missing")
            return default
        return self.data[name]

    def number(self, name: str, lo: float, hi: float, default: Any = ..., *, open_lo: bool = False) -> float:
        value = self.get(name, default)
        key = self.key(name)
        bracket = "(" if open_lo else "["
        allowed = f"a number in {bracket}{lo:g}, {hi:g}]"
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{key}: must be {allowed}, got {fmt(value)}")
        value = float(value)
        if not math.isfinite(value) or value > hi or value < lo or (open_lo and value == lo):
            raise ConfigError(f"{key}: must be {allowed}, got {fmt(value)}")
        return value

    def integer(self, name: str, lo: int, hi: int, default: Any = ...) -> int:
        value = self.get(name, default)
        return integer(value, self.key(name), lo, hi)

    def section(self, name: str, default: Any = ...) -> Section:
        return Section(self.get(name, default), self.key(name))

    def done(self) -> None:
        extra = sorted(set(self.data) - self.seen, key=str)
        if extra:
            raise ConfigError(
                f"{self.key(str(extra[0])[:QUOTE])}: unknown key (allowed: {', '.join(sorted(self.seen))})"
            )


def integer(value: Any, key: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(f"{key}: must be an integer in [{lo}, {hi}], got {fmt(value)}")
    return value


def int_range(section: Section, name: str, lo: int, hi: int, default: Any = ...) -> tuple[int, int]:
    value = section.get(name, default)
    key = section.key(name)
    ok = (
        isinstance(value, list | tuple)
        and len(value) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
        and lo <= value[0] <= value[1] <= hi
    )
    if not ok:
        raise ConfigError(
            f"{key}: must be an integer range [lo, hi] with {lo} <= lo <= hi <= {hi}, got {fmt(value)}"
        )
    return int(value[0]), int(value[1])


def number_list(section: Section, name: str, n: int | None = None) -> tuple[float, ...]:
    value = section.get(name)
    key = section.key(name)
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{key}: must be a non-empty list of numbers, got {fmt(value)}")
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ConfigError(f"{key}[{i}]: must be a finite number, got {fmt(v)}")
    if n is not None and len(value) != n:
        raise ConfigError(f"{key}: must have {n} entries (one per disturbance sine), got {len(value)}")
    return tuple(float(v) for v in value)


# Smallest allowed lower bound of each range: A always has a coefficient, inputs
# may be dropped, delays may be zero (a direct feed-through from i(k)).
GRID_LOWEST = {"na": 1, "nb1": 0, "nb2": 0, "nk1": 0, "nk2": 0}


def checked_grid_range(name: str, value: object, lowest: int) -> tuple[int, int]:
    message = f"Grid.{name}: must be two integers lo <= hi with lo >= {lowest}, got {value!r}"
    try:
        if isinstance(value, str | bytes) or len(value) != 2:  # type: ignore[arg-type]
            raise ConfigError(message)
        lo, hi = value  # type: ignore[misc]
        if isinstance(lo, bool) or isinstance(hi, bool):
            raise ConfigError(message)
        lo, hi = operator.index(lo), operator.index(hi)
    except TypeError as exc:
        raise ConfigError(message) from exc
    if lo > hi or lo < lowest:
        raise ConfigError(message)
    return (lo, hi)
