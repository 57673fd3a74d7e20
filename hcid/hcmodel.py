"""The human-controller model and its loop as python-control transfer functions.

SPEC section 1. ``Ypt`` and ``Ype`` are improper alone, so the paths are built
as the proper products with the neuromuscular system, ``Hft = Ynms*Ypt`` and
``He = Ynms*Ype``, without their delays; the delays are whole samples at the
simulation rate and are applied separately (:class:`DiscreteLoop`).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from hcid.config import HCModel, Loop

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
    "true_response",
]


def plant(loop: Loop) -> control.TransferFunction:
    """``Yc = Kc wb / (s (s + wb))``, theta per u."""
    return control.tf([loop.Kc * loop.wb], [1.0, loop.wb, 0.0])


def _nms(loop: Loop) -> control.TransferFunction:
    w, z = loop.w_nms, loop.zeta_nms
    return control.tf([w**2], [1.0, 2 * z * w, w**2])


def feedforward_path(model: HCModel, loop: Loop) -> control.TransferFunction:
    """``Ynms * Kpt / Yc / (TI s + 1)^2`` without its delay: u per ft (0 for Kpt = 0)."""
    if not model.has_feedforward:
        return control.tf([0.0], [1.0])
    inverse_plant = control.tf([1.0, loop.wb, 0.0], [loop.Kc * loop.wb])
    lag = control.tf([1.0], [model.TI**2, 2 * model.TI, 1.0])
    return control.minreal(model.Kpt * _nms(loop) * inverse_plant * lag, verbose=False)


def feedback_path(model: HCModel, loop: Loop) -> control.TransferFunction:
    """``Ynms * Kpe (TL s + 1)`` without its delay: u per e."""
    return _nms(loop) * control.tf([model.Kpe * model.TL, model.Kpe], [1.0])


def remnant_filter(loop: Loop) -> control.TransferFunction:
    """``Yn`` with ``Kn = 1``: remnant n per unit white noise."""
    w, z = loop.w_n, loop.zeta_n
    return control.tf([w**3], np.polymul([1.0, 2 * z * w, w**2], [1.0, w]))


def discretise(
    sys: control.TransferFunction, dt: float, method: str = "zoh"
) -> tuple[np.ndarray, np.ndarray]:
    """Discretise with python-control; returns ``(b, a)`` for ``scipy.signal.lfilter``."""
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
    """

    dt: float
    feedforward: tuple[np.ndarray, np.ndarray]
    feedback: tuple[np.ndarray, np.ndarray]
    plant: tuple[np.ndarray, np.ndarray]
    remnant: tuple[np.ndarray, np.ndarray]
    delay_ft: int
    delay_e: int
    has_feedforward: bool

    @classmethod
    def build(cls, model: HCModel, loop: Loop, dt: float) -> DiscreteLoop:
        return cls(
            dt=dt,
            feedforward=discretise(feedforward_path(model, loop), dt, PATH_METHOD)
            if model.has_feedforward
            else (np.zeros(1), np.ones(1)),
            feedback=discretise(feedback_path(model, loop), dt, PATH_METHOD),
            plant=discretise(plant(loop), dt, PATH_METHOD),
            remnant=discretise(remnant_filter(loop), dt),
            delay_ft=round(model.tau_pt / dt) if model.has_feedforward else 0,
            delay_e=round(model.tau_pe / dt),
            has_feedforward=model.has_feedforward,
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
