"""The fitting problems of the parametric HC model's targets: each gives the residuals of one
parameter vector and the costs of a population of them (:func:`hcid.hcfit.fit._solve` minimises
them; the ``lines`` target's is :class:`hcid.hcfit.lines.LinesProblem`)."""

from __future__ import annotations

import numpy as np

from hcid.config.fit_settings import FitSettings
from hcid.hcfit.closed_loop import _ClosedLoop
from hcid.hcfit.model import TrackingRecord, _names, _plant_polynomials, _responses, _Simulator


class FrequencyProblem:
    def __init__(self, omega, he, hft, plant):
        _plant_polynomials(plant)
        self.plant = plant
        self.s = (1j * omega)[:, None]
        self.yc = np.asarray(plant(1j * omega), dtype=complex)[:, None]
        self.names = _names(hft is not None)
        self.he = he[:, None]
        self.hft = None if hft is None else hft[:, None]

    def _relative_errors(self, theta: np.ndarray) -> np.ndarray:
        hft, he = _responses(theta, self.names, self.s, self.yc)
        errors = [(he - self.he) / np.abs(self.he)]
        if hft is not None:
            errors.append((hft - self.hft) / np.abs(self.hft))
        return np.concatenate(errors)  # (n_paths * n_w, n_sets)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        r = self._relative_errors(x[:, None])[:, 0]
        return np.concatenate([r.real, r.imag])

    def costs(self, thetas: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            c = np.sum(np.abs(self._relative_errors(thetas)) ** 2, axis=0)
        return np.where(np.isfinite(c), c, np.inf)


class TimeProblem:
    def __init__(self, record: TrackingRecord, plant, settings: FitSettings, feedforward: bool):
        self.plant = plant
        self.names = _names(feedforward)
        delay_bounds = [settings.bound(name) for name in ("tau_pe", "tau_pt") if name in self.names]
        delays = (min(b.lower for b in delay_bounds), max(b.upper for b in delay_bounds))
        stop = record.estimation.stop  # the cost needs u_par up to the estimation rows' end only
        self.simulate = _Simulator(record, plant, settings.oversample, feedforward, delays, stop)
        self.u = record.u[record.estimation]
        self.rows = record.estimation

    def residuals(self, x: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            r = self.simulate(dict(zip(self.names, x, strict=True)))[self.rows] - self.u
        # An unstable trial (never at the bounds' interior optimum) gets a large finite cost.
        return np.where(np.isfinite(r), r, 1e6)

    def costs(self, thetas: np.ndarray) -> np.ndarray:
        return np.array([np.sum(self.residuals(thetas[:, i]) ** 2) for i in range(thetas.shape[1])])


class ClosedLoopProblem:
    def __init__(self, record: TrackingRecord, plant, feedforward: bool, disturbance_at: str):
        self.plant = plant
        self.loop = _ClosedLoop(record, plant, feedforward, disturbance_at)
        self.names = self.loop.names
        self.u = record.u[record.estimation][:, None]
        self.rows = record.estimation

    def _errors(self, thetas: np.ndarray) -> np.ndarray:
        return self.loop.u(thetas)[self.rows] - self.u

    def residuals(self, x: np.ndarray) -> np.ndarray:
        r = self._errors(x[:, None])[:, 0]
        # An unstable loop (never at the bounds' interior optimum) gets a large finite cost.
        return np.where(np.isfinite(r), r, 1e6)

    def costs(self, thetas: np.ndarray) -> np.ndarray:
        c = np.sum(self._errors(thetas) ** 2, axis=0)
        return np.where(np.isfinite(c), c, np.inf)


class Fixed:
    """A problem with some parameters held at given values: its ``names`` are the free ones."""

    def __init__(self, problem, fixed: dict[str, float]):
        self.inner = problem
        self.plant = problem.plant
        self.fixed = dict(fixed)
        self.names = tuple(n for n in problem.names if n not in fixed)
        self._free = np.array([problem.names.index(n) for n in self.names], dtype=np.int64)
        self._values = np.array([self.fixed.get(n, 0.0) for n in problem.names])

    def _full(self, thetas: np.ndarray) -> np.ndarray:
        full = np.repeat(self._values[:, None], thetas.shape[1], axis=1)
        full[self._free] = thetas
        return full

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.inner.residuals(self._full(x[:, None])[:, 0])

    def costs(self, thetas: np.ndarray) -> np.ndarray:
        return self.inner.costs(self._full(thetas))
