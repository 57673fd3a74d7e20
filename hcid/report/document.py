"""The report as a document: Markdown text, tables and figures, rendered to Markdown and HTML."""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Doc", "to_html", "to_markdown"]


@dataclass
class Doc:
    """Report being written: blocks of Markdown text, tables and figures, in order.

    A figure block names a PNG; ``drawings[name]`` draws it (a matplotlib
    Figure) when the report is written, from data computed beforehand.
    """

    blocks: list[tuple[str, dict]] = field(default_factory=list)
    drawings: dict[str, Callable[[], object]] = field(default_factory=dict)

    def text(self, md: str) -> None:
        self.blocks.append(("md", {"text": md}))

    def table(self, header: list[str], rows: list[list[str]]) -> None:
        self.blocks.append(("table", {"header": header, "rows": rows}))

    def figure(self, name: str, caption: str, draw: Callable[[], object]) -> None:
        self.blocks.append(("figure", {"name": name, "caption": caption}))
        self.drawings[name] = draw


def _escape_md(text: str) -> str:
    """Markdown text with HTML escaped (``<``, ``>``, ``&``), as the HTML report escapes it: a config
    name or run path never becomes markup in a Markdown viewer."""
    return html.escape(text, quote=False)


def to_markdown(doc: Doc) -> str:
    parts = []
    for kind, block in doc.blocks:
        if kind == "md":
            parts.append(_escape_md(block["text"]))
        elif kind == "figure":
            f = block
            caption = _escape_md(f["caption"])
            parts.append(f"![{caption}]({f['name']})\n\n_{caption}_")
        else:
            t = block
            lines = [
                "| " + " | ".join(_escape_md(h) for h in t["header"]) + " |",
                "|" + "---|" * len(t["header"]),
            ]
            lines += [
                "| " + " | ".join(_escape_md(str(c)).replace("|", "\\|") for c in row) + " |"
                for row in t["rows"]
            ]
            parts.append("\n".join(lines))
    return "\n\n".join(parts) + "\n"


def _inline_md(text: str) -> str:
    r"""The Markdown the report's texts use, as HTML: ``**bold**``, ``*italic*`` and ``_italic_``,
    `` `code` ``, and ``\*`` for a literal asterisk (W\*).

    >>> _inline_md("*Words.* A run's **W\\*** and `nb_ft` (_p_ < 0.05)")
    "<i>Words.</i> A run's <b>W*</b> and <code>nb_ft</code> (<i>p</i> &lt; 0.05)"
    """
    out = html.escape(text, quote=False).replace("\\*", "\x00")  # a literal asterisk, kept aside
    out = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", out)
    out = re.sub(r"(?<![\w*])\*(?=\S)(.+?)(?<=\S)\*(?![\w*])", r"<i>\1</i>", out)
    out = re.sub(r"`(.+?)`", r"<code>\1</code>", out)
    out = re.sub(r"(?<!\w)_(.+?)_(?!\w)", r"<i>\1</i>", out)
    return out.replace("\x00", "*")


def to_html(doc: Doc, out_dir: Path, title: str) -> str:
    body = []
    for kind, block in doc.blocks:
        if kind == "md":
            for para in block["text"].split("\n\n"):
                if para.startswith("## "):
                    body.append(f"<h2>{_inline_md(para[3:])}</h2>")
                elif para.startswith("# "):
                    body.append(f"<h1>{_inline_md(para[2:])}</h1>")
                else:
                    body.append(f"<p>{_inline_md(para)}</p>")
        elif kind == "figure":
            f = block
            data = (
                base64.b64encode((out_dir / f["name"]).read_bytes()).decode("ascii")
                if (out_dir / f["name"]).is_file()
                else ""
            )
            body.append(
                f'<figure><img alt="{html.escape(f["name"])}" src="data:image/png;base64,{data}">'
                f"<figcaption>{_inline_md(f['caption'])}</figcaption></figure>"
            )
        else:
            t = block
            head = "".join(f"<th>{html.escape(h)}</th>" for h in t["header"])
            rows = "".join(
                "<tr>"
                + "".join(f'<td class="{_cell_class(c)}">{html.escape(str(c))}</td>' for c in row)
                + "</tr>"
                for row in t["rows"]
            )
            # A wide table scrolls in its own box; the page keeps its width.
            body.append(
                f'<div class="wide"><table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table></div>'
            )
    style = (
        "body{font-family:sans-serif;max-width:1240px;margin:2em auto;padding:0 1em;line-height:1.4}"
        "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 6px;"
        "vertical-align:top;font-size:0.85em}th{background:#f0f0f0}img{max-width:100%}"
        ".wide{overflow-x:auto;max-width:100%}"
        "figcaption{font-size:0.9em;color:#444}.holds{background:#e6f4e6}.fails{background:#fbe3e3}"
        ".na{background:#f4f4f4}.short{white-space:nowrap}"
    )
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>hcid report: '
        f"{html.escape(title)}</title><style>{style}</style></head><body>\n"
        + "\n".join(body)
        + "\n</body></html>\n"
    )


def _cell_class(cell) -> str:
    """A verdict's colour; a short value (an estimate with its se, ``0.96 ± 0.32``) kept on one
    line, where a narrow column would break it over three."""
    text = str(cell)
    verdict = {"holds": "holds", "does not hold": "fails", "not evaluated": "na"}.get(text)
    return verdict or ("short" if len(text) <= 16 else "")
