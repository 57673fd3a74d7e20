"""Fitting the parametric HC model: the frequency, time, closed-loop and lines targets, the
optimiser and the estimates' standard errors (which target a fit takes:
:mod:`hcid.hcfit.estimators`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import control
import numpy as np
import pyarrow as pa
from scipy import optimize

from hcid.config.fit_settings import UNITS, FitSettings
from hcid.errors import DataError, IdentificationError
from hcid.hcfit.determined import parameter_status
from hcid.hcfit.lines import LineData, LinesProblem, line_data
from hcid.hcfit.model import TrackingRecord, simulate_hc
from hcid.hcfit.problems import ClosedLoopProblem, Fixed, FrequencyProblem, TimeProblem
from hcid.hcfit.uncertainty import Z95, covariance, jacobian, strongest_correlations

__all__ = [
    "BOUND_TOLERANCE",
    "HCFit",
    "fit_closed_loop",
    "fit_frequency",
    "fit_lines",
    "fit_time",
]

#: A parameter is flagged ``at_bound`` when it lies within this share of its
#: bound width of a bound (the local stage lands within ~1e-9 of an active one).
BOUND_TOLERANCE = 1e-4


@dataclass(frozen=True)
class HCFit:
    """The fitted parametric HC model.

    Attributes
    ----------
    target : str
        The estimator fitted: ``lines``, ``time``, ``closed_loop`` or ``frequency`` (``auto``
        resolved).
    names : tuple of str
        Fitted parameters: :data:`FEEDBACK_PARAMETERS`, then
        :data:`FEEDFORWARD_PARAMETERS` if the model has a feedforward path.
    estimates : tuple of float
        Estimates in the units of :data:`UNITS`.
    at_bound : tuple of bool
        Whether each estimate lies on a bound (within :data:`BOUND_TOLERANCE`
        of the bound width): the optimum may lie outside the bounds.
    cost : float
        Frequency target: ``sum |H_arx - H_par|^2 / |H_arx|^2`` over the grid
        and both paths (-); time target: ``sum (u - u_par)^2`` over the
        estimation rows (rad^2).
    starts : int
        Local fits run (the global-stage result plus the random starts).
    start_costs : tuple of float
        Cost reached from each start, the global-stage start first.
    vaf_validation : float
        ``(1 - sum (u - u_par)^2 / sum u^2) * 100`` (%) over the validation
        rows; NaN when no record was given to a frequency fit.
    se : tuple of float
        Standard error of each estimate, in its unit (:mod:`hcid.hcfit.uncertainty`);
        NaN for a parameter on a bound and for the frequency target, inf for one the
        record does not determine. Not compared by ``==`` (NaN is not equal to itself).
    covariance : str
        How ``se`` was computed: ``sandwich`` (lag window of ``lag`` samples),
        ``gauss_newton``, or ``none`` (the frequency target).
    lag : int
        The sandwich's lag window (samples; 0 for Gauss-Newton).
    fixed : tuple of str
        Parameters held at a stated value, not estimated (their se is NaN).
    partner : tuple of str
        Per parameter, the other free parameter its estimate is most correlated with
        ("" when none or no covariance).
    correlation : tuple of float
        That correlation (NaN without a covariance).
    """

    target: str
    names: tuple[str, ...]
    estimates: tuple[float, ...]
    at_bound: tuple[bool, ...]
    cost: float
    starts: int
    start_costs: tuple[float, ...]
    vaf_validation: float
    se: tuple[float, ...] = field(default=(), compare=False)
    covariance: str = "gauss_newton"
    lag: int = 0
    fixed: tuple[str, ...] = ()
    partner: tuple[str, ...] = field(default=(), compare=False)
    correlation: tuple[float, ...] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        if not self.se:
            object.__setattr__(self, "se", tuple(math.nan for _ in self.names))
        if not self.partner:
            object.__setattr__(self, "partner", tuple("" for _ in self.names))
            object.__setattr__(self, "correlation", tuple(math.nan for _ in self.names))

    def interval(self, name: str) -> tuple[float, float]:
        """The 95% interval ``estimate +- 1.96 se`` of parameter ``name`` (NaN without an se)."""
        i = self.names.index(name)
        return self.estimates[i] - Z95 * self.se[i], self.estimates[i] + Z95 * self.se[i]

    @property
    def values(self) -> dict[str, float]:
        """``{parameter: estimate}``, for :func:`hc_response` and :func:`simulate_hc`."""
        return dict(zip(self.names, self.estimates, strict=True))

    @property
    def has_feedforward(self) -> bool:
        return "Kpt" in self.names

    @property
    def status(self) -> dict[str, str]:
        """``{parameter: status}``: ``determined``, or why the data do not determine it (on a
        search bound, its 95% interval wider than its plausible range, correlated with another,
        held fixed, ...) or why it is flagged; what ``hcid analyse`` writes as ``<name>_status``
        (:func:`hcid.hcfit.determined.parameter_status`)."""
        return parameter_status(self)

    def rows(self) -> list[dict[str, Any]]:
        """One dict per parameter: parameter, estimate, se, ci_low, ci_high, unit, at_bound,
        cost, vaf_validation, target, covariance, starts."""
        return [
            {
                "parameter": name,
                "estimate": value,
                "se": se,
                "ci_low": self.interval(name)[0],
                "ci_high": self.interval(name)[1],
                "unit": UNITS[name],
                "at_bound": hit,
                "cost": self.cost,
                "vaf_validation": self.vaf_validation,
                "target": self.target,
                "covariance": self.covariance,
                "starts": self.starts,
            }
            for name, value, se, hit in zip(self.names, self.estimates, self.se, self.at_bound, strict=True)
        ]

    def to_arrow(self) -> pa.Table:
        """:meth:`rows` as a table, one row per parameter."""
        return pa.Table.from_pylist(self.rows())


# --------------------------------------------------------------------------- problems


def _uncertainty(problem, x, lower, upper, at_bound, kind: str, lag_seconds: float, rate: float):
    """``(se, kind, lag, partner, correlation)`` at the optimum ``x`` (:mod:`hcid.hcfit.uncertainty`).

    ``kind`` ``none`` gives no standard errors (the frequency target: its residuals are the
    ARX model's approximation error on a chosen grid, not noise, and a covariance from them
    shrinks with the grid's size).
    """
    nan = tuple(math.nan for _ in x)
    if kind == "none":
        return nan, "none", 0, tuple("" for _ in x), nan
    free = ~np.asarray(at_bound)
    r = problem.residuals(x)
    jac = jacobian(problem.residuals, x, lower, upper, free)
    lag = round(lag_seconds * rate) if kind == "sandwich" else 0
    cov = covariance(kind, jac, r, lag)
    with np.errstate(invalid="ignore"):
        se_free = np.sqrt(np.diag(cov))
    se = np.full(x.size, np.nan)
    se[free] = se_free
    partner, correlation = strongest_correlations(cov, np.asarray(problem.names)[free], x.size, free)
    return tuple(float(v) for v in se), kind, lag, partner, correlation


#: How each target's standard errors are computed: the time-domain targets by the settings'
#: covariance (residuals correlated over time); the ``lines`` target by Gauss-Newton (its
#: residuals are independent DFT bins, each scaled by its remnant's variance); none for the
#: ``frequency`` target (above).
def _covariance_kind(target: str, settings: FitSettings) -> str:
    return {"frequency": "none", "lines": "gauss_newton"}.get(target, settings.covariance)


def _optimum(
    problem, settings: FitSettings, lower, upper, start_box
) -> tuple[float, np.ndarray, list[float]]:
    """The least cost over a global stage (differential evolution over the starting box) and
    ``settings.starts`` random starts, each polished by bounded least squares: ``(cost, x, the
    cost reached from every start, the global stage's first)``."""
    glob = optimize.differential_evolution(
        # Clipped, so a widened zero-width start never leaves the bounds.
        lambda thetas: problem.costs(np.clip(thetas, lower[:, None], upper[:, None])),
        start_box,
        popsize=settings.popsize,
        maxiter=settings.maxiter,
        tol=1e-8,
        seed=np.random.default_rng(settings.seed),
        polish=False,
        updating="deferred",
        vectorized=True,
    )
    rng = np.random.default_rng([settings.seed, 1])
    randoms = rng.uniform(
        [lo for lo, _ in start_box], [hi for _, hi in start_box], (settings.starts, len(start_box))
    )
    best = None
    costs = []
    for x0 in [glob.x, *randoms]:
        x0 = np.clip(x0, lower, upper)
        fit = optimize.least_squares(
            problem.residuals,
            x0,
            bounds=(lower, upper),
            method="trf",
            x_scale="jac",
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=400,
        )
        cost = float(np.sum(fit.fun**2))
        costs.append(cost)
        if best is None or cost < best[0]:
            best = (cost, fit.x)
    return best[0], best[1], costs


def _validation_vaf(values: dict, plant, record: TrackingRecord, oversample: int) -> float:
    """``(1 - sum (u - u_par)^2 / sum u^2) * 100`` (%) over the record's validation rows."""
    u_par = simulate_hc(values, plant, record, oversample)
    u = record.u[record.validation]
    return float((1.0 - np.sum((u - u_par[record.validation]) ** 2) / np.sum(u**2)) * 100.0)


def _solve(
    problem, settings: FitSettings, target: str, record: TrackingRecord | None, fixed: dict | None = None
) -> HCFit:
    full_names = problem.names
    fixed = {n: float(v) for n, v in (fixed or {}).items() if n in full_names}
    if fixed:
        problem = Fixed(problem, fixed)
    bounds = [settings.bound(n) for n in problem.names]
    lower = np.array([b.lower for b in bounds])
    upper = np.array([b.upper for b in bounds])
    start_box = [(b.start_lower, b.start_upper) for b in bounds]
    # A zero-width starting range is a fixed start: widen it by a hair for DE.
    start_box = [(lo, hi if hi > lo else lo + 1e-12 * max(1.0, abs(lo))) for lo, hi in start_box]
    cost, x, costs = _optimum(problem, settings, lower, upper, start_box)
    width = upper - lower
    at_bound = tuple(
        bool(v - lo <= BOUND_TOLERANCE * w or hi - v <= BOUND_TOLERANCE * w)
        for v, lo, hi, w in zip(x, lower, upper, width, strict=True)
    )
    kind = _covariance_kind(target, settings)
    rate = record.rate if record is not None else 1.0
    se, kind, lag, partner, correlation = _uncertainty(
        problem, x, lower, upper, at_bound, kind, settings.lag, rate
    )
    free = dict(zip(problem.names, (float(v) for v in x), strict=True))
    values = {n: fixed.get(n, free.get(n)) for n in full_names}
    vaf = math.nan if record is None else _validation_vaf(values, problem.plant, record, settings.oversample)

    def spread(per_free, default):
        got = dict(zip(problem.names, per_free, strict=True))
        return tuple(got.get(n, default) for n in full_names)

    return HCFit(
        target=target,
        names=full_names,
        estimates=tuple(values.values()),
        at_bound=spread(at_bound, False),
        cost=cost,
        starts=len(costs),
        start_costs=tuple(costs),
        vaf_validation=vaf,
        se=spread(se, math.nan),
        covariance=kind,
        lag=lag,
        fixed=tuple(n for n in full_names if n in fixed),
        partner=spread(partner, ""),
        correlation=spread(correlation, math.nan),
    )


# --------------------------------------------------------------------------- public fits


def _response(name: str, value: Any, n: int | None) -> np.ndarray:
    h = np.asarray(value, dtype=complex)
    if h.ndim != 1 or (n is not None and h.size != n):
        raise DataError(
            f"{name}: must be a 1-D array of complex responses, one per omega, got shape {h.shape}"
        )
    if not np.all(np.isfinite(h)) or np.any(h == 0):
        raise DataError(f"{name}: must be finite and nonzero at every frequency (the cost divides by |H|)")
    return h


def fit_frequency(
    omega: np.ndarray,
    he: np.ndarray,
    hft: np.ndarray | None,
    plant: control.TransferFunction,
    settings: FitSettings = FitSettings(),  # noqa: B008 (frozen)
    record: TrackingRecord | None = None,
    fixed: dict[str, float] | None = None,
) -> HCFit:
    """Fit the parametric paths to the ARX paths' frequency responses.

    Minimises ``sum_w |H_arx - H_par|^2 / |H_arx|^2`` over ``omega`` and both
    paths (real and imaginary parts as the least-squares residuals).

    Parameters
    ----------
    omega : ndarray, shape (n,)
        Frequencies (rad/s), normally ``band_grid(settings.band, settings.points)``.
    he : ndarray of complex, shape (n,)
        ARX feedback path, u per e (SPEC 5).
    hft : ndarray of complex, shape (n,), or None
        ARX feedforward path with the target shift undone (SPEC 5); None when
        the selected model has no feedforward (``nb_ft = 0``): the
        feedforward parameters are then not fitted.
    plant : control.TransferFunction
        ``Yc`` (:func:`hcid.loop.hcmodel.plant`).
    settings : FitSettings
        Bounds, starts, seed and global-stage size (``target`` is not read).
    record : TrackingRecord, optional
        Measured ft, e, u for the validation VAF; without it the VAF is NaN.
    fixed : mapping of str to float, optional
        Parameters held at these values, not fitted.

    Returns
    -------
    HCFit

    Raises
    ------
    hcid.errors.DataError
        If omega is not positive and finite or a response is not finite and nonzero.
    hcid.errors.ConfigError
        If the plant is not a proper SISO continuous transfer function.
    """
    omega = np.asarray(omega, dtype=np.float64)
    if omega.ndim != 1 or omega.size < 2 or not np.all(np.isfinite(omega)) or np.any(omega <= 0):
        raise DataError(
            f"omega: must be a 1-D array of positive frequencies (rad/s), got shape {omega.shape}"
        )
    he = _response("he", he, omega.size)
    hft = None if hft is None else _response("hft", hft, omega.size)
    problem = FrequencyProblem(omega, he, hft, plant)
    return _solve(problem, settings, "frequency", record, fixed)


def fit_time(
    record: TrackingRecord,
    plant: control.TransferFunction,
    feedforward: bool,
    settings: FitSettings = FitSettings(),  # noqa: B008 (frozen)
    fixed: dict[str, float] | None = None,
) -> HCFit:
    """Fit the parametric model to the measured u over the estimation rows.

    Minimises ``sum (u - u_par)^2`` over ``record.estimation``, with u_par from
    :func:`simulate_hc` at ``settings.oversample``.

    Parameters
    ----------
    record : TrackingRecord
        Measured ft (unshifted), e, u (rad) at ``record.rate`` (Hz), with the
        estimation and validation rows.
    plant : control.TransferFunction
        ``Yc``.
    feedforward : bool
        Whether the selected model has a feedforward path (``nb_ft > 0``).
    settings : FitSettings
        ``target`` is not read.
    fixed : mapping of str to float, optional
        Parameters held at these values, not fitted.

    Returns
    -------
    HCFit
    """
    if not isinstance(record, TrackingRecord):
        raise IdentificationError(f"record: must be a TrackingRecord, got {type(record).__name__}")
    problem = TimeProblem(record, plant, settings, bool(feedforward))
    return _solve(problem, settings, "time", record, fixed)


def fit_closed_loop(
    record: TrackingRecord,
    plant: control.TransferFunction,
    feedforward: bool,
    settings: FitSettings = FitSettings(),  # noqa: B008 (frozen)
    disturbance_at: str = "output",
    fixed: dict[str, float] | None = None,
) -> HCFit:
    """Fit the parametric model in closed loop with the plant to the measured u.

    Minimises ``sum (u - u_cl)^2`` over ``record.estimation``, with ``u_cl`` the
    loop's output driven by the record's ft and fd (:func:`closed_loop_u`):
    the remnant cannot reach these inputs, so it adds spread but no bias.

    Parameters
    ----------
    record : TrackingRecord
        Measured ft (unshifted), fd, u (rad) at ``record.rate`` (Hz), with the
        estimation and validation rows; ``record.fd`` must be given.
    plant : control.TransferFunction
        ``Yc``.
    feedforward : bool
        Whether the selected model has a feedforward path (``nb_ft > 0``).
    settings : FitSettings
        ``target`` is not read.
    disturbance_at : str
        Where fd enters the loop: ``output`` (the paper) or ``input`` (SPEC 7).
    fixed : mapping of str to float, optional
        Parameters held at these values, not fitted.

    Returns
    -------
    HCFit
    """
    if not isinstance(record, TrackingRecord):
        raise IdentificationError(f"record: must be a TrackingRecord, got {type(record).__name__}")
    # _ClosedLoop refuses a record without fd and an unknown disturbance point.
    problem = ClosedLoopProblem(record, plant, bool(feedforward), disturbance_at)
    return _solve(problem, settings, "closed_loop", record, fixed)


def fit_lines(
    record: TrackingRecord,
    plant: control.TransferFunction,
    feedforward: bool,
    settings: FitSettings = FitSettings(),  # noqa: B008 (frozen)
    disturbance_at: str = "output",
    fixed: dict[str, float] | None = None,
    data: LineData | None = None,
) -> HCFit:
    """Fit the parametric model in closed loop to the record's u at its forcing lines.

    Minimises ``sum_k |U_k - U_cl,k|^2 / sigma_k^2`` over the forcing lines k of the whole
    record (:mod:`hcid.hcfit.lines`): ``U_cl`` the loop's u driven by the recorded ft and fd,
    ``sigma_k^2`` the remnant's variance in u beside line k. Standard errors by Gauss-Newton
    (the bins are independent). The record must be a whole number of its forcing functions'
    periods (multisines on disjoint lines).

    Parameters
    ----------
    record : TrackingRecord
        ft (unshifted), fd, e, u (rad) at ``record.rate`` (Hz); the validation rows give the VAF.
    plant : control.TransferFunction
        ``Yc``.
    feedforward : bool
        Whether to fit the feedforward path.
    settings : FitSettings
        ``target`` is not read.
    disturbance_at : str
        ``output`` or ``input`` (SPEC 7).
    fixed : mapping of str to float, optional
        Parameters held at these values (e.g. :data:`hcid.hcfit.determined.LITERATURE_NMS`).
    data : LineData, optional
        The record at its lines, where already read (:func:`hcid.hcfit.lines.line_data`).

    Raises
    ------
    hcid.errors.DataError
        If the record's forcing functions have no lines (the reason named).
    """
    if not isinstance(record, TrackingRecord):
        raise IdentificationError(f"record: must be a TrackingRecord, got {type(record).__name__}")
    if disturbance_at not in ("output", "input"):
        raise IdentificationError(f"disturbance_at: must be output or input, got {disturbance_at!r}")
    data = line_data(record) if data is None else data
    problem = LinesProblem(data, plant, bool(feedforward), disturbance_at)
    return _solve(problem, settings, "lines", record, fixed)
