"""What the twins of ``hcid analyse`` simulate (SPEC 10): a group's fitted values brought into
the ranges the twins' config takes (:data:`TWIN_RANGES`; delays in whole samples of the twins'
simulation), with what had to change and why a model cannot make twins at all
(:func:`twin_model`), and the twins' simulation rate (:func:`twin_rate`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import NamedTuple

from hcid.config import HCModel, Loop
from hcid.errors import ConfigError
from hcid.hcfit.determined import Simulated
from hcid.loop.hcmodel import check_closed_loops

__all__ = [
    "MIN_TWIN_KPT",
    "PATH_PARAMETERS",
    "REMNANT",
    "TWIN_RANGES",
    "TWIN_SIM_RATE",
    "twin_model",
    "twin_rate",
    "twin_remnant",
    "twin_values",
]

#: The twins' simulation rate: the smallest multiple of the analysis rate at or above this (Hz).
TWIN_SIM_RATE = 100.0


def twin_rate(rate: float) -> float:
    return rate * max(1, math.ceil(TWIN_SIM_RATE / rate - 1e-9))


#: The FF twin's smallest Kpt: a group whose fitted Kpt is below it (nobody uses feedforward)
#: gets twins that nearly coincide, and the calibration says that no W separates them.
MIN_TWIN_KPT = 1e-3


#: What the twins' config takes of each value (:mod:`hcid.config.parse`, its ``models`` and
#: ``loop`` sections): the lowest, the highest, and whether the lowest itself is refused (the FF
#: twin's TI must be above 0: its Kpt is). ``kn`` is ``loop.remnant_gain``.
TWIN_RANGES = {
    "Kpt": (0.0, 10.0, False),
    "TI": (0.0, 10.0, True),
    "tau_pt": (-2.0, 2.0, False),
    "Kpe": (0.0, 100.0, True),
    "TL": (0.0, 10.0, False),
    "tau_pe": (0.0, 2.0, True),
    "w_nms": (0.0, 1e3, True),
    "zeta_nms": (0.0, 10.0, True),
    "kn": (0.0, 1e3, False),
    "w_n": (0.0, 1e3, True),
    "zeta_n": (0.0, 10.0, True),
}
# The HC model's path parameters (the twins' ``models`` section); delays in whole samples.
PATH_PARAMETERS = ("Kpt", "TI", "tau_pt", "Kpe", "TL", "tau_pe")
_DELAYS = ("tau_pt", "tau_pe")
REMNANT = ("kn", "w_n", "zeta_n")


def _into_range(name: str, value: float, sim_rate: float) -> tuple[float, str, str]:
    """One value as the twins simulate it: ``(value, change, problem)``, the change in words
    where it had to be brought into :data:`TWIN_RANGES`, the problem where it cannot be.

    A delay is whole samples at ``sim_rate`` (SPEC 1), and at least one where 0 is refused: a
    delay fitted at 0 s (on its search bound) or under half a sample says only that it is shorter
    than the fit can tell apart from the neuromuscular lag, and one sample, the shortest the
    simulation takes, changes the loop's phase by at most ``w / sim_rate`` rad (3 deg at 5 rad/s,
    100 Hz). A value above its range is brought to the range's top, one below a lowest that is
    taken to that lowest; one at or below a refused lowest of 0 (no gain, no damping) has no
    nearest value to stand for it, and is a problem.
    """
    lo, hi, open_lo = TWIN_RANGES[name]
    if not math.isfinite(value):
        return value, "", f"{name} is {value:g}"
    if name in _DELAYS:
        n = round(value * sim_rate)
        shortest = 1 if open_lo else math.ceil(lo * sim_rate - 1e-9)
        longest = math.floor(hi * sim_rate + 1e-9)
        if shortest <= n <= longest:
            return n / sim_rate, "", ""
        k = min(max(n, shortest), longest)
        to, was = k / sim_rate, f"{name} {value:.3f} s"
        if k == 1:
            return to, f"{was} raised to one sample of the twins' simulation, {to:g} s at {sim_rate:g} Hz", ""
        if n < shortest:
            return to, f"{was} raised to {to:g} s, the shortest the twins take", ""
        return to, f"{was} lowered to {to:g} s, the longest the twins take", ""
    if value > hi:
        return hi, f"{name} {value:.3g} lowered to {hi:g}, the most the twins take", ""
    if value <= lo and open_lo:
        return value, "", f"{name} is {value:.3g}, where the twins need a value above {lo:g}"
    if value < lo:
        return lo, f"{name} {value:.3g} raised to {lo:g}, the least the twins take", ""
    return value, "", ""


def _in_range(values: dict, names: Sequence[str], sim_rate: float) -> Simulated:
    brought = [_into_range(n, float(values[n]), sim_rate) for n in names]
    return Simulated(
        {n: v for n, (v, _, _) in zip(names, brought, strict=True)},
        tuple(c for _, c, _ in brought if c),
        "; ".join(p for _, _, p in brought if p),
    )


def twin_values(fitted: dict, sim_rate: float) -> dict[str, float]:
    """The FF twin's HC parameters (its paths' and its neuromuscular pair) as simulated at
    ``sim_rate`` (Hz): Kpt at least :data:`MIN_TWIN_KPT`, every value in :data:`TWIN_RANGES`
    (delays in whole samples, the error delay at least one; an anticipating tau_pt, < 0, reads the
    twins' periodic target ahead). :func:`twin_model` says what it changed."""
    return twin_model(fitted, sim_rate).values


def twin_model(fitted: dict, sim_rate: float, loop: Loop | None = None) -> Simulated:
    """A group's model as its twins simulate it at ``sim_rate`` (Hz), what had to be brought into
    the twins' ranges to make it (:data:`TWIN_RANGES`: a delay fitted at 0 s to one sample), and
    why the twins cannot be made from it at all: a value without a nearest one the twins take,
    or, given the study's ``loop`` (its plant), a loop with the plant or a feedforward path that
    is unstable as simulated (:func:`hcid.loop.hcmodel.check_closed_loops`, the twins' config's
    own check). What :func:`hcid.hcfit.determined.group_model` judges the group's candidate
    models by."""
    given = {**fitted, "Kpt": max(float(fitted["Kpt"]), MIN_TWIN_KPT)}
    sim = _in_range(given, (*PATH_PARAMETERS, "w_nms", "zeta_nms"), sim_rate)
    if sim.problem or loop is None:
        return sim
    ff = HCModel("FF", **{k: sim.values[k] for k in PATH_PARAMETERS})
    twin_loop = replace(loop, w_nms=sim.values["w_nms"], zeta_nms=sim.values["zeta_nms"])
    unstable = {  # the FB twin's loop is the FF twin's: checked alone first, to say which fails
        "FB": f"the loop with the plant is unstable as the twins simulate it at {sim_rate:g} Hz",
        "FF": "the feedforward path Ynms Kpt / Yc / (TI s + 1)^2 is unstable or improper with this plant",
    }
    for model in (replace(ff, name="FB", Kpt=0.0), ff):
        try:
            check_closed_loops((model,), twin_loop, 1.0 / sim_rate)
        except ConfigError:
            return Simulated(sim.values, sim.changes, unstable[model.name])
    return sim


class Remnant(NamedTuple):
    """The twins' remnant filter (SPEC 1): gain at the twins' rate, break frequency, damping."""

    kn: float
    w_n: float
    zeta_n: float


def twin_remnant(remnant: tuple[float, float, float]) -> Simulated:
    """The group's remnant filter ``(kn, w_n, zeta_n)`` as its twins take it (:data:`TWIN_RANGES`),
    with what had to be brought into range, in words (values ``kn``, ``w_n``, ``zeta_n``)."""
    return _in_range(dict(zip(REMNANT, remnant, strict=True)), REMNANT, 1.0)  # no delay: any rate
