"""1b. The experiment: plant, disturbance point, forcing functions and their spectra (SPEC 7)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcid.config import FileSignal, Multisine, Segments, paper
from hcid.loop.signals import forcing
from hcid.report import figures
from hcid.report.document import Doc

TITLE = "Experiment"


@dataclass(frozen=True)
class ExperimentData:
    rows: list[list[str]]
    spectra: dict[str, tuple[np.ndarray, np.ndarray]]  # name -> (w rad/s, amplitude rad)
    nyquist: float  # rad/s, of the analysis rate
    is_paper: bool


def _describe(spec) -> str:
    if isinstance(spec, Multisine):
        w = 2 * np.pi / spec.base_period * np.asarray(spec.k, dtype=float)
        rms = np.degrees(np.sqrt(np.sum(np.asarray(spec.amplitude) ** 2) / 2))
        return (
            f"multisine: {len(spec.k)} sines, {w.min():.3g}..{w.max():.3g} rad/s "
            f"(k x 2 pi / {spec.base_period:g} s), RMS {rms:.3g} deg"
        )
    if isinstance(spec, Segments):
        kinds = {"c": "hold", "p": "parabola", "r": "ramp"}
        counts = {kinds[k]: sum(s.kind == k for s in spec.segments) for k in kinds}
        parts = ", ".join(f"{n} {name}" for name, n in counts.items() if n)
        return (
            f"segments: {parts}; {sum(s.duration for s in spec.segments):g} s, "
            f"gain {np.degrees(spec.gain):g} deg"
        )
    if isinstance(spec, FileSignal):
        return f"file: column {spec.column!r} of {spec.path}, {spec.rate:g} Hz, window from {spec.start:g} s"
    return type(spec).__name__


def _spectrum(config, spec) -> tuple[np.ndarray, np.ndarray]:
    """Amplitudes of one measurement window's DFT lines (rad) up to the analysis Nyquist frequency."""
    timing = config.timing
    x = forcing(timing, spec)[-timing.window_samples :]
    lines = np.abs(np.fft.rfft(x)) * 2 / x.size
    w = 2 * np.pi / timing.window * np.arange(lines.size)
    keep = (w > 0) & (w <= np.pi * timing.output_rate)
    return w[keep], lines[keep]


def compute(run, done) -> ExperimentData:
    config = run.config
    timing = config.timing
    nyquist = np.pi * timing.output_rate
    if not config.simulates:
        rows = [
            ["described by", "the measured data only (the config has no simulation sections)"],
            ["analysis rate", f"{timing.output_rate:g} Hz, record {timing.window:g} s"],
        ]
        if config.data is not None:
            rows.append(["lead-in skipped", f"{config.data.lead_in:g} s"])
        return ExperimentData(rows, {}, nyquist, False)
    loop = config.loop
    point = {
        "output": "at the plant output: theta = Yc u + fd (as in the paper)",
        "input": "at the plant input: theta = Yc (u + fd)",
    }[loop.disturbance_at]
    rows = [
        ["plant Yc", f"{loop.plant.text} ({loop.plant.kind})"],
        ["disturbance fd enters", point],
        ["target ft", _describe(config.target)],
        ["disturbance fd", _describe(config.disturbance)],
        [
            "timing",
            f"simulated at {timing.sim_rate:g} Hz, analysed at {timing.output_rate:g} Hz; run-in "
            f"{timing.run_in:g} s, window {timing.window:g} s, {timing.periods} period(s)",
        ],
        [
            "feedforward hypothesis",
            "Inverse Feedforward Model: Ynms Kpt / Yc / (TI s + 1)^2 exp(-s tau_pt)",
        ],
    ]
    if config.data is not None and config.data.lead_in:
        rows.append(["measured data lead-in skipped", f"{config.data.lead_in:g} s"])
    spectra = {"ft": _spectrum(config, config.target), "fd": _spectrum(config, config.disturbance)}
    return ExperimentData(rows, spectra, nyquist, paper.is_paper_experiment(config))


def render(data: ExperimentData, doc: Doc) -> None:
    doc.text(f"## {TITLE}")
    if data.is_paper:
        doc.text("The paper's experiment (SPEC sections 1 and 2).")
    doc.table(["setting", "value"], data.rows)
    if data.spectra:
        doc.figure(
            "forcing_spectra.png",
            "Forcing functions: amplitude of each DFT line of one measurement window, up to the "
            "analysis Nyquist frequency.",
            lambda: figures.plot_forcing_spectra(data.spectra, data.nyquist),
        )
