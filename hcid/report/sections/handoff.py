"""7b. What a choosing stage hands on (indirect stage 1: e_r) against the noise-free signal."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hcid import methods
from hcid.report.document import Doc

TITLE = "7b. Stage-1 hand-off: e_r against the noise-free e"


@dataclass(frozen=True)
class HandoffData:
    options: list[str]
    rows: list[list[str]]


def summarize(values: np.ndarray) -> tuple[float, float, float]:
    """(median, 5th percentile, min) of VAF values, NaN-free."""
    return float(np.median(values)), float(np.percentile(values, 5)), float(values.min())


def effective_options(spec, stage) -> str:
    """Every option of a stage with the value in effect (configured or default)."""
    return ", ".join(f"{k} {spec.option(stage, k)}" for k in spec.options)


def stage_options(config) -> list[str]:
    """``method stage: key value, ...`` for every stage configured away from its defaults."""
    out = []
    for method in methods.resolved(config.identify).values():
        for spec in method.stages:
            stage = config.identify.stage(spec.name)
            if stage.options:
                out.append(f"{method.name} {spec.name}: {effective_options(spec, stage)}")
    return out


def compute(run, done) -> HandoffData | None:
    if run.handoff is None:
        return None
    table = run.handoff.to_pydict()
    groups: dict[tuple, list[tuple[float, float]]] = {}
    for model, method, stage, signal, vaf, vaf_record in zip(
        table["model"],
        table["method"],
        table["stage"],
        table["signal"],
        table["vaf_noise_free"],
        table["vaf_noise_free_record"],
        strict=True,
    ):
        if np.isfinite(vaf):
            groups.setdefault((method, stage, signal, model), []).append((vaf, vaf_record))
    if not groups:
        return None
    rows = []
    for (method, stage, signal, model), vafs in groups.items():
        used, record = np.array(vafs).T
        med, p5, lo = summarize(used)
        rows.append(
            [method, stage, model, f"{signal}_r", str(len(vafs)), f"{med:.2f}", f"{p5:.2f}", f"{lo:.2f}"]
            + [f"{np.median(record):.4g}"]
        )
    return HandoffData(stage_options(run.config), rows)


def render(data: HandoffData | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    doc.text(
        "VAF (%) of the signal a choosing stage hands on against the same loop simulated without "
        "remnant: how well stage 1's e_r recovers the noise-free e that the indirect method's stage 2 "
        "assumes, over the rows the next stage fits and validates on, and (median) over the whole "
        "record, whose first samples stage 1 does not fit unless it starts from the first sample. "
        "Stage options: " + ("; ".join(data.options) if data.options else "the SPEC 3 defaults") + "."
    )
    doc.table(
        [
            "method",
            "stage",
            "model",
            "signal",
            "n",
            "median VAF %",
            "5th pct %",
            "min %",
            "whole record, median VAF %",
        ],
        data.rows,
    )
