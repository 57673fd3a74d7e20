"""Settings of the parametric HC fit: parameters, bounds, starting ranges, optimiser sizes.

:class:`FitSettings` is built from the config's ``fit_hc`` mapping by
:func:`parse_fit_settings`; errors name the dotted key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hcid.config._checks import Section, fmt, integer
from hcid.errors import ConfigError
from hcid.tables import PARAMETER_UNITS

__all__ = [
    "DEFAULT_BOUNDS",
    "FEEDBACK_PARAMETERS",
    "FEEDFORWARD_PARAMETERS",
    "PARAMETERS",
    "COVARIANCES",
    "NMS_CHOICES",
    "TARGETS",
    "UNITS",
    "FitSettings",
    "ParameterBounds",
    "band_grid",
    "parse_fit_settings",
]

FEEDBACK_PARAMETERS = ("Kpe", "TL", "tau_pe", "w_nms", "zeta_nms")
FEEDFORWARD_PARAMETERS = ("Kpt", "TI", "tau_pt")
PARAMETERS = FEEDBACK_PARAMETERS + FEEDFORWARD_PARAMETERS
UNITS = PARAMETER_UNITS  # one home: the tables' vocabulary (hcid.tables)
#: The estimators; ``auto`` is ``lines`` where the record's forcing functions are multisines on
#: disjoint lines over whole periods with at least one disturbance line per feedback parameter,
#: else ``time`` (docs/parametric-fit.md: how it was chosen).
TARGETS = ("auto", "lines", "time", "closed_loop", "frequency")
#: The neuromuscular pair: ``auto`` (fitted, and held at the literature values where the fit
#: leaves it undetermined), ``free`` (always fitted) or ``fixed`` (always held).
NMS_CHOICES = ("auto", "free", "fixed")
#: How the estimates' standard errors are computed (:mod:`hcid.hcfit.uncertainty`).
COVARIANCES = ("sandwich", "gauss_newton")

# Physical limits that no bound may cross: a negative feedback delay is not
# causal, and w_nms, zeta_nms and TI must be positive for the paths to be
# stable and of the stated order. (name: (lowest, strict))
_LIMITS = {
    "TL": (0.0, False),
    "tau_pe": (0.0, False),
    "w_nms": (0.0, True),
    "zeta_nms": (0.0, True),
    "TI": (0.0, True),
}


def _check_bounds(name: str, values: tuple, key: str, start_key: str) -> None:
    if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values):
        raise ConfigError(f"{key}: bounds and starting range must be finite numbers, got {list(values)}")
    lower, upper, start_lower, start_upper = values
    if lower > upper:
        raise ConfigError(f"{key}: lower {lower:g} above upper {upper:g}")
    if lower == upper:
        raise ConfigError(f"{key}: lower {lower:g} equals upper {upper:g} (parameters cannot be fixed)")
    if name in _LIMITS:
        lowest, strict = _LIMITS[name]
        if lower < lowest or (strict and lower == lowest):
            relation = ">" if strict else ">="
            raise ConfigError(f"{key}: lower must be {relation} {lowest:g} {UNITS[name]}, got {lower:g}")
    if start_lower > start_upper:
        raise ConfigError(f"{start_key}: lower {start_lower:g} above upper {start_upper:g}")
    if start_lower < lower or start_upper > upper:
        raise ConfigError(
            f"{start_key}: [{start_lower:g}, {start_upper:g}] outside the bounds [{lower:g}, {upper:g}]"
        )


@dataclass(frozen=True)
class ParameterBounds:
    """Bounds and starting range of one parameter, in its unit (:data:`UNITS`).

    The local stage keeps the parameter in ``[lower, upper]``; the global stage
    and the random starts draw it from ``[start_lower, start_upper]``, which
    must lie inside the bounds.

    Raises
    ------
    ConfigError
        If a value is not finite, ``lower >= upper``, the starting range is
        reversed or outside the bounds, or a bound crosses a physical limit.
    """

    name: str
    lower: float
    upper: float
    start_lower: float
    start_upper: float

    def __post_init__(self) -> None:
        _check_bounds(
            self.name,
            (self.lower, self.upper, self.start_lower, self.start_upper),
            f"bounds.{self.name}",
            f"start_ranges.{self.name}",
        )


# Defaults: wide enough for any human controller reported in manual-control
# studies (feedback gains and lead times for single/double-integrator plants,
# delays 0.1-0.4 s, NMS break 5-20 rad/s), starting ranges on typical values.
DEFAULT_BOUNDS = (
    ParameterBounds("Kpe", 0.01, 50.0, 0.1, 5.0),
    ParameterBounds("TL", 0.0, 5.0, 0.0, 2.0),
    ParameterBounds("tau_pe", 0.0, 1.0, 0.1, 0.5),
    ParameterBounds("w_nms", 2.0, 50.0, 5.0, 20.0),
    ParameterBounds("zeta_nms", 0.05, 2.0, 0.1, 1.0),
    ParameterBounds("Kpt", 0.0, 5.0, 0.1, 2.0),
    ParameterBounds("TI", 0.01, 2.0, 0.05, 1.0),
    ParameterBounds("tau_pt", -1.0, 1.0, -0.5, 0.8),
)


@dataclass(frozen=True)
class FitSettings:
    """How to fit the parametric HC model.

    Attributes
    ----------
    target : str
        ``auto`` (the default: ``lines`` where the forcing functions allow it, with at least 5
        disturbance lines, else ``time``; docs/parametric-fit.md), ``lines``, ``time``,
        ``closed_loop`` or ``frequency`` (:data:`TARGETS`).
    nms : str
        The neuromuscular pair: ``auto``, ``free`` or ``fixed`` (:data:`NMS_CHOICES`).
    starts : int
        Random local starts besides the global-stage result (>= 0).
    seed : int
        Seed of the global stage and of the random starts.
    band : tuple of float, or None
        ``(lo, hi)`` of the frequency target's log grid (rad/s). None until
        resolved: :func:`parse_fit_settings` fills in the config's disturbance
        band (:attr:`hcid.config.Config.disturbance_band`, SPEC 5) when the config
        gives none.
    points : int
        Points of that grid.
    oversample : int
        Time target: the paths are simulated at ``oversample`` times the
        record's rate (see :func:`simulate_hc`).
    popsize, maxiter : int
        ``scipy.optimize.differential_evolution`` population multiplier and
        generations of the global stage.
    covariance : str
        Standard errors of the time-domain targets: ``sandwich`` (default, a
        Bartlett lag window of ``lag`` seconds: right for coloured residuals)
        or ``gauss_newton`` (right for white ones only). The frequency target's
        are always Gauss-Newton.
    lag : float
        The sandwich's lag window (s).
    bounds : tuple of ParameterBounds
        One per parameter of :data:`PARAMETERS`, in that order.
    """

    target: str = "auto"
    starts: int = 4
    seed: int = 0
    band: tuple[float, float] | None = None
    points: int = 50
    oversample: int = 4
    popsize: int = 8
    maxiter: int = 30
    bounds: tuple[ParameterBounds, ...] = field(default=DEFAULT_BOUNDS)
    covariance: str = "sandwich"
    lag: float = 2.0
    nms: str = "auto"

    def __post_init__(self) -> None:
        if self.target not in TARGETS:
            raise ConfigError(f"target: must be one of {', '.join(TARGETS)}, got {fmt(self.target)}")
        if self.nms not in NMS_CHOICES:
            raise ConfigError(f"nms: must be one of {', '.join(NMS_CHOICES)}, got {fmt(self.nms)}")
        integer(self.starts, "starts", 0, 100)
        integer(self.seed, "seed", 0, 2**32 - 1)
        integer(self.points, "points", 4, 10_000)
        integer(self.oversample, "oversample", 1, 64)
        integer(self.popsize, "popsize", 2, 200)
        integer(self.maxiter, "maxiter", 1, 10_000)
        if self.covariance not in COVARIANCES:
            raise ConfigError(
                f"covariance: must be one of {', '.join(COVARIANCES)}, got {fmt(self.covariance)}"
            )
        _lag_check(self.lag, "lag")
        if self.band is not None:
            lo, hi = self.band
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
                raise ConfigError(f"band: must be [lo, hi] rad/s with 0 < lo < hi, got {list(self.band)}")
        names = tuple(b.name for b in self.bounds)
        if names != PARAMETERS:
            raise ConfigError(f"bounds: must be one per parameter in the order {PARAMETERS}, got {names}")

    def bound(self, name: str) -> ParameterBounds:
        """The bounds of parameter ``name``."""
        return self.bounds[PARAMETERS.index(name)]


def _lag_check(value, key: str) -> None:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or not 0 <= value <= 60:
        raise ConfigError(f"{key}: must be a number of seconds in [0, 60], got {fmt(value)}")


def _pair(section: Section, name: str, default: tuple[float, float] | None) -> tuple[float, float] | None:
    value = section.get(name, None)
    if value is None:
        return default
    ok = (
        isinstance(value, list | tuple)
        and len(value) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    )
    if not ok:
        raise ConfigError(f"{section.key(name)}: must be two finite numbers [lower, upper], got {fmt(value)}")
    return float(value[0]), float(value[1])


def parse_fit_settings(
    data: dict | None, path: str = "fit_hc", *, default_band: tuple[float, float] | None = None
) -> FitSettings:
    """Build :class:`FitSettings` from a parsed YAML mapping.

    Parameters
    ----------
    data : dict or None
        E.g. ``{target: frequency, starts: 4, seed: 0, band: [0.23, 17.33],
        points: 50, oversample: 4, popsize: 8, maxiter: 30, covariance: sandwich, lag: 2.0, nms: auto,
        bounds: {Kpe: [0.01, 50], ...}, start_ranges: {Kpe: [0.1, 5], ...}}``;
        every key optional, None gives the defaults. A parameter given bounds
        but no starting range starts from its default range clipped to the new
        bounds (the whole bounds if the two do not overlap).
    path : str
        Dotted key of the mapping, prefixed to error messages.
    default_band : tuple of float, optional
        The band (rad/s) when ``data`` gives none: the config's disturbance
        band (:attr:`hcid.config.Config.disturbance_band`).

    Raises
    ------
    ConfigError
        On an unknown key or parameter, a wrong type, lower above upper, or a
        starting range outside the bounds, naming the dotted key, e.g.
        ``fit_hc.bounds.TL: lower 2 above upper 1``.
    """
    s = Section({} if data is None else data, path)
    defaults = FitSettings()
    target = s.get("target", defaults.target)
    if target not in TARGETS:
        raise ConfigError(f"{s.key('target')}: must be one of {', '.join(TARGETS)}, got {fmt(target)}")
    starts = s.integer("starts", 0, 100, defaults.starts)
    seed = s.integer("seed", 0, 2**32 - 1, defaults.seed)
    points = s.integer("points", 4, 10_000, defaults.points)
    oversample = s.integer("oversample", 1, 64, defaults.oversample)
    popsize = s.integer("popsize", 2, 200, defaults.popsize)
    maxiter = s.integer("maxiter", 1, 10_000, defaults.maxiter)
    covariance = s.get("covariance", defaults.covariance)
    if covariance not in COVARIANCES:
        raise ConfigError(
            f"{s.key('covariance')}: must be one of {', '.join(COVARIANCES)}, got {fmt(covariance)}"
        )
    lag = s.get("lag", defaults.lag)
    _lag_check(lag, s.key("lag"))
    nms = s.get("nms", defaults.nms)
    if nms not in NMS_CHOICES:
        raise ConfigError(f"{s.key('nms')}: must be one of {', '.join(NMS_CHOICES)}, got {fmt(nms)}")
    band = _pair(s, "band", default_band)
    if band is not None and not 0 < band[0] < band[1]:
        raise ConfigError(f"{s.key('band')}: must be [lo, hi] rad/s with 0 < lo < hi, got {list(band)}")
    given_bounds = s.section("bounds", {})
    given_starts = s.section("start_ranges", {})
    bounds = []
    for default in DEFAULT_BOUNDS:
        name = default.name
        lower, upper = _pair(given_bounds, name, (default.lower, default.upper))
        start = _pair(given_starts, name, None)
        if start is None:
            start = (max(default.start_lower, lower), min(default.start_upper, upper))
            if start[0] > start[1]:
                start = (lower, upper)
        _check_bounds(name, (lower, upper, *start), given_bounds.key(name), given_starts.key(name))
        bounds.append(ParameterBounds(name, lower, upper, *start))
    given_bounds.done()
    given_starts.done()
    s.done()
    return FitSettings(
        target=target,
        starts=starts,
        seed=seed,
        band=band,
        points=points,
        oversample=oversample,
        popsize=popsize,
        maxiter=maxiter,
        bounds=tuple(bounds),
        covariance=covariance,
        lag=float(lag),
        nms=nms,
    )


def band_grid(band: tuple[float, float], points: int = 50) -> np.ndarray:
    """Log grid of ``points`` frequencies (rad/s) from ``band[0]`` to ``band[1]``, ends included.

    Examples
    --------
    >>> band_grid((0.1, 10.0), 3)
    array([ 0.1,  1. , 10. ])
    """
    if band is None:
        raise ConfigError("band: not resolved; give fit_hc.band or parse the settings with the config")
    return np.geomspace(band[0], band[1], points)
