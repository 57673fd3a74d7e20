"""Build a run's report: compute every section's data first, then render and write it.

:func:`compute_report` reads the run directory once (:mod:`hcid.report.run`)
and computes the data of every section (:mod:`hcid.report.sections`) without
drawing; :func:`write_report` renders that data into Markdown, self-contained
HTML and PNG figures.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hcid.io import folders, results
from hcid.pipeline.rundir import using
from hcid.report import figures
from hcid.report.document import Doc, to_html, to_markdown
from hcid.report.run import RunTables, read_run
from hcid.report.sections import RENDER_ORDER, SECTIONS, STUDY_SECTIONS

__all__ = ["Report", "ReportData", "build_report", "compute_report", "write_report"]


@dataclass(frozen=True)
class ReportData:
    """Everything the report shows: the run's tables and each section's computed data, by section."""

    run: RunTables
    sections: dict[str, Any]
    missing: tuple[str, ...]

    @property
    def verdicts(self) -> list:
        verdicts = self.sections.get("verdicts")
        return verdicts[1] if verdicts is not None else []


@dataclass(frozen=True)
class Report:
    """Where the report went and what it holds."""

    markdown: Path
    html: Path
    figures: tuple[Path, ...]
    missing: tuple[str, ...]
    verdicts: list


def _section_name(module) -> str:
    return module.__name__.rsplit(".", 1)[-1]


def compute_report(run_dir: str | Path) -> ReportData:
    """Read ``run_dir`` and compute every section's data (no drawing, no writing)."""
    run = read_run(Path(run_dir))
    done: dict[str, Any] = {}
    if run.analysis is not None:  # a measured study (hcid analyse): its answer, no paper sections
        for section in STUDY_SECTIONS:
            done[_section_name(section)] = section.compute(run, done)
        return ReportData(run=run, sections=done, missing=())
    for section in SECTIONS:
        done[_section_name(section)] = section.compute(run, done)
    missing = tuple(
        name
        for name, table in (
            ("simulation", run.summary),
            ("identification", run.frontier),
            ("W sweep", run.selection),
        )
        if table is None
    )
    return ReportData(run=run, sections=done, missing=missing)


def render(data: ReportData) -> Doc:
    """The report document, with each figure's drawing deferred to :func:`write_report`."""
    doc = Doc()
    doc.text(f"# hcid report: {data.run.config.name}\n\nRun directory: `{data.run.run_dir}`.")
    if data.missing:
        doc.text(
            "**Missing stages:** "
            + ", ".join(data.missing)
            + ". Run `hcid run CONFIG` to complete them; what is there is reported below."
        )
    for section in STUDY_SECTIONS if data.run.analysis is not None else RENDER_ORDER:
        section.render(data.sections[_section_name(section)], doc)
    return doc


def _old_report(entries: list[str]) -> bool:
    """A report folder written by an hcid without manifests: only its Markdown, HTML and figures."""
    return all(e in ("report.md", "report.html") or e.endswith(".png") for e in entries)


def write_report(data: ReportData, out_dir: Path, *, adopt_old: bool = False) -> Report:
    """Draw the figures and write ``report.md``, ``report.html`` and the PNGs into ``out_dir``.

    ``out_dir`` follows the rules of every folder hcid writes (:mod:`hcid.io.folders`):
    new, empty or an hcid report folder; only hcid's own files are replaced, and
    figures of an earlier report that this one does not draw are removed.
    ``adopt_old`` takes over a report folder written before folders had manifests.
    """
    doc = render(data)
    folders.check_output_path(out_dir, "report folder")
    names = [*doc.drawings, "report.md", "report.html"]
    folders.claim(out_dir, names, folders.REPORT, adopt=_old_report if adopt_old else None)
    for name in names:  # before drawing anything: a refusal leaves no half-written report
        folders.check_replaceable(out_dir / name)
    written = []
    for name, draw in doc.drawings.items():
        figures.save(draw(), out_dir / name)
        written.append(out_dir / name)
    md_path, html_path = out_dir / "report.md", out_dir / "report.html"
    results.write_text(to_markdown(doc), md_path)
    results.write_text(to_html(doc, out_dir, data.run.config.name), html_path)
    stale = [f for f in folders.owned_files(out_dir) if f not in names]
    if stale:
        folders.remove_owned(out_dir, stale)
    return Report(md_path, html_path, tuple(written), data.missing, data.verdicts)


def build_report(run_dir: str | Path, out_dir: str | Path | None = None) -> Report:
    """Write the report of ``run_dir`` into ``out_dir`` (default: ``run_dir/report``)."""
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run_dir / "report"
    with using(run_dir, create=False):
        return write_report(compute_report(run_dir), out, adopt_old=out_dir is None)
