"""Analyses of one selected ARX model: its parametric HC fit and its residuals.

Given a record, the model a method selected at some W (its orders and
coefficients, from ``frontier.parquet``) and the earlier stages' choices, this
module fits the parametric HC model of SPEC sections 1, 7 and 8
(:mod:`hcid.hcfit`) and analyses the selected model's simulation residual
(:mod:`hcid.analysis.residuals`). Pure: arrays and dataclasses in, dataclasses out.

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

import control
import numpy as np
import pyarrow as pa

from hcid import hcfit
from hcid.analysis.descriptors import RemnantFit, fit_remnant, loop_margins, variance_shares
from hcid.analysis.residuals import ResidualAnalysis, analyse_residuals
from hcid.arx.response import path_response
from hcid.arx.simulation import simulate
from hcid.config import Config, StageConfig, Window
from hcid.errors import IdentificationError
from hcid.loop.hcmodel import plant, true_response
from hcid.methods import Method, StageChoice, shift_forward
from hcid.selection.frontier import Frontier
from hcid.tables import ORDER_COLUMNS

__all__ = [
    "fit_selected",
    "LoopDescription",
    "RESIDUAL_CONFIDENCE",
    "RESIDUAL_MAX_LAG",
    "SelectedAnalysis",
    "SelectedModel",
    "analyse_selected",
    "describe_loop",
    "true_loop",
    "true_parameters",
]

#: Largest residual-correlation lag (s): 1 s, the target shift, 25 samples at 25 Hz.
RESIDUAL_MAX_LAG = 1.0
#: Confidence of the white-residual band (the issue's 99%, MATLAB resid's default).
RESIDUAL_CONFIDENCE = 0.99


@dataclass(frozen=True)
class SelectedModel:
    """The ARX model a method selected at ``w`` (SPEC 3): ``A u = B_ft ft_s + B_e e``.

    Attributes
    ----------
    w : float
        The penalty W it was selected at (``MSC = log V + W d``).
    na, nb_ft, nb_e : int
        Orders; ``nb_ft = 0`` means no feedforward path, ``nb_e = 0`` no feedback path.
    nk_ft, nk_e : int
        Delays (samples at ``rate``) of the shifted target ``ft_s`` and of e
        (``nk_ft`` counts from ``ft_s``: the delay from ft is ``nk_ft`` minus the shift).
    v : float
        Mean squared simulation error over the validation rows (rad^2).
    vaf_validation : float
        Variance accounted for (percent) over the validation rows.
    a : ndarray, shape (na + 1,)
        ``[1, a1, ..., a_na]``.
    b_ft, b_e : ndarray, shape (nb_ft,), (nb_e,)
        ``[b_0, ...]``; empty for a dropped input.
    method : str
        The method that selected it (:data:`hcid.methods.METHODS`).
    rate : float
        Sample rate (Hz) of the record it was identified on.
    target_shift : float
        Time (s) ft was shifted forward before the fit (SPEC 3: 1 s);
        :meth:`frequency_response` undoes it.
    estimation, validation : Window
        The final stage's windows (1-based inclusive samples of the record).
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
    method: str
    rate: float
    target_shift: float
    estimation: Window
    validation: Window

    @property
    def orders(self) -> tuple[int, int, int, int, int]:
        """``(na, nb_ft, nb_e, nk_ft, nk_e)``."""
        return (self.na, self.nb_ft, self.nb_e, self.nk_ft, self.nk_e)

    @property
    def has_feedforward(self) -> bool:
        return self.nb_ft > 0

    @classmethod
    def from_frontier(
        cls, frontier: Frontier, row: int, w: float, *, rate: float, target_shift: float, stage: StageConfig
    ) -> SelectedModel:
        """Row ``row`` of a frontier as the model selected at ``w``."""
        return cls(
            w=float(w),
            **{c: int(getattr(frontier, c)[row]) for c in ORDER_COLUMNS},
            v=float(frontier.v[row]),
            vaf_validation=float(frontier.vaf_validation[row]),
            **frontier.row_coefficients(row),
            method=frontier.method,
            rate=float(rate),
            target_shift=float(target_shift),
            estimation=stage.estimation,
            validation=stage.validation,
        )

    def frequency_response(self, omega: np.ndarray) -> dict[str, np.ndarray]:
        """Complex frequency response of both paths at ``omega`` (rad/s), the target shift undone.

        Returns
        -------
        dict
            ``{"ft": Hft, "e": He}``, each complex of the shape of ``omega``: u per ft
            (SPEC 5: ``exp(jw shift) z^-nk_ft B_ft / A``) and u per e; zeros for a dropped path.

        Raises
        ------
        IdentificationError
            For an ``omega`` that is not finite and >= 0.
        """
        omega = np.asarray(omega, dtype=np.float64)
        bad = ~(np.isfinite(omega) & (omega >= 0))
        if bad.any():
            raise IdentificationError(
                f"omega: must be finite frequencies >= 0 (rad/s), got {float(omega[bad].flat[0])}"
            )
        dt = 1.0 / self.rate
        return {
            "ft": path_response(self.a, self.b_ft, self.nk_ft, omega, dt, advance=self.target_shift),
            "e": path_response(self.a, self.b_e, self.nk_e, omega, dt),
        }

    def simulate(self, ft: np.ndarray, e: np.ndarray) -> np.ndarray:
        """u simulated from rest from the unshifted target ``ft`` and the error ``e`` (rad).

        ``ft`` is shifted forward by the target shift (zeros after the record's
        end, :func:`hcid.methods.shift_forward`); the result has the length of ``ft``.
        """
        ft = np.ascontiguousarray(ft, dtype=np.float64)
        e = np.ascontiguousarray(e, dtype=np.float64)
        ft_s = shift_forward(ft, round(self.target_shift * self.rate))
        return simulate(self.a, self.b_ft, self.b_e, self.nk_ft, self.nk_e, ft_s, e)

    def to_arrow(self) -> pa.Table:
        """One row: W, orders, V, VAF, coefficients (list columns), method, rate and target shift."""
        row = {
            "w": self.w,
            **dict(zip(ORDER_COLUMNS, self.orders, strict=True)),
            "v": self.v,
            "vaf_validation": self.vaf_validation,
            "a": self.a.tolist(),
            "b_ft": self.b_ft.tolist(),
            "b_e": self.b_e.tolist(),
            "method": self.method,
            "rate": self.rate,
            "target_shift": self.target_shift,
        }
        return pa.Table.from_pylist([row])


