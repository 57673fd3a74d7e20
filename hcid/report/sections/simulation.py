"""2. Simulation: RMS(e) and remnant ratio beside the paper's Table 2, and one record."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcid.config import paper
from hcid.report import figures
from hcid.report.document import Doc

TITLE = "2. Simulation"


@dataclass(frozen=True)
class SimulationData:
    rows: list[list[str]]
    record: dict[str, np.ndarray] | None
    record_key: tuple[str, int] | None
    rate: float
    is_paper: bool = True  # the paper's experiment: its Table 2 beside the RMS(e)


def compute(run, done) -> SimulationData | None:
    if run.summary is None:
        return None
    s = run.summary.to_pydict()
    is_paper = paper.is_paper_experiment(run.config)
    rows = []
    for m in run.config.models:
        idx = [i for i, n in enumerate(s["model"]) if n == m.name]
        if not idx:
            continue
        rms = np.array([s["rms_e_deg"][i] for i in idx])
        ratio = np.array([s["noise_ratio_disturbance_only"][i] for i in idx])
        ref = paper.RMS_E_DEG.get(m.name) if is_paper else None
        rows.append(
            [
                m.name,
                f"{m.Kpt:g}",
                f"{m.Kpe:g}",
                f"{m.TL:g}",
                f"{m.tau_pe:g}",
                f"{rms.mean():.3f} +- {rms.std(ddof=1) if rms.size > 1 else 0:.3f}",
                *([f"{ref:.2f}" if ref is not None else "-"] if is_paper else []),
                f"{ratio.mean():.4f}",
                f"{s['kn'][idx[0]]:.5g}",
            ]
        )
    recs = run.simulations()
    key = record = None
    if recs:
        key = next(
            ((m.name, run.config.seeds[0]) for m in run.config.models if m.has_feedforward), next(iter(recs))
        )
        record = recs.get(key)
    return SimulationData(rows, record, key, run.config.timing.output_rate, is_paper)


def render(data: SimulationData | None, doc: Doc) -> None:
    doc.text(f"## {TITLE}")
    if data is None:
        doc.text("_Missing: `simulation_summary.parquet` (run `hcid simulate`)._")
        return
    doc.table(
        [
            "model",
            "Kpt",
            "Kpe",
            "TL s",
            "tau_pe s",
            "RMS(e) deg (mean +- sd)",
            *(["paper Table 2"] if data.is_paper else []),
            "var(n)/var(u) dist.-only",
            "Kn",
        ],
        data.rows,
    )
    if data.record is not None:
        model, seed = data.record_key
        doc.figure(
            "signals.png",
            f"One simulated record (model {model}, seed {seed}), {data.rate:g} Hz.",
            lambda: figures.plot_signals(
                data.record["t"], data.record, f"Record of model {model}, seed {seed}"
            ),
        )
