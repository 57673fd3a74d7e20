"""Which estimator fits the parametric HC model (``FitSettings.target``): ``auto`` resolved from the
record (:func:`resolve_target`), the estimators by name (:data:`ESTIMATORS`, each in
:mod:`hcid.hcfit.fit`), and the neuromuscular pair held where a fit leaves it undetermined
(:func:`fit_parametric`, with :func:`nested_test`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np
from scipy import stats

from hcid.config.fit_settings import FEEDBACK_PARAMETERS, FitSettings
from hcid.errors import DataError, IdentificationError
from hcid.hcfit.consistency import CONTRADICTED
from hcid.hcfit.determined import LITERATURE_NMS, nms_undetermined
from hcid.hcfit.fit import HCFit, fit_closed_loop, fit_frequency, fit_lines, fit_time
from hcid.hcfit.lines import LineData, line_data
from hcid.hcfit.model import TrackingRecord

__all__ = ["ESTIMATORS", "MIN_DISTURBANCE_LINES", "fit_parametric", "nested_test", "resolve_target"]


#: ``auto`` takes the ``lines`` estimator only where the disturbance has at least one line per
#: feedback parameter: each line gives He at one frequency (two numbers), and with fewer lines the
#: feedback path is barely determined by them (the CPHS second-order plant's 3 lines: twins with
#: a person's remnant were fitted better by ``time``; docs/parametric-fit.md).
MIN_DISTURBANCE_LINES = len(FEEDBACK_PARAMETERS)


def resolve_target(target: str, record: TrackingRecord | None) -> str:
    """The estimator ``auto`` stands for on this record: ``lines`` where its forcing functions are
    multisines on disjoint lines over whole periods (:func:`hcid.hcfit.lines.line_data`) and the
    disturbance has at least :data:`MIN_DISTURBANCE_LINES` lines, else ``time``; any other target
    is itself."""
    return _resolve(target, record)[0]


def _resolve(target: str, record: TrackingRecord | None) -> tuple[str, LineData | None]:
    """The target and, where read, the record's lines."""
    if target not in ("auto", "lines") or record is None or record.fd is None:
        return ("time" if target == "auto" else target), None
    try:
        data = line_data(record)
    except DataError:
        if target == "lines":
            raise
        return "time", None
    if target == "auto" and np.count_nonzero(~data.is_target) < MIN_DISTURBANCE_LINES:
        return "time", data
    return "lines", data


@dataclass(frozen=True)
class _Asked:
    """What :func:`fit_parametric` was given, for the estimator its target names."""

    settings: FitSettings
    plant: control.TransferFunction
    feedforward: bool
    record: TrackingRecord | None
    omega: np.ndarray | None
    he: np.ndarray | None
    hft: np.ndarray | None
    disturbance_at: str
    data: LineData | None


def _by_frequency(a: _Asked, fixed) -> HCFit:
    if a.omega is None or a.he is None or (a.hft is None) == a.feedforward:
        raise IdentificationError(
            "omega, he, hft: the frequency target needs omega and he, and hft exactly when feedforward"
        )
    return fit_frequency(a.omega, a.he, a.hft, a.plant, a.settings, a.record, fixed)


#: The estimators by target (``FitSettings.target``; ``auto`` is resolved to ``lines`` or ``time``
#: first, :func:`resolve_target`): each takes what :func:`fit_parametric` was given and the held
#: parameters.
ESTIMATORS = {
    "lines": lambda a, fixed: fit_lines(
        a.record, a.plant, a.feedforward, a.settings, a.disturbance_at, fixed, a.data
    ),
    "closed_loop": lambda a, fixed: fit_closed_loop(
        a.record, a.plant, a.feedforward, a.settings, a.disturbance_at, fixed
    ),
    "time": lambda a, fixed: fit_time(a.record, a.plant, a.feedforward, a.settings, fixed),
    "frequency": _by_frequency,
}


def fit_parametric(
    settings: FitSettings,
    plant: control.TransferFunction,
    feedforward: bool,
    *,
    record: TrackingRecord | None = None,
    omega: np.ndarray | None = None,
    he: np.ndarray | None = None,
    hft: np.ndarray | None = None,
    disturbance_at: str = "output",
) -> HCFit:
    """Fit by ``settings.target`` (``auto``: :func:`resolve_target`) and ``settings.nms``.

    The targets: :func:`fit_lines`, :func:`fit_time`, :func:`fit_closed_loop` or
    :func:`fit_frequency`. The frequency target needs ``omega`` and ``he`` (and ``hft``
    exactly when ``feedforward``); the others need ``record`` (with its fd for ``lines`` and
    ``closed_loop``), which the frequency target uses for its validation VAF when given.

    ``settings.nms``: ``free`` fits the neuromuscular pair; ``fixed`` holds it at
    :data:`hcid.hcfit.determined.LITERATURE_NMS`; ``auto`` (the default) fits it and, where
    the fit leaves either of the pair undetermined (:func:`hcid.hcfit.determined.nms_undetermined`),
    fits again with the pair held there (``HCFit.fixed`` says so) and keeps that reduced model,
    unless (``lines`` target, whose residuals allow the test) the nested F test
    (:func:`nested_test`) rejects the held values at
    :data:`~hcid.hcfit.consistency.CONTRADICTED`. For the time-domain targets, whose residuals
    are correlated, no such test is made: an undetermined pair is held.
    """
    target, data = _resolve(settings.target, record)
    if target != "frequency" and record is None:
        raise IdentificationError(f"record: the {target} target needs the measured record")
    asked = _Asked(settings, plant, bool(feedforward), record, omega, he, hft, disturbance_at, data)

    def fit(fixed):
        return ESTIMATORS[target](asked, fixed)

    if settings.nms == "fixed":
        return fit(LITERATURE_NMS)
    full = fit(None)
    if settings.nms != "auto" or not nms_undetermined(full):
        return full
    reduced = fit(LITERATURE_NMS)
    if target == "lines" and nested_test(full, reduced, 2 * data.omega.size) < CONTRADICTED:
        return full  # the data reject the literature pair
    return reduced


def nested_test(full: HCFit, reduced: HCFit, n: int) -> float:
    """p-value of the F test of ``reduced`` (some parameters held) against ``full`` on the same
    ``n`` independent residuals: ``((C_r - C_f) / q) / (C_f / (n - p))``, F(q, n - p) when the held
    values are right (q held parameters, p fitted in ``full``). Valid for the ``lines`` target,
    whose residuals are independent DFT bins; NaN without residual degrees of freedom."""
    q = len(reduced.fixed) - len(full.fixed)
    p = len(full.names) - len(full.fixed)
    if q <= 0 or n <= p or full.cost <= 0:
        return math.nan
    f = max(reduced.cost - full.cost, 0.0) / q / (full.cost / (n - p))
    return float(stats.f.sf(f, q, n - p))
