"""The answer, first in the report: the paper's claims (SPEC section 6) against this run, each by a
stated rule."""

from __future__ import annotations

from hcid.config import paper
from hcid.report.document import Doc
from hcid.report.verdicts import Verdict, compute_verdicts

TITLE = "The answer: the paper's claims (SPEC section 6) against this run"


def compute(run, done) -> tuple[bool, list[Verdict]] | None:
    """The verdicts, or None for another experiment than the paper's (its claims do not apply)."""
    if run.config.simulates and not paper.is_paper_experiment(run.config):
        return None
    curves = done.get("curves")
    responses = done.get("responses")
    verdicts = compute_verdicts(
        run.config,
        run.summary,
        curves.curves if curves is not None else None,
        run.thresholds,
        responses.bic if responses is not None else None,
        responses.no_ff if responses is not None else None,
    )
    return run.summary is not None, verdicts


def render(data: tuple[bool, list[Verdict]] | None, doc: Doc) -> None:
    if data is None:  # not the paper's experiment: no section
        return
    simulated, verdicts = data
    doc.text(f"## {TITLE}")
    if not simulated:
        doc.text("_No simulation in this run: the paper's claims are not evaluated._")
    doc.table(
        ["claim", "paper", "this run", "holds", "rule"],
        [
            [
                v.claim,
                v.paper,
                v.this_run,
                v.status_text,
                v.rule,
            ]
            for v in verdicts
        ],
    )
