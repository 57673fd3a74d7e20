"""9. Measured data as a function of W (paper section 6, second recommendation)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)

from hcid.report import compute as calc
from hcid.report import figures
from hcid.report.document import Doc
from hcid.report.run import marks_for_plot

TITLE = "9. Measured data"


@dataclass(frozen=True)
class DataSection:
    name: str
    structure: calc.DataStructure | None
    marks: dict[str, float]
    summary_rows: list[list[str]]
    shift_text: str
    responses: list[tuple[float, calc.Responses, list[str]]]
    calibrated: bool


def compute(run, done) -> DataSection | None:
    data_cfg = run.config.data
    if (
        data_cfg is None
        or run.frontier is None
        or data_cfg.name not in set(run.frontier.column("model").to_pylist())
    ):
        return None
    calibration = done.get("calibration")
    recommended = calibration.recommended if calibration is not None else {}
    structure = (
        calc.compute_data_structure(run.selection, data_cfg.name) if run.selection is not None else None
    )
    bic = {
        label: w for label, w in marks_for_plot(run.criterion_marks()).items() if label.startswith("W_BIC")
    }
    marks = {**bic, **{f"calibrated {m}": w for m, w in recommended.items()}}
    w_values = sorted(set(data_cfg.w_report) | {w for w in recommended.values() if np.isfinite(w)})
    rows = calc.data_summary_rows(run.frontier, data_cfg.name, w_values)
    shift = run.config.identify
    frontier = run.frontier.filter(pa.compute.equal(run.frontier.column("model"), data_cfg.name))
    methods_present = set(frontier.column("method").to_pylist())
    responses = []
    for w in w_values:
        answer_for = [m for m, r in recommended.items() if np.isclose(w, r)]
        resp = calc.compute_responses(frontier, run.config, dict.fromkeys(methods_present, w))
        responses.append((w, resp, answer_for))
    return DataSection(
        name=data_cfg.name,
        structure=structure,
        marks=marks,
        summary_rows=rows,
        shift_text=(
            f"nk_ft includes the {shift.target_shift:g} s target shift: the ft delay is "
            f"nk_ft - {shift.shift_samples(run.config.timing.output_rate)} samples (negative: anticipation)."
        ),
        responses=responses,
        calibrated=bool(recommended),
    )


def render(data: DataSection | None, doc: Doc) -> None:
    if data is None:
        return
    doc.text(f"## {TITLE}: {data.name}")
    doc.text(
        "No true dynamics are known for measured data: the report shows the selected structure and "
        "fit as functions of W, and the models at chosen W values"
        + (
            ", the calibrated W marked as the answer."
            if data.calibrated
            else "; run `hcid calibrate-w` to mark a calibrated W."
        )
    )
    if data.structure is not None:
        doc.figure(
            "data_structure.png",
            "Selected nb_ft, d and VAF of every run vs W.",
            lambda: figures.plot_data_structure(data.structure, data.marks, data.name),
        )
    doc.table(
        ["run", "method", "W", "na", "nb_ft", "nb_e", "nk_ft", "nk_e", "VAF est. %", "VAF val. %"],
        data.summary_rows,
    )
    doc.text(data.shift_text)
    for w, resp, answer_for in data.responses:
        name = f"bode_data_w{w:.4g}.png".replace("+", "")
        title = f"{data.name}: selected models at W = {w:.3g}" + (
            f" (calibrated for the {' and '.join(answer_for)} method)" if answer_for else ""
        )
        doc.figure(
            name,
            f"Every run's selected model at W = {w:.3g}"
            + (", the calibrated W: the answer." if answer_for else "."),
            lambda resp=resp, title=title: figures.plot_bode(resp, data.name, {}, title=title),
        )
