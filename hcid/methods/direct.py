"""The direct method (SPEC 3): i1 = ft shifted forward, i2 = e, o = u, one stage."""

from __future__ import annotations

import time

from hcid.methods.base import Method, MethodResult, StageSpec, arithmetic, fit_stage, shift_forward

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
    fit = fit_stage(DIRECT, settings.stage("direct"), ft_s, record["e"], record["u"], threads)
    return MethodResult("direct", fit, (), time.perf_counter() - start)


#: Fused multiply-adds by default: 0.8x the time of the grid, V within 1e-12 relative of the
#: unfused values on the paper's direct and stage-2 grids but for 5 of the study's 89,600
#: frontier rows (at most 4.1e-12), every selection the same (README, "The ARX engine").
DIRECT = StageSpec("direct", ("ft", "e", "u"), DIRECT_DEFAULTS, options=arithmetic("fused"))

METHOD = Method(name="direct", stages=(DIRECT,), run=_run)
