"""Analyses of one selected ARX model: its parametric HC fit and its residuals.

Given a record, the model a method selected at some W (its orders and
coefficients, from ``frontier.parquet``) and the earlier stages' choices, this
module fits the parametric HC model of SPEC sections 1, 7 and 8
(:mod:`hcid.hcfit`) and analyses the selected model's simulation residual
(:mod:`hcid.residuals`). Pure: arrays and dataclasses in, dataclasses out.

- Fit targets (``config.fit_hc.target``): ``frequency`` fits the parametric
  paths to the ARX paths (SPEC 5: ``Hft`` with the target shift undone, ``He``)
  on the log grid of ``fit_hc.band``; ``time`` fits the measured u. The
  feedforward parameters are fitted exactly when the selected model has
  ``nb_ft > 0``. A frequency fit needs a feedback path: a selected model with
  ``nb_e = 0`` is not fitted (``fit`` is None).
- Residual: ``eps = o - o_hat``, ``o_hat`` the selected model simulated from
  rest on the final stage's own inputs (:meth:`hcid.methods.Method.final_signals`:
  ft_s and e for the direct method, ft_s and e_r for the indirect one, e_r
  from stage 1's stored choice refitted), analysed over the final stage's
  validation rows for lags up to :data:`RESIDUAL_MAX_LAG` s. Its inputs are
  named ``ft_s`` (the shifted target the model sees: a lag of ``ft_s`` is
  that lag minus the shift for ft) and ``e`` (e_r for the indirect method).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from hcid import hcfit
from hcid.arx.engine import simulate
from hcid.arx.response import path_response
from hcid.config import Config
from hcid.hcmodel import plant
from hcid.methods import Method, StageChoice
from hcid.residuals import ResidualAnalysis, analyse_residuals

__all__ = [
    "RESIDUAL_CONFIDENCE",
    "RESIDUAL_MAX_LAG",
    "SelectedAnalysis",
    "SelectedModel",
    "analyse_selected",
    "true_parameters",
]

#: Largest residual-correlation lag (s): 1 s, the target shift, 25 samples at 25 Hz.
RESIDUAL_MAX_LAG = 1.0
#: Confidence of the white-residual band (the issue's 99%, MATLAB resid's default).
RESIDUAL_CONFIDENCE = 0.99


@dataclass(frozen=True)
class SelectedModel:
    """A frontier row selected at ``w``: orders, delays (samples), V and coefficients.

    ``a = [1, a1, ..]``; ``b_ft``, ``b_e`` empty for a dropped input (SPEC 3).
    """

    w: float
    na: int
    nb_ft: int
    nb_e: int
    nk_ft: int
    nk_e: int
    v: float
    vaf_validation: float
    a: np.ndarray
    b_ft: np.ndarray
    b_e: np.ndarray

    @property
    def orders(self) -> tuple[int, int, int, int, int]:
        return (self.na, self.nb_ft, self.nb_e, self.nk_ft, self.nk_e)


@dataclass(frozen=True)
class SelectedAnalysis:
    """The fit (None when not fitted: a frequency fit of a model without feedback path)
    and the residual analysis of one selected model."""

    model: SelectedModel
    fit: hcfit.HCFit | None
    residuals: ResidualAnalysis


def true_parameters(config: Config, model_name: str) -> dict[str, float]:
    """The SPEC-8 parameters of a simulated model: its HC model and the loop's NMS.

    A model without feedforward (``Kpt = 0``) has ``Kpt = 0`` and no ``TI``,
    ``tau_pt`` (NaN).
    """
    m = config.model(model_name)
    ff = m.has_feedforward
    return {
        "Kpe": m.Kpe,
        "TL": m.TL,
        "tau_pe": m.tau_pe,
        "w_nms": config.loop.w_nms,
        "zeta_nms": config.loop.zeta_nms,
        "Kpt": m.Kpt,
        "TI": m.TI if ff else float("nan"),
        "tau_pt": m.tau_pt if ff else float("nan"),
    }


def analyse_selected(
    selected: SelectedModel,
    record: Mapping[str, np.ndarray],
    config: Config,
    method: Method,
    choices: tuple[StageChoice, ...] = (),
) -> SelectedAnalysis:
    """Fit the parametric HC model to a selected model and analyse its residual.

    Parameters
    ----------
    selected : SelectedModel
        The model ``method`` selected on ``record``.
    record : mapping of ndarray
        ``ft`` (unshifted), ``fd``, ``e``, ``u`` (rad), shape (N,), at
        ``config.timing.output_rate``.
    config : Config
        Loop (plant), identification stages (windows, target shift) and the
        fit settings ``config.fit_hc`` (band resolved).
    method : Method
        The method that selected the model (:data:`hcid.methods.METHODS`).
    choices : tuple of StageChoice
        The earlier stages' choices on this record (``stage1.parquet``).

    Returns
    -------
    SelectedAnalysis
    """
    settings = config.fit_hc
    rate = config.timing.output_rate
    dt = 1.0 / rate
    stage = config.identify.stage(method.final_stage.name)
    estimation, validation = stage.estimation.rows(), stage.validation.rows()
    yc = plant(config.loop)
    feedforward = selected.nb_ft > 0
    tracking = hcfit.TrackingRecord(record["ft"], record["e"], record["u"], rate, estimation, validation)

    fit = None
    if settings.target == "time" or selected.nb_e > 0:
        omega = hcfit.band_grid(settings.band, settings.points)
        he = path_response(selected.a, selected.b_e, selected.nk_e, omega, dt)
        hft = (
            path_response(
                selected.a, selected.b_ft, selected.nk_ft, omega, dt, advance=config.identify.target_shift
            )
            if feedforward
            else None
        )
        fit = hcfit.fit_hc(settings, yc, feedforward, record=tracking, omega=omega, he=he, hft=hft)

    shift = config.identify.shift_samples(rate)
    i1, i2, o = method.final_signals(record, config.identify, shift, choices)
    o_hat = simulate(selected.a, selected.b_ft, selected.b_e, selected.nk_ft, selected.nk_e, i1, i2)
    inputs = {"ft_s": i1, method.final_stage.inputs[1]: i2}
    # A series constant over the rows has no correlation (e.g. a target holding still).
    inputs = {k: x for k, x in inputs.items() if np.ptp(x[validation]) > 0}
    residuals = analyse_residuals(
        o - o_hat,
        inputs,
        validation,
        max_lag=round(RESIDUAL_MAX_LAG * rate),
        rate=rate,
        confidence=RESIDUAL_CONFIDENCE,
    )
    return SelectedAnalysis(model=selected, fit=fit, residuals=residuals)
