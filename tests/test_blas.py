"""The same bits on every machine (issue 47): OpenBLAS's Haswell (AVX2) kernels wherever hcid
starts, on a CPU that runs them; a user's own setting wins; never too late to hold."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from hcid._blas import cpu_flags

#: What OpenBLAS reports it runs, in a fresh interpreter, after ``first`` (Python code).
_PROBE = (
    "import threadpoolctl, numpy; "
    "print([i.get('architecture') for i in threadpoolctl.threadpool_info() if i['internal_api'] == "
    "'openblas'])"
)


def _kernels(first: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    out = subprocess.run(
        [sys.executable, "-c", f"{first}; {_PROBE}"],
        env={**clean, **env},
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.strip()


needs_avx2 = pytest.mark.skipif(
    not {"avx2", "fma"} <= cpu_flags(), reason="a CPU without AVX2 and FMA: OpenBLAS keeps its own kernels"
)


@needs_avx2
def test_importing_hcid_first_pins_the_haswell_kernels():
    # The CLI (`hcid` imports the package first), the API and the workers of --jobs (they inherit
    # the environment) all run OpenBLAS's Haswell kernels: on this machine without the pin,
    # OpenBLAS picks its own (SkylakeX on an AVX-512 Xeon), whose last bits differ.
    assert _kernels("import hcid") == "['Haswell']"
    pool = (
        "import hcid, os; from joblib import Parallel, delayed; "
        "print(Parallel(n_jobs=2, backend='loky')(delayed(os.environ.get)('OPENBLAS_CORETYPE') "
        "for _ in range(2)))"
    )
    assert _kernels(pool).splitlines()[0] == "['Haswell', 'Haswell']"


@needs_avx2
def test_a_users_own_setting_wins_and_a_late_import_sets_nothing():
    assert _kernels("import hcid", OPENBLAS_CORETYPE="Sandybridge") == "['Sandybridge']"
    # numpy loaded before hcid: too late for this process, so nothing is set (its workers then run
    # what it runs, and results do not depend on --jobs).
    late = "import numpy, os, hcid; assert 'OPENBLAS_CORETYPE' not in os.environ"
    assert _kernels(late) != "['Haswell']" or "avx512f" not in cpu_flags()
