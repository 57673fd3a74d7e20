"""Closed-loop simulation of the HC model in the tracking task (SPEC sections 1, 2).

The loop runs at the simulation rate with discretised paths (Tustin for Hft,
He and Yc, ZOH for the remnant filter; :mod:`hcid.loop.hcmodel`) and whole-sample
delays. Because the feedback path holds a delay of ``L`` samples,
the feedback input ``e(k - L)`` is known ``L`` samples ahead: the loop is
exact to rounding with no algebraic loop and no iteration. It runs sample by
sample in a compiled kernel doing ``lfilter``'s own arithmetic (for filters
with ``a[0] = 1`` and ``len(a) = len(b) >= 2``, as every discretised path is;
others run as blocks of ``L`` samples, two ``lfilter`` calls with carried
state each, the kernel's slow twin, which gives the same bits where both
apply).
The kept window is low-passed at the output Nyquist frequency by an FFT
brick-wall (zero phase) and decimated.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
from numba import njit

from hcid.config import Config, HCModel, Multisine, Segments
from hcid.errors import ConfigError
from hcid.loop import signals
from hcid.loop.hcmodel import DiscreteLoop
from hcid.tables import CHANNELS

__all__ = [
    "Realization",
    "decimate",
    "remnant_gain",
    "simulate_loop",
    "simulate_realization",
    "white_noise",
]


@dataclass(frozen=True)
class Realization:
    """One simulated record at the output rate.

    Attributes
    ----------
    model : str
    seed : int
    t : ndarray, shape (N,)
        Time (s) from the start of the measurement window.
    ft, fd, e, u, theta, n : ndarray, shape (N,)
        Target, disturbance, error, HC output, system output, remnant (rad).
    kn : float
        Remnant gain used.
    """

    model: str
    seed: int
    t: np.ndarray
    ft: np.ndarray
    fd: np.ndarray
    e: np.ndarray
    u: np.ndarray
    theta: np.ndarray
    n: np.ndarray
    kn: float

    @property
    def rms_e_deg(self) -> float:
        return float(np.degrees(np.sqrt(np.mean(self.e**2))))

    @property
    def noise_ratio(self) -> float:
        """var(n)/var(u) over the record."""
        return float(np.var(self.n) / np.var(self.u))


def white_noise(seed: int, n: int, stream: int = 0) -> np.ndarray:
    """Unit-variance Gaussian white noise, one stream per seed (shared by every model); a
    ``stream`` other than 0 (:attr:`hcid.config.Config.noise_stream`) gives every seed another."""
    return np.random.default_rng([stream, seed] if stream else seed).standard_normal(n)


def simulate_loop(
    dloop: DiscreteLoop, ft: np.ndarray, fd: np.ndarray, n: np.ndarray, *, ft_ahead: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Simulate the closed loop from rest at the simulation rate.

    Parameters
    ----------
    dloop : DiscreteLoop
        Discretised paths and delays; the feedback delay must be >= 1 sample.
    ft, fd, n : ndarray, shape (m,)
        Target, disturbance and remnant (rad), one value per simulation sample.
    ft_ahead : ndarray, optional
        The target past the last sample: what a feedforward with a negative delay (anticipation,
        ``tau_pt < 0``) reads at the end; at least that many samples.

    Returns
    -------
    dict of ndarray
        ``ft, fd, e, u, theta, n``, each shape (m,).
    """
    m = ft.size
    block = dloop.delay_e
    if block < 1:
        raise ValueError("simulate_loop: the feedback delay must be at least one sample")
    u_open = n.copy()
    if dloop.has_feedforward:
        b, a = dloop.feedforward
        delay = dloop.delay_ft
        if delay >= 0:
            u_ff = _lfilter(b, a, ft)
            u_open[delay:] += u_ff[: m - delay]
        else:  # anticipation: the path reads the target -delay samples ahead
            if ft_ahead is None or ft_ahead.size < -delay:
                raise ValueError(
                    f"simulate_loop: an anticipating feedforward needs ft {-delay} samples ahead"
                )
            u_open += _lfilter(b, a, np.concatenate([ft, ft_ahead[:-delay]]))[-delay:]

    e = np.zeros(m + block)  # e[block + k] is e(k); the first `block` entries are the rest state
    u = np.empty(m)
    theta = np.empty(m)
    at_input = dloop.disturbance_at == "input"
    if _replicable(*dloop.feedback) and _replicable(*dloop.plant):
        _loop_kernel(*dloop.feedback, *dloop.plant, block, u_open, ft, fd, at_input, e, u, theta)
    else:  # filters whose lfilter arithmetic the kernel does not replicate (not the discretised paths)
        _loop_blocks(dloop, block, u_open, ft, fd, at_input, e, u, theta)
    return {"ft": ft, "fd": fd, "e": e[block:], "u": u, "theta": theta, "n": n}


