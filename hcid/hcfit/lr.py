"""The feedforward path's likelihood ratio at a record's forcing lines (issue 47, item 5).

The ``lines`` estimator's cost (:class:`hcid.hcfit.lines.LinesProblem`) is
``C = sum_k |U_k - U_cl,k|^2 / sigma_k^2`` over the forcing lines: for a Gaussian remnant,
``-2 log`` of the likelihood up to a constant. The statistic is ``C_FB - C_FF``, the cost of the
feedback-only model minus that of the model with the feedforward path (Kpt, TI, tau_pt), each
fitted to the same lines: the likelihood ratio of the nested pair. It uses what the W* of an ARX
selection leaves out: the parametric structure of both paths (three parameters for Ht against
an ARX model's free numerator), and the weights of the remnant beside each line.

Its null distribution is not chi-square: the fits are local (bounded least squares from the
group's fitted model, the same start for a run and for its twins, so that their statistics are
made alike), the weights are estimated, and the model only approximates a person. As for W*,
the run's p-value comes from its FB twins (:func:`hcid.selection.calibration.run_p_value`).

**Ties at 0.** Where the lines do not ask for feedforward, the full fit stays at the nested model
(Kpt = 0 is its bound) and ``C_FB - C_FF`` is exactly 0: a point mass shared by runs and twins,
whose ties make the p-values of such runs near 1 rather than uniform (SPEC 13's KS test failed on
it: docs/methodology.md). There the statistic is instead minus the cost's slope in Kpt at the
nested model, ``-dC_FF/dKpt`` (<= 0): how steeply the lines oppose a feedforward path. The slope
is exact, not a finite difference: the closed loop's U is linear in Ht, so in Kpt. Every value
above 0 is a likelihood ratio, every value below it a slope; the order of runs and twins is all
a p-value reads.
"""

from __future__ import annotations

from collections.abc import Mapping

import control
import numpy as np
from scipy import optimize

from hcid.config.fit_settings import FEEDFORWARD_PARAMETERS, FitSettings
from hcid.hcfit.lines import LineData, LinesProblem

__all__ = ["feedforward_lr", "nested_slope"]


def _local_fit(problem: LinesProblem, start: np.ndarray, settings: FitSettings) -> tuple[float, np.ndarray]:
    """The least cost from ``start`` (clipped into the bounds) by bounded least squares."""
    bounds = [settings.bound(n) for n in problem.names]
    lower = np.array([b.lower for b in bounds])
    upper = np.array([b.upper for b in bounds])
    fit = optimize.least_squares(
        problem.residuals,
        np.clip(start, lower, upper),
        jac=lambda x: problem.jacobian(x, lower, upper),
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        xtol=1e-8,
        ftol=1e-8,
        gtol=1e-8,
        max_nfev=200,
    )
    return float(np.sum(fit.fun**2)), fit.x


def nested_slope(problem: LinesProblem, nested: np.ndarray) -> float:
    """``dC/dKpt`` of the model with feedforward at ``nested`` (its Kpt 0): the residuals are
    linear in Kpt (the closed loop's U is linear in Ht), so ``r(Kpt) = r0 + Kpt d`` with
    ``d = r(1) - r0`` and the slope at 0 is ``2 r0 . d``, exactly."""
    i = problem.names.index("Kpt")
    unit = nested.copy()
    unit[i] = 1.0
    r0 = problem.residuals(nested)
    return float(2.0 * r0 @ (problem.residuals(unit) - r0))


def feedforward_lr(
    data: LineData,
    plant: control.TransferFunction,
    disturbance_at: str,
    start: Mapping[str, float],
    settings: FitSettings = FitSettings(),  # noqa: B008 (frozen)
) -> float:
    """``C_FB - C_FF`` where the feedforward path lowers the cost, else ``-dC_FF/dKpt`` at the
    nested model (at most 0; module notes).

    Parameters
    ----------
    data : LineData
        The record at its forcing lines (:func:`hcid.hcfit.lines.line_data`).
    plant : control.TransferFunction
        ``Yc``.
    disturbance_at : str
        ``output`` or ``input`` (SPEC 7).
    start : mapping of str to float
        Every parameter's start (the group's fitted model): the feedback-only fit starts at its
        feedback part; the full fit at ``start`` and at the feedback-only optimum with Kpt = 0
        (the nested model, so the full fit never ends above it), the lower cost kept.
    settings : FitSettings
        The parameters' bounds.
    """
    fb = LinesProblem(data, plant, False, disturbance_at)
    ff = LinesProblem(data, plant, True, disturbance_at)
    cost_fb, x_fb = _local_fit(fb, np.array([start[n] for n in fb.names]), settings)
    # The full model from the start, and from the feedback-only optimum with no feedforward (Kpt
    # 0: the nested model itself, cost C_FB, which least squares only lowers): C_FF <= C_FB.
    nested = {
        **dict(zip(fb.names, x_fb, strict=True)),
        **{n: start[n] for n in FEEDFORWARD_PARAMETERS},
        "Kpt": 0.0,
    }
    cost_ff = min(_local_fit(ff, np.array([s[n] for n in ff.names]), settings)[0] for s in (start, nested))
    if cost_fb - cost_ff > 0.0:
        return cost_fb - cost_ff
    return -max(nested_slope(ff, np.array([nested[n] for n in ff.names])), 0.0)
