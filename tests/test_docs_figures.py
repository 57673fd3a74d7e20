"""The docs' marked figures (issue 46): every mark well formed and filled, and the check's rules.
`make docs-figures` makes each marked figure again and compares; these tests check what can be
checked without running the studies."""

from __future__ import annotations

import importlib.util
import re

import pytest

from .conftest import ROOT

_spec = importlib.util.spec_from_file_location("docs_figures", ROOT / "benchmarks" / "docs_figures.py")
docs_figures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(docs_figures)


@pytest.mark.parametrize("doc", docs_figures.DOCS)
def test_every_mark_is_closed_and_holds_a_figure(doc):
    # An opened mark without its close would swallow the text up to the next one; an empty mark
    # is a figure nobody wrote in (`docs_figures.py --write` fills it).
    text = (ROOT / doc).read_text()
    opened, closed = text.count("<!-- fig "), text.count("<!-- /fig -->")
    assert opened == closed, (doc, opened, closed)
    for m in docs_figures.MARK.finditer(text):
        assert "<!-- fig " not in m["body"], (doc, m["name"])  # not nested
        assert m["body"].strip(), (doc, m["name"])
        if m["name"].startswith("time:"):  # a wall time is a range with its unit
            assert re.fullmatch(r"[\d.]+ to [\d.]+ (s|min)", m["body"].strip()), (doc, m["body"])


def test_a_wall_time_is_judged_against_its_range():
    assert docs_figures.in_range("30 to 120 s", 57.3)
    assert not docs_figures.in_range("30 to 120 s", 161.0)
    assert docs_figures.in_range("5 to 8 min", 376.8) and not docs_figures.in_range("5 to 8 min", 250.0)
    assert not docs_figures.in_range("about 50 s", 50.0)  # a single number is not a range


def test_the_marks_of_the_docs_are_read_as_written(tmp_path, monkeypatch):
    # A figure that differs is listed with both texts; --write puts the made one in its place,
    # a block staying a block and a word a word; a name nothing makes is listed as such.
    doc = tmp_path / "page.md"
    doc.write_text("W is <!-- fig a:w -->0.25<!-- /fig -->.\n<!-- fig a:t -->\n| x |\n<!-- /fig -->\n"
                   "<!-- fig a:typo -->1<!-- /fig -->\n")  # fmt: skip
    monkeypatch.setattr(docs_figures, "ROOT", tmp_path)
    monkeypatch.setattr(docs_figures, "DOCS", ("page.md",))
    made = {"a:w": "0.26", "a:t": "| y |"}
    wrong = docs_figures.check_marks(made, {}, (), write=False)
    assert len(wrong) == 3 and "0.25" in wrong[0] and "0.26" in wrong[0] and "nothing makes" in wrong[2]
    docs_figures.check_marks(made, {}, (), write=True)
    text = doc.read_text()
    assert "<!-- fig a:w -->0.26<!-- /fig -->" in text and "<!-- fig a:t -->\n| y |\n<!-- /fig -->" in text
    assert docs_figures.check_marks(made, {}, ("a:typo",), write=False) == []
