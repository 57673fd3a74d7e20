"""The human-controller model and its loop as transfer functions.

SPEC section 1. ``Ypt`` and ``Ype`` are improper alone, so the paths are built
as the proper products with the neuromuscular system, ``Hft = Ynms*Ypt`` and
``He = Ynms*Ype``, without their delays; the delays are whole samples at the
simulation rate and are applied separately (:class:`DiscreteLoop`).

The paths are formed and discretised as polynomial pairs by :mod:`hcid.loop._lti`
(python-control's arithmetic, the same bits, without its import cost); the public
functions return python-control transfer functions of those polynomials.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hcid.config import HCModel, Loop, Plant
from hcid.config.plant import MAX_INVERTIBLE_DEGREE
from hcid.errors import ConfigError, quote
from hcid.loop import _lti

if TYPE_CHECKING:
    import control

#: Discretisation of the deterministic paths (Hft, He, Yc). Tustin keeps the
#: phase of these smooth signals (ZOH would add half a sample of lag to each);
#: the remnant filter, driven by sample-held white noise, uses ZOH.
PATH_METHOD = "bilinear"
__all__ = [
    "DiscreteLoop",
    "discretise",
    "feedback_path",
    "feedforward_path",
    "plant",
    "remnant_filter",
    "transfer_function",
    "true_response",
]


def _tf(polynomials: _lti.Polynomials) -> control.TransferFunction:
    import control

    return control.tf(*polynomials)


def plant(loop: Loop) -> control.TransferFunction:
    """The configured plant ``Yc`` (the paper's ``Kc wb / (s (s + wb))`` by default), theta per u.

    Raises
    ------
    ConfigError
        For a plant per level of a data factor: each run's own comes from
        :meth:`hcid.config.Config.with_plant`.
    """
    if not isinstance(loop.plant, Plant):
        raise ConfigError(f"loop.plant.by: one plant is needed here, got one per level of {loop.plant.by!r}")
    return transfer_function(loop.plant)


def transfer_function(yc: Plant) -> control.TransferFunction:
    """A plant as a python-control transfer function, theta per u."""
    return _tf(_lti.tf(yc.num, yc.den))


def _nms(loop: Loop) -> _lti.Polynomials:
    w, z = loop.w_nms, loop.zeta_nms
    return _lti.tf([w**2], [1.0, 2 * z * w, w**2])


def _feedforward(model: HCModel, loop: Loop) -> _lti.Polynomials:
    if not model.has_feedforward:
        return _lti.tf([0.0], [1.0])
    yc = loop.plant
    inverse_plant = _lti.tf(yc.den, yc.num)
    lag = _lti.tf([1.0], [model.TI**2, 2 * model.TI, 1.0])
    path = _lti.product(_lti.product(_lti.gain(model.Kpt, _nms(loop)), inverse_plant), lag)
    if yc.relative_degree > MAX_INVERTIBLE_DEGREE:
        raise ConfigError(
            f"models.{model.name}: the feedforward path Ynms Kpt / Yc / (TI s + 1)^2 is improper "
            f"for the plant {quote(yc.text)} (relative degree {yc.relative_degree} > "
            f"{MAX_INVERTIBLE_DEGREE}); no proper Inverse Feedforward Model exists for it"
        )
    return _lti.minreal(path)


def feedforward_path(model: HCModel, loop: Loop) -> control.TransferFunction:
    """``Ynms * Kpt / Yc / (TI s + 1)^2`` without its delay: u per ft (0 for Kpt = 0).

    The Inverse Feedforward Model (SPEC 7) for the configured plant, formed as one
    transfer function (common factors cancelled).

    Raises
    ------
    ConfigError
        If the product is improper for this plant (its relative degree exceeds 4).
    """
    return _tf(_feedforward(model, loop))


def _feedback(model: HCModel, loop: Loop) -> _lti.Polynomials:
    return _lti.product(_nms(loop), _lti.tf([model.Kpe * model.TL, model.Kpe], [1.0]))


def feedback_path(model: HCModel, loop: Loop) -> control.TransferFunction:
    """``Ynms * Kpe (TL s + 1)`` without its delay: u per e."""
    return _tf(_feedback(model, loop))


def _remnant(loop: Loop) -> _lti.Polynomials:
    w, z = loop.w_n, loop.zeta_n
    return _lti.tf([w**3], np.polymul([1.0, 2 * z * w, w**2], [1.0, w]))


def remnant_filter(loop: Loop) -> control.TransferFunction:
    """``Yn`` with ``Kn = 1``: remnant n per unit white noise."""
    return _tf(_remnant(loop))


def discretise(sys, dt: float, method: str = "zoh") -> tuple[np.ndarray, np.ndarray]:
    """Discretise a SISO transfer function by ``control.sample_system``; returns ``(b, a)`` for
    ``scipy.signal.lfilter``. A ``(num, den)`` pair (the loop's own paths, ``bilinear`` or
    ``zoh``) is done by :mod:`hcid.loop._lti`, the same bits without importing python-control."""
    if isinstance(sys, tuple):
        num, den = _lti.sample(sys, dt, method)
    else:
        import control

        d = control.sample_system(sys, dt, method=method)
        num = np.atleast_1d(np.squeeze(np.asarray(d.num[0][0], dtype=np.float64)))
        den = np.atleast_1d(np.squeeze(np.asarray(d.den[0][0], dtype=np.float64)))
    # Pad the numerator to the denominator's length so coefficient k is lag k.
    b = np.concatenate([np.zeros(den.size - num.size), num])
    return b / den[0], den / den[0]


@dataclass(frozen=True)
class DiscreteLoop:
    """The loop at the simulation rate: discretised paths and whole-sample delays.

    Hft, He and Yc are discretised by Tustin (:data:`PATH_METHOD`), Yn by ZOH.

    Attributes
    ----------
    dt : float
        Simulation step (s).
    feedforward, feedback, plant, remnant : tuple of ndarray
        ``(b, a)`` of Hft, He, Yc and Yn (Kn = 1).
    delay_ft, delay_e : int
        Feedforward and feedback delays in samples.
    has_feedforward : bool
    disturbance_at : str
        ``output`` (``theta = Yc u + fd``) or ``input`` (``theta = Yc (u + fd)``).
    """

    dt: float
    feedforward: tuple[np.ndarray, np.ndarray]
    feedback: tuple[np.ndarray, np.ndarray]
    plant: tuple[np.ndarray, np.ndarray]
    remnant: tuple[np.ndarray, np.ndarray]
    delay_ft: int
    delay_e: int
    has_feedforward: bool
    disturbance_at: str = "output"

    @classmethod
    def build(cls, model: HCModel, loop: Loop, dt: float) -> DiscreteLoop:
        return cls(
            dt=dt,
            feedforward=discretise(_feedforward(model, loop), dt, PATH_METHOD)
            if model.has_feedforward
            else (np.zeros(1), np.ones(1)),
            feedback=discretise(_feedback(model, loop), dt, PATH_METHOD),
            plant=discretise(_lti.tf(loop.plant.num, loop.plant.den), dt, PATH_METHOD),
            remnant=discretise(_remnant(loop), dt),
            delay_ft=round(model.tau_pt / dt) if model.has_feedforward else 0,
            delay_e=round(model.tau_pe / dt),
            has_feedforward=model.has_feedforward,
            disturbance_at=loop.disturbance_at,
        )

    def response(self, which: str, w: np.ndarray) -> np.ndarray:
        """Frequency response of a discrete path with its delay at w (rad/s)."""
        b, a = {
            "feedforward": self.feedforward,
            "feedback": self.feedback,
            "plant": self.plant,
            "remnant": self.remnant,
        }[which]
        delay = {"feedforward": self.delay_ft, "feedback": self.delay_e}.get(which, 0)
        z = np.exp(1j * np.asarray(w) * self.dt)
        return np.polyval(b, z) / np.polyval(a, z) * z ** (-float(delay))


def true_response(model: HCModel, loop: Loop, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time true paths with delays at w (rad/s): ``(Hft, He)``, u per ft and per e."""
    w = np.asarray(w, dtype=np.float64)
    s = 1j * w
    hft = feedforward_path(model, loop)(s) * np.exp(-s * model.tau_pt)
    he = feedback_path(model, loop)(s) * np.exp(-s * model.tau_pe)
    return np.asarray(hft, dtype=complex), np.asarray(he, dtype=complex)


def closed_loop_poles(model: HCModel, loop: Loop, dt: float) -> np.ndarray:
    """Poles (z) of the discretised feedback loop ``1 + Yc(z) He(z) z^-L = 0`` at step ``dt``.

    The feedforward path is outside the loop, so the loop's stability is the
    feedback path's with the plant (the same for a model's disturbance-only task).

    Examples
    --------
    >>> from hcid.config.types import HCModel, Loop, Plant
    >>> loop = Loop(Plant.second_order(2.75, 2.0), 10.1, 0.35, 12.7, 0.26, remnant_ratio=0.15)
    >>> fb = HCModel("FB", 0.0, 0.0, 0.0, 0.75, 0.4, 0.24)
    >>> bool(np.max(np.abs(closed_loop_poles(fb, loop, 0.01))) < 1)
    True
    """
    b_e, a_e = discretise(_feedback(model, loop), dt, PATH_METHOD)
    b_c, a_c = discretise(_lti.tf(loop.plant.num, loop.plant.den), dt, PATH_METHOD)
    delay = round(model.tau_pe / dt)
    den = np.polymul(a_c, a_e)
    num = np.concatenate([np.zeros(delay), np.polymul(b_c, b_e)])
    n = max(den.size, num.size)
    # Coefficients in q = z^-1: char(q) = den(q) + q^L num(q); poles z = 1/q.
    char = np.zeros(n)
    char[: den.size] += den
    char[: num.size] += num
    q = np.roots(char[::-1])
    return 1.0 / q[np.abs(q) > 0]


def check_closed_loops(models, loop: Loop, dt: float) -> None:
    """Refuse a model whose closed loop or feedforward path is unstable or improper.

    The closed loop is named with its largest pole; the feedforward path
    (``Ynms Kpt / Yc / (TI s + 1)^2``, the plant's zeros become its poles) with
    its right-half-plane pole; an improper path is refused by :func:`feedforward_path`.

    Raises
    ------
    ConfigError
        ``models.<name>: the closed loop with this plant is unstable (pole at z = ..., |z| = ...)``.
    """

    for model in models:
        ff = _feedforward(model, loop)
        if model.has_feedforward:
            ff_poles = _lti.poles(ff)
            if ff_poles.size and np.max(ff_poles.real) >= 0:
                p = ff_poles[np.argmax(ff_poles.real)]
                raise ConfigError(
                    f"models.{model.name}: the feedforward path Ynms Kpt / Yc / (TI s + 1)^2 is unstable "
                    f"for the plant {quote(loop.plant.text)} (pole at s = {p.real:.3g}{p.imag:+.3g}j rad/s: "
                    "a zero of the plant in the right half-plane or at 0)"
                )
    for model in models:
        poles = closed_loop_poles(model, loop, dt)
        worst = poles[np.argmax(np.abs(poles))] if poles.size else 0.0
        if poles.size and abs(worst) >= 1.0 - 1e-12:
            s = np.log(complex(worst)) / dt
            raise ConfigError(
                f"models.{model.name}: the closed loop with this plant is unstable (pole at "
                f"z = {worst.real:.4f}{worst.imag:+.4f}j, |z| = {abs(worst):.4f}; "
                f"s = {s.real:.3g}{s.imag:+.3g}j rad/s)"
            )