@dataclass(frozen=True)
class SelectedAnalysis:
    """The fit (None when not fitted: a frequency fit of a model without feedback path)
    and the residual analysis of one selected model."""

    model: SelectedModel
    fit: hcfit.HCFit | None
    residuals: ResidualAnalysis
    loop: tuple[LoopDescription, ...] = ()


@dataclass(frozen=True)
class LoopDescription:
    """The loop a model of the person implies on one record (SPEC 8's descriptors).

    Attributes
    ----------
    source : str
        ``arx`` (the selected ARX model's paths) or ``fitted`` (the parametric fit's).
    crossover : float
        Gain-crossover frequency of ``He Yc`` (rad/s); NaN without a crossing.
    phase_margin : float
        ``180 + arg(He Yc)`` at the crossover (deg).
    n_crossovers : int
        Crossings of ``|He Yc| = 1`` found (the one of smallest margin is reported).
    shares : dict of str to float
        ``ft``, ``e`` and ``remnant``: the variance of u through each path, and of
        what the paths leave (``n = u - u_ft - u_e``), over ``var(u)``.
    remnant : RemnantFit or None
        SPEC 1's remnant filter fitted to the spectrum of ``n``.
    """

    source: str
    crossover: float
    phase_margin: float
    n_crossovers: int
    shares: dict[str, float]
    remnant: RemnantFit | None


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


def true_loop(config: Config, model_name: str) -> tuple[float, float]:
    """Crossover (rad/s) and phase margin (deg) of a simulated model's true loop ``He Yc`` (SPEC 1)."""
    model = config.model(model_name)
    yc = plant(config.loop)
    margins = loop_margins(lambda w: true_response(model, config.loop, w)[1] * yc(1j * w))
    return margins.crossover, margins.phase_margin


def _span(selected: SelectedModel) -> slice:
    """The rows of the loop's descriptors: the final stage's estimation start to its windows' end."""
    est, val = selected.estimation.rows(), selected.validation.rows()
    return slice(min(est.start, val.start), max(est.stop, val.stop))


