"""Direct and two-stage indirect identification of one record (SPEC section 3).

- Direct: i1 = ft shifted forward, i2 = e, o = u.
- Indirect stage 1: i1 = ft shifted, i2 = fd, o = e; the smallest-V candidate
  of its own grid is simulated over the whole record to give ``e_r``, a
  noise-free estimate of e.
- Indirect stage 2: i1 = ft shifted, i2 = e_r, o = u.

Each returns the frontier of its final grid (:class:`hcid.arx.GridFit`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hcid.arx.engine import GridFit, best, fit_grid, simulate
from hcid.config import IdentifyConfig, StageConfig
from hcid.errors import IdentificationError

__all__ = ["METHODS", "MethodResult", "Stage1Choice", "identify", "shift_forward"]

METHODS = ("direct", "indirect")


def shift_forward(x: np.ndarray, n: int) -> np.ndarray:
    """``x(k + n)`` with zeros after the record (SPEC 3: ``ft_s(k) = ft(k + 25)``)."""
    if n == 0:
        return x.copy()
    return np.concatenate([x[n:], np.zeros(n)])


@dataclass(frozen=True)
class Stage1Choice:
    """The stage-1 model of the indirect method: the smallest V of its grid."""

    na: int
    nb1: int
    nb2: int
    nk1: int
    nk2: int
    v: float
    n_candidates: int
    n_unstable: int
    seconds: float


@dataclass(frozen=True)
class MethodResult:
    """Frontier of one method on one record, with the stage-1 choice (indirect only)."""

    method: str
    fit: GridFit
    stage1: Stage1Choice | None
    seconds: float


def _fit(stage: StageConfig, i1, i2, o, threads: int) -> GridFit:
    return fit_grid(
        i1,
        i2,
        o,
        stage.grid,
        stage.estimation.rows(),
        stage.validation.rows(),
        threads=threads,
    )


def identify(
    record: dict[str, np.ndarray],
    settings: IdentifyConfig,
    method: str,
    *,
    rate: float,
    threads: int = 1,
) -> MethodResult:
    """Identify one record by one method.

    Parameters
    ----------
    record : dict of ndarray
        ``ft``, ``fd``, ``e``, ``u`` (rad), shape (N,) each, at ``rate``.
    settings : IdentifyConfig
        Grids, windows and the target shift.
    method : {'direct', 'indirect'}
    rate : float
        Sample rate of the record (Hz), for the target shift in samples.
    threads : int
        Threads of the ARX engine (1 inside a worker process).

    Returns
    -------
    MethodResult
    """
    if method not in METHODS:
        raise IdentificationError(f"method: must be one of {', '.join(METHODS)}, got {method!r}")
    start = time.perf_counter()
    ft_s = shift_forward(record["ft"], settings.shift_samples(rate))
    if method == "direct":
        fit = _fit(settings.direct, ft_s, record["e"], record["u"], threads)
        return MethodResult(method, fit, None, time.perf_counter() - start)

    stage1 = _fit(settings.stage1, ft_s, record["fd"], record["e"], threads)
    row = best(stage1)
    e_r = simulate(
        stage1.a[row],
        stage1.b1[row],
        stage1.b2[row],
        int(stage1.nk1[row]),
        int(stage1.nk2[row]),
        ft_s,
        record["fd"],
    )
    choice = Stage1Choice(
        na=int(stage1.na[row]),
        nb1=int(stage1.nb1[row]),
        nb2=int(stage1.nb2[row]),
        nk1=int(stage1.nk1[row]),
        nk2=int(stage1.nk2[row]),
        v=float(stage1.v[row]),
        n_candidates=stage1.n_candidates,
        n_unstable=stage1.n_unstable_total,
        seconds=time.perf_counter() - start,
    )
    fit = _fit(settings.stage2, ft_s, e_r, record["u"], threads)
    return MethodResult(method, fit, choice, time.perf_counter() - start)
