"""The direct method (SPEC 3): i1 = ft shifted forward, i2 = e, o = u, one stage."""

from __future__ import annotations

import time

from hcid.methods.base import Method, MethodResult, StageSpec, fit_stage, shift_forward

#: SPEC 3: the direct grid and windows (174,447 candidates).
DIRECT_DEFAULTS = {
    "na": [1, 7],
    "nb1": [0, 7],
    "nb2": [0, 7],
    "nk1": [1, 50],
    "nk2": [1, 10],
    "estimation": [129, 1088],
    "validation": [1089, 2048],
}


def _run(record, settings, shift, threads) -> MethodResult:
    start = time.perf_counter()
    ft_s = shift_forward(record["ft"], shift)
    fit = fit_stage(settings.stage("direct"), ft_s, record["e"], record["u"], threads)
    return MethodResult("direct", fit, (), time.perf_counter() - start)


METHOD = Method(
    name="direct",
    stages=(StageSpec("direct", ("ft", "e", "u"), DIRECT_DEFAULTS),),
    run=_run,
)