def describe_loop(
    selected: SelectedModel,
    fit: hcfit.HCFit | None,
    record: Mapping[str, np.ndarray],
    yc: control.TransferFunction,
    kn_rate: float,
    oversample: int = 4,
) -> tuple[LoopDescription, ...]:
    """The loop's descriptors from the selected ARX model and, when fitted, the parametric model.

    Over the rows from the final stage's estimation start to its windows' end:
    u split into the target path's part, the error path's part (each simulated
    from rest from the measured ft and e) and the rest, the remnant, whose
    spectrum is fitted with SPEC 1's filter (``kn`` for unit white noise at
    ``kn_rate`` Hz). Crossover and phase margin of ``He Yc``: the ARX model's up to
    its Nyquist frequency, the parametric model's (with its continuous delay)
    up to 1000 rad/s, simulated at ``oversample`` times the record's rate (the fit's).
    """
    rate = selected.rate
    rows = _span(selected)
    ft, e, u = (np.asarray(record[k], dtype=np.float64) for k in ("ft", "e", "u"))
    zeros = np.zeros_like(ft)

    def describe(source, he_of_w, band, parts) -> LoopDescription:
        """The loop of ``He = he_of_w`` with the plant, u's split into ``parts`` and the remnant."""
        margins = loop_margins(lambda w: he_of_w(w) * yc(1j * w), band)
        shares = variance_shares(u[rows], {k: x[rows] for k, x in parts.items()})
        n = u[rows] - sum(x[rows] for x in parts.values())
        try:
            remnant = fit_remnant(n, rate, kn_rate) if np.ptp(n) > 0 else None
        except IdentificationError:  # too few spectral lines in the band
            remnant = None
        return LoopDescription(
            source, margins.crossover, margins.phase_margin, margins.n_crossovers, shares, remnant
        )

    arx = describe(
        "arx",
        lambda w: selected.frequency_response(w)["e"],
        (1e-2, 0.999 * np.pi * rate),
        {"ft": selected.simulate(ft, zeros), "e": selected.simulate(zeros, e)},
    )
    if fit is None:
        return (arx,)
    tracking = hcfit.TrackingRecord(ft, e, u, rate, rows, rows)
    values = fit.values
    feedback = {k: values[k] for k in hcfit.FEEDBACK_PARAMETERS}
    u_e = hcfit.simulate_hc(feedback, yc, tracking, oversample)
    parts = {"ft": hcfit.simulate_hc(values, yc, tracking, oversample) - u_e, "e": u_e}
    fitted = describe("fitted", lambda w: hcfit.hc_response(values, yc, w)[1], (1e-2, 1e3), parts)
    return arx, fitted


def fit_selected(
    selected: SelectedModel,
    record: Mapping[str, np.ndarray],
    yc: control.TransferFunction,
    settings: hcfit.FitSettings,
    disturbance_at: str = "output",
) -> hcfit.HCFit | None:
    """Fit the parametric HC model (SPEC 8) to a selected model and its record.

    The ``frequency`` target fits both paths of ``selected`` (target shift undone)
    on the log grid of ``settings.band``; the ``time`` target fits the record's u
    from its unshifted ft and e over ``selected``'s estimation window; the
    ``closed_loop`` target fits u of the model in closed loop with ``yc``
    (disturbance at the plant's ``disturbance_at``), driven by the record's ft and
    fd, over the same window. The feedforward parameters are fitted exactly
    when ``selected.nb_ft > 0``.

    Returns
    -------
    HCFit or None
        None for a frequency fit of a model without feedback path (``nb_e = 0``).
    """
    tracking = hcfit.TrackingRecord(
        record["ft"],
        record["e"],
        record["u"],
        selected.rate,
        selected.estimation.rows(),
        selected.validation.rows(),
        fd=record["fd"],
    )
    if settings.target == "frequency" and selected.nb_e == 0:
        return None
    omega = hcfit.band_grid(settings.band, settings.points)
    paths = selected.frequency_response(omega)
    hft = paths["ft"] if selected.has_feedforward else None
    return hcfit.fit_parametric(
        settings,
        yc,
        selected.has_feedforward,
        record=tracking,
        omega=omega,
        he=paths["e"],
        hft=hft,
        disturbance_at=disturbance_at,
    )


def analyse_selected(
    selected: SelectedModel,
    record: Mapping[str, np.ndarray],
    config: Config,
    method: Method,
    choices: tuple[StageChoice, ...] = (),
    fit: hcfit.HCFit | None = None,
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
    fit : HCFit, optional
        What :func:`fit_selected` would return, already computed by the caller (``hcid
        analyse`` fits every run with and without feedforward before it selects): the
        ``time`` or ``closed_loop`` fit of this record over the selected model's windows,
        with feedforward exactly when it has some. Not checked beyond that.

    Returns
    -------
    SelectedAnalysis
    """
    rate = config.timing.output_rate
    validation = config.identify.stage(method.final_stage.name).validation.rows()
    if fit is None:
        fit = fit_selected(selected, record, plant(config.loop), config.fit_hc, config.loop.disturbance_at)
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
    loop = describe_loop(
        selected, fit, record, plant(config.loop), config.timing.sim_rate, config.fit_hc.oversample
    )
    return SelectedAnalysis(model=selected, fit=fit, residuals=residuals, loop=loop)
