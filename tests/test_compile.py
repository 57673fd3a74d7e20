"""Compiling ahead (issue 28): ``compile_before_fork`` compiles what a study's fits then run.

Source of the expectation: a kernel compiled (or loaded) ahead is one numba need not compile
again, so a fit after ``hcid.pipeline.parallel.compile_before_fork`` adds no signature to any of the
engine's kernels; if the ahead-of-time call used other argument types (a Python int for an
int64 array, a C for an F layout), the fit would compile its own and this test fails.
"""

import json
import subprocess
import sys

import numba
import pytest

pytestmark = pytest.mark.skipif(numba.config.DISABLE_JIT, reason="nothing compiles without the JIT")

SCRIPT = """
import json
import numba
import numpy as np
from hcid.arx import _blocks, _kernels, _lanes, engine
from hcid.arx.grid import Grid
from hcid.pipeline.parallel import compile_before_fork


def signatures():
    out = {}
    for module in (_blocks, _kernels, _lanes):
        for name, f in vars(module).items():
            if isinstance(f, numba.core.registry.CPUDispatcher):
                out[module.__name__ + "." + name] = sorted(map(str, f.signatures))
    return out


compile_before_fork()
before = signatures()
rng = np.random.default_rng(1)
i1, i2 = rng.standard_normal(600), rng.standard_normal(600)
o = np.convolve(i1, [0.0, 0.5, 0.2])[:600] + 0.1 * rng.standard_normal(600)
# The vector steps (affine groups and general lanes, fused) and the plain path (unfused). Not
# na above 12 (no study of the paper's grids has it): its frontier's errors are a kernel of
# their own (_kernels.squared_errors), compiled when first taken.
for grid, fused in (
    (Grid((1, 3), (0, 3), (0, 2), (1, 12), (1, 3)), None),
    (Grid((1, 2), (0, 2), (0, 1), (1, 9), (1, 2)), False),
):
    fit = engine.fit_grid(i1, i2, o, grid, slice(50, 300), slice(300, 600), fused=fused)
row = engine.best(fit)
engine.simulate(fit.a[row], fit.b1[row], fit.b2[row], int(fit.nk1[row]), int(fit.nk2[row]), i1, i2)
after = signatures()
print(json.dumps({"before": before, "after": after}))
"""


def test_a_fit_after_compile_kernels_compiles_nothing_new():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    before, after = result["before"], result["after"]
    new = {k: sorted(set(v) - set(before.get(k, []))) for k, v in after.items()}
    assert {k: v for k, v in new.items() if v} == {}
    # The entries a fit calls from Python were there before it, compiled or loaded ahead.
    for name in ("hcid.arx._blocks.simulate_blocks", "hcid.arx._blocks.simulate_blocks_plain",
                 "hcid.arx._kernels.fit_units", "hcid.arx._blocks.squared_errors_wide"):  # fmt: skip
        assert before[name], name
