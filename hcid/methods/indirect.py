"""The two-stage indirect method (SPEC 3).

- Stage 1: i1 = ft shifted, i2 = fd, o = e; the smallest-V candidate of its
  grid is simulated over the whole record to give ``e_r``, a noise-free
  estimate of e.
- Stage 2: i1 = ft shifted, i2 = e_r, o = u, on the direct method's grid and
  windows unless the config gives its own.

Stage 1 has two options (``identify.stage1.<key>``) for studying how it is
done; their defaults are SPEC 3:

- ``rows``: ``auto`` fits and validates on the stage's windows (SPEC 3: from
  the grid's largest lag on); ``zero_initial`` on every sample of the record,
  with the regressors before the record taken as zero, as the paper describes
  MATLAB's ``arx`` on "all data, k = 1..2048". The ARX engine pads inputs and
  output with zeros before the record, so it fits those rows as they are.
- ``model``: ``best`` takes the smallest-V candidate of the grid; ``fixed``
  fits only ``fixed_orders`` = [na, nb_ft, nb_fd, nk_ft, nk_fd] (the authors'
  public code uses a fixed low order such as [4, 2, 2, 6, 6]). nk_ft counts
  from the shifted target, as everywhere in hcid.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

from hcid.arx.engine import fit_grid
from hcid.arx.simulation import simulate
from hcid.config.types import Grid
from hcid.errors import ConfigError
from hcid.methods.base import (
    Method,
    MethodResult,
    StageOption,
    StageSpec,
    choose,
    fit_stage,
    one_of,
    refit,
    shift_forward,
)
from hcid.methods.direct import DIRECT_DEFAULTS

#: SPEC 3: the stage-1 grid (64,260 candidates); its windows run from the grid's largest lag on.
STAGE1_DEFAULTS = {
    "na": [1, 10],
    "nb1": [0, 25],
    "nb2": [0, 10],
    "nk1": [1, 5],
    "nk2": [1, 5],
    "estimation": "auto",
    "validation": "auto",
}


def _orders(value: Any, key: str) -> tuple[int, ...]:
    ok = (
        isinstance(value, list | tuple)
        and len(value) == 5
        and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    )
    if ok:
        try:
            Grid(*((v, v) for v in value))
        except ConfigError:
            ok = False
    if not ok:
        raise ConfigError(
            f"{key}: must be [na, nb_ft, nb_fd, nk_ft, nk_fd] with na >= 1 and the others >= 0, got {value!r}"
        )
    return tuple(value)


#: Stage-1 options (module docstring); the defaults are SPEC 3.
STAGE1_OPTIONS = {
    "rows": StageOption("auto", one_of("auto", "zero_initial"), "stage windows, or every sample from zero"),
    "model": StageOption("best", one_of("best", "fixed"), "smallest V of the grid, or fixed_orders"),
    "fixed_orders": StageOption((4, 2, 2, 6, 6), _orders, "[na, nb_ft, nb_fd, nk_ft, nk_fd] of model: fixed"),
}


def _stage1_fit(settings, ft_s, fd, e, threads):
    stage = settings.stage("stage1")
    grid = stage.grid
    if STAGE1.option(stage, "model") == "fixed":
        grid = Grid(*((v, v) for v in STAGE1.option(stage, "fixed_orders")))
    # Only the grid's smallest V is kept (SPEC 3), so the search need not finish the other triples.
    return fit_grid(ft_s, fd, e, grid, *_stage1_rows(settings, e.size), threads=threads, best_only=True)


def _stage1_rows(settings, n: int) -> tuple[slice, slice]:
    """Stage 1's estimation and validation rows: its windows, or every sample (``rows: zero_initial``)."""
    stage = settings.stage("stage1")
    if STAGE1.option(stage, "rows") == "zero_initial":
        return slice(0, n), slice(0, n)
    return stage.estimation.rows(), stage.validation.rows()


def _run(record, settings, shift, threads) -> MethodResult:
    start = time.perf_counter()
    ft_s = shift_forward(record["ft"], shift)
    stage1 = _stage1_fit(settings, ft_s, record["fd"], record["e"], threads)
    row, choice = choose("stage1", stage1, start)
    e_r = simulate(stage1.a[row], stage1.b1[row], stage1.b2[row], choice.nk1, choice.nk2, ft_s, record["fd"])
    fit = fit_stage(settings.stage("stage2"), ft_s, e_r, record["u"], threads)
    choice = dataclasses.replace(choice, signal=e_r)
    return MethodResult("indirect", fit, (choice,), time.perf_counter() - start)


def _signals(record, settings, shift, choices):
    # e_r again from stage 1's stored choice (stage1.parquet holds its orders, not its
    # coefficients): the one candidate is refitted on the rows it was chosen on, its V
    # checked against the stored one.
    (choice,) = choices
    ft_s = shift_forward(record["ft"], shift)
    a, b1, b2 = refit(choice, ft_s, record["fd"], record["e"], *_stage1_rows(settings, record["e"].size))
    e_r = simulate(a, b1, b2, choice.nk1, choice.nk2, ft_s, record["fd"])
    return ft_s, e_r, record["u"]


STAGE1 = StageSpec("stage1", ("ft", "fd", "e"), STAGE1_DEFAULTS, options=STAGE1_OPTIONS)

METHOD = Method(
    name="indirect",
    stages=(STAGE1, StageSpec("stage2", ("ft", "e", "u"), DIRECT_DEFAULTS, defaults_from="direct")),
    run=_run,
    signals=_signals,
)