def _loop_blocks(dloop, block, u_open, ft, fd, at_input, e, u, theta):
    """The loop in blocks of ``block`` samples, two ``lfilter`` calls with carried state each."""
    from scipy import signal as sps

    b_fb, a_fb = dloop.feedback
    b_c, a_c = dloop.plant
    z_fb = np.zeros(max(a_fb.size, b_fb.size) - 1)
    z_c = np.zeros(max(a_c.size, b_c.size) - 1)
    m = u.size
    for k0 in range(0, m, block):
        k1 = min(k0 + block, m)
        u_fb, z_fb = sps.lfilter(b_fb, a_fb, e[k0:k1], zi=z_fb)
        u[k0:k1] = u_fb + u_open[k0:k1]
        if at_input:  # theta = Yc (u + fd)
            theta[k0:k1], z_c = sps.lfilter(b_c, a_c, u[k0:k1] + fd[k0:k1], zi=z_c)
        else:  # theta = Yc u + fd (the paper)
            y, z_c = sps.lfilter(b_c, a_c, u[k0:k1], zi=z_c)
            theta[k0:k1] = y + fd[k0:k1]
        e[block + k0 : block + k1] = ft[k0:k1] - theta[k0:k1]


def _replicable(b: np.ndarray, a: np.ndarray) -> bool:
    """Whether :func:`_df2t` does lfilter's exact arithmetic for (b, a).

    It does for ``a[0] = 1`` and ``len(a) = len(b) >= 2``, the form every
    discretised path has; lfilter treats others differently (a length-1
    ``a`` by convolution; padding divided by ``a[0]``).
    """
    return a.size == b.size >= 2 and a[0] == 1.0


@njit(cache=True)
def _df2t(b, a, x, z):
    """One sample of a direct form II transposed filter, state ``z`` updated in place.

    scipy.signal.lfilter's own loop (scipy/signal/_lfilter.c, ``DOUBLE_filt``),
    operation for operation: ``y = z0 + b0 x``, then ``z_n = (z_{n+1} + x
    b_{n+1}) - y a_{n+1}``, the last ``x b - y a``. No FMA: numba contracts
    nothing without fastmath.
    """
    y = z[0] + b[0] * x
    last = b.shape[0] - 1
    for i in range(last - 1):
        z[i] = (z[i + 1] + x * b[i + 1]) - y * a[i + 1]
    z[last - 1] = x * b[last] - y * a[last]
    return y


