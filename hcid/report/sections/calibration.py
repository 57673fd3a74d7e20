"""8. W calibration on the HC hypothesis (paper section 6, first recommendation)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from hcid import methods
from hcid.report import figures
from hcid.report.document import Doc

TITLE = "8. W calibration on the HC hypothesis"


@dataclass(frozen=True)
class CalibrationData:
    table: pa.Table
    name: str
    rows: list[list[str]]
    recommended: dict[str, float]


def compute(run, done) -> CalibrationData | None:
    if run.calibration is None:
        return None
    rows, recommended = [], {}
    present = run.calibration.to_pylist()
    for method in [*methods.METHODS, *sorted({r["method"] for r in present} - set(methods.METHODS))]:
        r = next((x for x in present if x["method"] == method), None)
        if r is None:
            continue
        recommended[method] = r["recommended"]
        rows.append(
            [
                method,
                f"{r['target_rate']:g}",
                *_interval(r),
            ]
        )
    return CalibrationData(run.calibration, run.config.name, rows, recommended)


def _interval(r: dict) -> tuple[str, str, str]:
    """The safe interval's ends and the recommended W; without a safe interval the calibration's
    pair is false positives up to, false negatives from (backward), not an interval."""
    if np.isfinite(r["recommended"]):
        return f"{r['safe_low']:.4g}", f"{r['safe_high']:.4g}", f"{r['recommended']:.4g}"
    return f"none (FP up to {r['safe_low']:.4g})", f"none (FN from {r['safe_high']:.4g})", "no safe W"


def render(data: CalibrationData | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}")
    doc.figure(
        "calibration.png",
        "False-positive rate of the FB twin and false-negative rate of the FF "
        "twin over W, with exact 95% (Clopper-Pearson) bands over realizations; green: the safe "
        "interval where both rates are at most the target rate, and the recommended W, its "
        "geometric midpoint.",
        lambda: figures.plot_calibration(data.table, data.name),
    )
    doc.table(["method", "target rate", "safe from W", "safe below W", "recommended W"], data.rows)
