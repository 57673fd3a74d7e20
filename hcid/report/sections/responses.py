"""5-7. The selected models' frequency responses against the true paths (paper Figs. 7-10),
and the stage choices of methods with a choosing stage."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hcid import methods
from hcid.config import paper
from hcid.loop.hcmodel import true_response
from hcid.report import compute as calc
from hcid.report import figures
from hcid.report.document import Doc

TITLE = "5. Selected models at W_BIC"


@dataclass(frozen=True)
class ResponsesData:
    bic: calc.Responses
    w_bic: dict[str, float]
    no_ff: calc.Responses
    truths: dict[str, dict[str, np.ndarray]]
    references: dict[str, dict[str, list]]
    ff_model: str | None
    errors: dict[tuple[str, str], dict[str, np.ndarray]]
    choices: dict[str, list[tuple[tuple, int]]] = field(default_factory=dict)
    is_paper: bool = True  # the paper's experiment: its figures named beside the titles


def _choices(run) -> dict[str, list[tuple[tuple, int]]]:
    """The most frequent models of each choosing stage, with their counts."""
    out = {}
    for name, table in run.choices.items():
        cols = [c for c in table.column_names if c.startswith(("na", "nb_", "nk_"))]
        values = table.select(cols).to_pydict()
        counts: dict[tuple, int] = {}
        for row in zip(*values.values(), strict=True):
            counts[row] = counts.get(row, 0) + 1
        out[name] = (cols, sorted(counts.items(), key=lambda x: -x[1])[:6])
    return out


def compute(run, done) -> ResponsesData | None:
    if run.frontier is None:
        return None
    config = run.config
    w_bic = run.w_bic()
    bic = calc.compute_responses(run.frontier, config, w_bic)
    no_ff = calc.compute_responses(
        run.frontier, config, dict.fromkeys(methods.METHODS, paper.W_NO_FEEDFORWARD)
    )
    omega = bic.omega
    ref = calc.reference_feedforward(config, omega)
    truths, references = {}, {}
    for m in config.models:
        hft, he = true_response(m, config.loop, omega)
        truths[m.name] = {"hft": hft, "he": he}
        references[m.name] = (
            {"hft": [(f"FF feedforward, Kpt = {paper.KPT_FALSE_POSITIVE:g}", ref)]}
            if not m.has_feedforward and ref is not None
            else {}
        )
    ff = next((m for m in config.models if m.has_feedforward), None)
    errors = {}
    if ff is not None:
        for path in ("hft", "he"):
            for (model, method), h in getattr(bic, path).items():
                if model == ff.name:
                    errors[(path, method)] = calc.compute_errors(h, truths[ff.name][path])
    return ResponsesData(
        bic=bic,
        w_bic=w_bic,
        no_ff=no_ff,
        truths=truths,
        references=references,
        ff_model=ff.name if ff is not None else None,
        errors=errors,
        choices=_choices(run),
        is_paper=paper.is_paper_experiment(config),
    )


def render(data: ResponsesData | None, doc: Doc) -> None:
    doc.text(f"## {TITLE}" + (" (paper Figs. 7, 8)" if data is not None and data.is_paper else ""))
    if data is None:
        doc.text("_Missing: `frontier.parquet` (run `hcid identify`)._")
        return
    w_text = ", ".join(sorted({f"{w:.3g}" for w in data.w_bic.values()}))
    band = f"{data.bic.band[0]:.2f}..{data.bic.band[1]:.2f} rad/s"
    for model, truth in data.truths.items():
        name = f"bode_{model}_bic.png"
        doc.figure(
            name,
            f"{model}: every realization's selected model at W_BIC (thin lines; "
            f"the count of models with that path in the legend), the true paths (black), "
            f"the disturbance band {band} (dashed).",
            lambda model=model, truth=truth: figures.plot_bode(
                data.bic,
                model,
                truth,
                data.references[model],
                title=f"{model}: selected models at W_BIC = {w_text}",
            ),
        )
    if data.ff_model is not None:
        ff = data.ff_model
        w = paper.W_NO_FEEDFORWARD
        doc.text(f"## 6. FF feedback path at W = {w:g}" + (" (paper Fig. 9)" if data.is_paper else ""))
        doc.figure(
            f"bode_{ff}_w{w:g}.png".replace("0.", "0"),
            f"Feedback path of the models selected at W = {w:g}.",
            lambda: figures.plot_bode(
                data.no_ff,
                ff,
                {"he": data.truths[ff]["he"]},
                paths=("he",),
                title=f"{ff}: feedback path at W = {w:g}",
            ),
        )
        doc.text("## 7. Errors at W_BIC per method" + (" (paper Fig. 10)" if data.is_paper else ""))
        doc.figure(
            "errors_bic.png",
            f"Magnitude and phase errors (paper eq. 11-12) of the {ff} model.",
            lambda: figures.plot_errors(
                data.bic.omega,
                data.errors,
                data.bic.band,
                f"{ff}: errors at W_BIC, mean (solid) and max (dashed) over realizations",
            ),
        )
    for stage, (cols, counts) in data.choices.items():
        doc.text(
            f"The models {stage} chose ({', '.join(cols)}), over the realizations: "
            + ", ".join(f"{k} x{v}" for k, v in counts)
            + "."
        )
