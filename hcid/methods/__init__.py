"""The registry of identification methods: direct and two-stage indirect (SPEC 3).

Everything that identifies, tabulates or reports iterates over :data:`METHODS`
in registration order. To add a method, write one module defining a
:class:`~hcid.methods.base.Method` (its stages, their SPEC defaults, its run
function), register it below, and give its stages a section under ``identify``
in the config if the defaults do not fit. A test may register a toy method with
:func:`registered`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping

import numpy as np

from hcid.config.types import IdentifyConfig
from hcid.errors import IdentificationError
from hcid.methods import direct, indirect
from hcid.methods.base import Method, MethodResult, StageChoice, StageSpec, shift_forward

__all__ = [
    "METHODS",
    "Method",
    "MethodResult",
    "StageChoice",
    "StageSpec",
    "get",
    "identify",
    "registered",
    "shift_forward",
    "resolved",
    "stage_specs",
]

#: Registered methods by name, in the order tables and reports list them.
METHODS: dict[str, Method] = {m.name: m for m in (direct.METHOD, indirect.METHOD)}


def get(name: str) -> Method:
    """The registered method ``name``; one-line error naming the choices otherwise."""
    try:
        return METHODS[name]
    except KeyError:
        raise IdentificationError(f"method: must be one of {', '.join(METHODS)}, got {name!r}") from None


def resolved(settings: IdentifyConfig) -> dict[str, Method]:
    """The registered methods whose every stage ``settings`` holds (those a config was resolved for)."""
    built = {name for name, _ in settings.stages}
    return {n: m for n, m in METHODS.items() if all(spec.name in built for spec in m.stages)}


def stage_specs() -> dict[str, StageSpec]:
    """Every registered method's stages by name, in registration order (what ``identify`` may hold)."""
    out: dict[str, StageSpec] = {}
    for method in METHODS.values():
        for stage in method.stages:
            out.setdefault(stage.name, stage)
    return out


@contextlib.contextmanager
def registered(method: Method) -> Iterator[Method]:
    """Register ``method`` for the duration of a ``with`` block (tests, plug-ins)."""
    if method.name in METHODS:
        raise IdentificationError(f"method: {method.name!r} is already registered")
    METHODS[method.name] = method
    try:
        yield method
    finally:
        del METHODS[method.name]


def identify(
    record: Mapping[str, np.ndarray], settings: IdentifyConfig, method: str, *, rate: float, threads: int = 1
) -> MethodResult:
    """Identify one record by one method.

    Parameters
    ----------
    record : mapping of ndarray
        ``ft``, ``fd``, ``e``, ``u`` (rad), shape (N,) each, at ``rate``.
    settings : IdentifyConfig
        Stages (grids, windows) and the target shift.
    method : str
        A registered method's name.
    rate : float
        Sample rate of the record (Hz), for the target shift in samples.
    threads : int
        Threads of the ARX engine (1 inside a worker process).
    """
    chosen = get(method)
    shift = settings.shift_samples(rate)
    # Only the samples the windows use (and the target shift's look-ahead) are identified:
    # the simulated outputs before them do not depend on later samples.
    need = max(
        max(s.estimation.last, s.validation.last) for s in (settings.stage(x.name) for x in chosen.stages)
    )
    keep = {name: np.asarray(x)[: need + shift] for name, x in record.items()}
    return chosen.run(keep, settings, shift, threads)
