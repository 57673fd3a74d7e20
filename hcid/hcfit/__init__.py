"""Parametric fit of the HC model to a selected ARX model (SPEC section 8).

The parametric paths are those of SPEC sections 1 and 7 with continuous delays:

    He_par  = Ynms * Kpe (TL s + 1) exp(-s tau_pe)                 u per e
    Hft_par = Ynms * Kpt / Yc / (TI s + 1)^2 exp(-s tau_pt)        u per ft
    Ynms    = w_nms^2 / (s^2 + 2 zeta_nms w_nms s + w_nms^2)

with the plant ``Yc`` any proper continuous python-control transfer function
(:func:`hcid.loop.hcmodel.plant`); it is only evaluated through its frequency
response and its numerator and denominator polynomials. The feedforward
parameters are fitted only when the selected model has a feedforward path
(``nb_ft > 0``).

Four targets (:data:`TARGETS`), and ``auto``, the default: ``lines`` where the record's
forcing functions are multisines with at least one disturbance line per feedback parameter, else
``time`` (:func:`resolve_target`; how it was chosen: docs/parametric-fit.md):

- ``lines``: the parametric model in closed loop with the plant, driven by the recorded ft and
  fd, output error on U at the forcing lines weighted by the remnant beside each
  (:func:`fit_lines`, :mod:`hcid.hcfit.lines`).
- ``time``: minimise ``sum (u - u_par)^2`` over the estimation rows, where
  ``u_par = Hft_par ft + He_par e`` is simulated from the measured, unshifted ft
  and e (:func:`simulate_hc`).
- ``closed_loop``: the parametric model in closed loop with the plant, driven
  by the measured ft and fd, output error on u (:func:`closed_loop_u`): the
  least biased on the paper study, as the remnant cannot reach its inputs, but
  more spread.
- ``frequency`` (the authors' approach): minimise
  ``sum_w |H_arx - H_par|^2 / |H_arx|^2`` over both paths on a log grid of the
  disturbance band (:func:`band_grid`; the config's
  :attr:`hcid.config.Config.disturbance_band`), the relative complex error.

The neuromuscular pair is held at literature values where a fit leaves it undetermined
(``FitSettings.nms``, :mod:`hcid.hcfit.determined`, which also gives each parameter's status).

All run a seeded global stage (``scipy.optimize.differential_evolution`` over
the starting ranges) and then a bounded local stage
(``scipy.optimize.least_squares``) from the global result and from
``starts`` points drawn from the starting ranges with the seed; the best local
result wins. Equal inputs and settings give identical results. Each estimate
carries a standard error (:mod:`hcid.hcfit.uncertainty`: a lag-window sandwich
by default, right for the coloured residuals a remnant leaves).
"""

from hcid.config.fit_settings import (
    DEFAULT_BOUNDS,
    FEEDBACK_PARAMETERS,
    FEEDFORWARD_PARAMETERS,
    PARAMETERS,
    TARGETS,
    UNITS,
    FitSettings,
    ParameterBounds,
    band_grid,
    parse_fit_settings,
)
from hcid.hcfit.closed_loop import closed_loop_u, loop_is_stable
from hcid.hcfit.estimators import fit_parametric, resolve_target
from hcid.hcfit.fit import (
    BOUND_TOLERANCE,
    HCFit,
    fit_closed_loop,
    fit_frequency,
    fit_lines,
    fit_time,
)
from hcid.hcfit.model import TrackingRecord, hc_response, simulate_hc

__all__ = [
    "BOUND_TOLERANCE",
    "DEFAULT_BOUNDS",
    "FEEDBACK_PARAMETERS",
    "FEEDFORWARD_PARAMETERS",
    "PARAMETERS",
    "TARGETS",
    "UNITS",
    "FitSettings",
    "HCFit",
    "ParameterBounds",
    "TrackingRecord",
    "band_grid",
    "closed_loop_u",
    "fit_closed_loop",
    "fit_frequency",
    "fit_parametric",
    "fit_lines",
    "fit_time",
    "hc_response",
    "loop_is_stable",
    "parse_fit_settings",
    "resolve_target",
    "simulate_hc",
]
