"""The same bits on every machine: OpenBLAS's kernels pinned before numpy loads.

OpenBLAS picks its kernels for the CPU it runs on, and AVX-512 kernels round differently from
AVX2 ones: the same inputs then give tables that differ in their last bits between an AVX-512
machine and an AVX2 one (measured on the ci study: every table; issue 47). Where the CPU has AVX2,
hcid asks OpenBLAS for its Haswell (AVX2) kernels, which every such CPU runs, so that one machine's
tables are another's. It must happen before numpy is imported (OpenBLAS reads the setting once,
when it loads), so ``hcid/__init__.py`` calls :func:`pin_openblas` first; the worker processes of
``--jobs`` inherit the environment. A user's own ``OPENBLAS_CORETYPE`` wins, and where numpy is
already loaded (a notebook that imported it first) nothing is set: the workers then run the
kernels the parent runs, so results still do not depend on the number of workers.
"""

from __future__ import annotations

import os
import sys
from collections.abc import MutableMapping
from pathlib import Path

#: The variable OpenBLAS reads, and the kernels hcid pins where the CPU can run them.
VARIABLE = "OPENBLAS_CORETYPE"
KERNELS = "Haswell"


def cpu_flags(cpuinfo: Path = Path("/proc/cpuinfo")) -> frozenset[str]:
    """The CPU's feature flags as Linux lists them (empty where there is no such file).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     info = Path(d) / "cpuinfo"
    ...     _ = info.write_text("model name\\t: X\\nflags\\t\\t: fpu avx2 fma\\n")
    ...     sorted(cpu_flags(info))
    ['avx2', 'fma', 'fpu']
    """
    try:
        text = cpuinfo.read_text()
    except OSError:
        return frozenset()
    line = next((x for x in text.splitlines() if x.startswith("flags")), "")
    return frozenset(line.split(":", 1)[1].split()) if ":" in line else frozenset()


def pin_openblas(
    environ: MutableMapping[str, str] | None = None,
    flags: frozenset[str] | None = None,
    numpy_loaded: bool | None = None,
) -> str | None:
    """Set ``OPENBLAS_CORETYPE=Haswell`` where the CPU has AVX2 and FMA, the variable is unset and
    numpy is not loaded yet; returns what was set (None where nothing was).

    Examples
    --------
    >>> env = {}
    >>> pin_openblas(env, frozenset({"avx2", "fma"}), numpy_loaded=False), env
    ('Haswell', {'OPENBLAS_CORETYPE': 'Haswell'})
    >>> pin_openblas({"OPENBLAS_CORETYPE": "SkylakeX"}, frozenset({"avx2", "fma"}), False)  # the user's wins
    >>> pin_openblas({}, frozenset({"sse4_2"}), False)  # no AVX2: OpenBLAS's own choice
    >>> pin_openblas({}, frozenset({"avx2", "fma"}), True)  # numpy already loaded: too late
    """
    environ = os.environ if environ is None else environ
    flags = cpu_flags() if flags is None else flags
    numpy_loaded = "numpy" in sys.modules if numpy_loaded is None else numpy_loaded
    if VARIABLE in environ or numpy_loaded or not {"avx2", "fma"} <= flags:
        return None
    environ[VARIABLE] = KERNELS
    return KERNELS
