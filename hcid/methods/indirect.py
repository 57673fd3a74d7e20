"""The two-stage indirect method (SPEC 3).

- Stage 1: i1 = ft shifted, i2 = fd, o = e; the smallest-V candidate of its
  grid is simulated over the whole record to give ``e_r``, a noise-free
  estimate of e.
- Stage 2: i1 = ft shifted, i2 = e_r, o = u, on the direct method's grid and
  windows unless the config gives its own.
"""

from __future__ import annotations

import time

from hcid.arx.engine import simulate
from hcid.methods.base import Method, MethodResult, StageSpec, choose, fit_stage, refit, shift_forward
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


def _run(record, settings, shift, threads) -> MethodResult:
    start = time.perf_counter()
    ft_s = shift_forward(record["ft"], shift)
    stage1 = fit_stage(settings.stage("stage1"), ft_s, record["fd"], record["e"], threads)
    row, choice = choose("stage1", stage1, start)
    e_r = simulate(stage1.a[row], stage1.b1[row], stage1.b2[row], choice.nk1, choice.nk2, ft_s, record["fd"])
    fit = fit_stage(settings.stage("stage2"), ft_s, e_r, record["u"], threads)
    return MethodResult("indirect", fit, (choice,), time.perf_counter() - start)


def _signals(record, settings, shift, choices):
    # e_r again from stage 1's stored choice (stage1.parquet holds its orders, not its
    # coefficients): the one candidate is refitted, its V checked against the stored one.
    (choice,) = choices
    ft_s = shift_forward(record["ft"], shift)
    a, b1, b2 = refit(settings.stage("stage1"), choice, ft_s, record["fd"], record["e"])
    e_r = simulate(a, b1, b2, choice.nk1, choice.nk2, ft_s, record["fd"])
    return ft_s, e_r, record["u"]


METHOD = Method(
    name="indirect",
    stages=(
        StageSpec("stage1", ("ft", "fd", "e"), STAGE1_DEFAULTS),
        StageSpec("stage2", ("ft", "e", "u"), DIRECT_DEFAULTS, defaults_from="direct"),
    ),
    run=_run,
    signals=_signals,
)