def _lfilter(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``scipy.signal.lfilter(b, a, x)`` from rest: the compiled :func:`_df2t` where it does
    lfilter's arithmetic (:func:`_replicable`; the same bits), lfilter itself otherwise. A
    simulating process then need not import scipy.signal."""
    if _replicable(b, a):
        return _filter_kernel(b, a, np.ascontiguousarray(x, dtype=np.float64))
    from scipy import signal as sps

    return sps.lfilter(b, a, x)


@njit(cache=True)
def _filter_kernel(b, a, x):
    """:func:`_df2t` over ``x`` from a zero state."""
    z = np.zeros(b.shape[0] - 1)
    y = np.empty_like(x)
    for k in range(x.shape[0]):
        y[k] = _df2t(b, a, x[k], z)
    return y


@njit(cache=True)
def _loop_kernel(b_fb, a_fb, b_c, a_c, block, u_open, ft, fd, at_input, e, u, theta):
    """The loop sample by sample (compiled); the arithmetic of :func:`_loop_blocks` for
    filters that pass :func:`_replicable`.

    ``e(k - block)``, the feedback path's input at sample k, is known
    ``block`` samples ahead, so a sample-by-sample loop does the blocks'
    operations in the same order.
    """
    z_fb = np.zeros(b_fb.shape[0] - 1)
    z_c = np.zeros(b_c.shape[0] - 1)
    for k in range(u.shape[0]):
        u[k] = _df2t(b_fb, a_fb, e[k], z_fb) + u_open[k]
        if at_input:  # theta = Yc (u + fd)
            theta[k] = _df2t(b_c, a_c, u[k] + fd[k], z_c)
        else:  # theta = Yc u + fd (the paper)
            theta[k] = _df2t(b_c, a_c, u[k], z_c) + fd[k]
        e[block + k] = ft[k] - theta[k]


def decimate(x: np.ndarray, factor: int) -> np.ndarray:
    """Zero-phase FFT brick-wall low-pass at the new Nyquist frequency, then every ``factor``-th sample.

    Bins at and above ``fs / (2 factor)`` are removed (x is treated as one period).
    """
    spectrum = np.fft.rfft(x)
    cutoff = x.size // (2 * factor)
    spectrum[cutoff:] = 0.0
    return np.fft.irfft(spectrum, n=x.size)[::factor]


def _forcing(timing, spec, ahead: int = 0) -> np.ndarray:
    """:func:`hcid.loop.signals.forcing`, computed once per process for the kinds made from
    the config alone (every seed and model of a study shares them); any other kind
    (a data file's column) is made each time. A copy: callers may write to it."""
    if isinstance(spec, _CONFIG_ONLY):
        return _config_forcing(timing, spec, ahead).copy()
    return signals.forcing(timing, spec, ahead)


# Forcing kinds that are a function of their (frozen, hashable) config section alone.
_CONFIG_ONLY = (Multisine, Segments)


@functools.lru_cache(maxsize=16)
def _config_forcing(timing, spec, ahead: int) -> np.ndarray:
    return signals.forcing(timing, spec, ahead)


@functools.lru_cache(maxsize=16)
def _discrete_loop(model: HCModel, loop, dt: float) -> DiscreteLoop:
    """:meth:`DiscreteLoop.build`, once per process (every seed shares it); its arrays
    are made read-only, since every later realization of the process reads them."""
    dloop = DiscreteLoop.build(model, loop, dt)
    for path in (dloop.feedforward, dloop.feedback, dloop.plant, dloop.remnant):
        for coefficients in path:
            coefficients.flags.writeable = False
    return dloop


def _feedback_only(model: HCModel) -> HCModel:
    """The model without its feedforward path (the disturbance-only task)."""
    return dataclasses.replace(model, Kpt=0.0, TI=0.0, tau_pt=0.0)


def _disturbance_lines(config: Config) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (rad/s) and amplitudes (rad) of the disturbance's sines."""
    dist = config.disturbance
    if isinstance(dist, Multisine):
        return signals.forcing_frequencies(dist), np.asarray(dist.amplitude)
    timing = config.timing
    fd = signals.forcing(timing, dist)[-timing.window_samples :]
    lines = np.fft.rfft(fd)[1 : (fd.size + 1) // 2] * 2 / fd.size  # DC and Nyquist left out
    w = 2 * np.pi / timing.window * np.arange(1, lines.size + 1)
    return w, np.abs(lines)


def remnant_gain(config: Config) -> float:
    """Kn that gives ``var(n)/var(u) = remnant_ratio`` in the disturbance-only task (or the
    config's ``loop.remnant_gain`` when it gives Kn itself).

    Computed once, analytically, from the discrete loop's frequency responses
    (ft = 0, feedback path of the first model; SPEC: all models share one Kn):
    ``u = (n - He D fd) / (1 + Yc He)`` with ``D = 1`` for a disturbance at the plant's
    output and ``D = Yc`` at its input, so with ``n = Kn n1``

    - ``var(u_fd) = sum_i A_i^2 / 2 |He D / (1 + Yc He)|^2`` at the disturbance frequencies
      (a multisine's own lines; for another kind of disturbance, the DFT lines of one
      window of it at the simulation rate, the window taken as its period),
    - ``var(n1)`` and ``var(n1 / (1 + Yc He))`` are integrals of ``|.|^2`` over
      ``[0, pi]`` of the unit-white-noise-driven discrete filters,

    and ``Kn^2 = r var(u_fd) / (var(n1) - r var(n1 / (1 + Yc He)))``.
    """
    if config.loop.remnant_gain is not None:  # given as Kn (a twin of a measured person)
        return float(config.loop.remnant_gain)
    dloop = DiscreteLoop.build(_feedback_only(config.models[0]), config.loop, config.timing.sim_dt)
    ratio = config.loop.remnant_ratio
    if ratio == 0.0:
        return 0.0

    w_dist, amplitude = _disturbance_lines(config)
    he = dloop.response("feedback", w_dist)
    yc = dloop.response("plant", w_dist)
    to_u = he / (1 + yc * he)
    if dloop.disturbance_at == "input":
        to_u = to_u * yc
    var_u_fd = float(np.sum(amplitude**2 / 2 * np.abs(to_u) ** 2))

    # Variance of a unit-white-noise-driven discrete filter: (1/pi) int_0^pi |H|^2 dW.
    # The midpoint rule is spectrally accurate for these smooth periodic integrands
    # and never evaluates the plant's pole at z = 1.
    m = 2**17
    omega = (np.arange(m) + 0.5) * np.pi / m
    w = omega / dloop.dt
    n1 = dloop.response("remnant", w)
    sens = 1.0 / (1.0 + dloop.response("plant", w) * dloop.response("feedback", w))
    var_n1 = float(np.mean(np.abs(n1) ** 2))
    var_un = float(np.mean(np.abs(n1 * sens) ** 2))
    if var_n1 - ratio * var_un <= 0.0:
        # var(n)/var(u) tends to var(n1)/var(S n1) as Kn grows: the loop cannot have more.
        raise ConfigError(
            f"loop.remnant_ratio: {ratio:g} is more than this loop can show (var(n)/var(u) stays below "
            f"{var_n1 / var_un:.3g} however strong the remnant); give a smaller ratio or loop.remnant_gain"
        )
    return float(np.sqrt(ratio * var_u_fd / (var_n1 - ratio * var_un)))


def simulate_realization(
    config: Config, model: HCModel, seed: int, kn: float, *, disturbance_only: bool = False
) -> Realization:
    """Simulate one model and remnant realization and return the decimated record.

    Parameters
    ----------
    config : Config
        Loop, signals and timing.
    model : HCModel
        The HC model. With ``disturbance_only`` its feedforward is dropped and ft = 0.
    seed : int
        Seed of the white-noise stream (the same stream for every model; with the config's
        ``noise_stream``).
    kn : float
        Remnant gain, from :func:`remnant_gain`.

    Returns
    -------
    Realization
        The last measurement window at the output rate.
    """
    timing = config.timing
    t = signals.simulation_time(timing)
    fd = _forcing(timing, config.disturbance)
    if disturbance_only:
        model = _feedback_only(model)
    dloop = _discrete_loop(model, config.loop, timing.sim_dt)
    ahead = max(0, -dloop.delay_ft)  # an anticipating feedforward reads the target past the end
    ft = np.zeros_like(t) if disturbance_only else _forcing(timing, config.target, ahead)
    b_n, a_n = dloop.remnant
    n = kn * _lfilter(b_n, a_n, white_noise(seed, t.size, config.noise_stream))
    out = simulate_loop(dloop, ft[: t.size], fd, n, ft_ahead=ft[t.size :])

    keep = slice(t.size - timing.window_samples, t.size)
    factor = timing.decimation
    record = {name: decimate(out[name][keep], factor) for name in CHANNELS}
    t_out = np.arange(timing.record_samples) / timing.output_rate
    return Realization(model=model.name, seed=seed, t=t_out, kn=kn, **record)
