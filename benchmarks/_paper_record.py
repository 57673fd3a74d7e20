"""One realistic record for the benchmarks: the paper config, FF model, seed 1.

Mirrors the ``paper_record`` fixture of ``tests/conftest.py`` (kept here, not
in ``hcid``, because only benchmarks need it).
"""

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# The slow twins the benchmarks compare with live with the tests (tests/naive.py).
sys.path.insert(0, str(ROOT / "tests"))
PAPER_CONFIG = ROOT / "configs" / "paper.yaml"


def paper_record(model: str = "FF", seed: int = 1) -> dict[str, np.ndarray]:
    """ft_s, fd, e, u (rad) of one paper record at 25 Hz, 2048 samples.

    ``ft_s(k) = ft(k + 25)``, zeros after the record (SPEC section 3).
    """
    from hcid.assembly.resolve import load_config
    from hcid.loop.simulate import remnant_gain, simulate_realization
    from hcid.methods import shift_forward

    config = load_config(PAPER_CONFIG)
    r = simulate_realization(config, config.model(model), seed, remnant_gain(config))
    shift = config.identify.shift_samples(config.timing.output_rate)
    ft_s = shift_forward(r.ft, shift)
    return {"ft_s": ft_s, "fd": r.fd, "e": r.e, "u": r.u}
