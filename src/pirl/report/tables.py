"""The report's tables as data: each is built once from the numbers as rows of cells, then
rendered to Markdown here (:func:`render_markdown`, ``table.md``) and to HTML by the report's
Jinja2 template (``templates/report.html.j2``); neither output is parsed back from the other.

A module of its own (not part of :mod:`pirl.report.document`) because the modules that build
a table for the report (the physics, mission and advice-curve tables) are imported by it.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Span:
    """A piece of a cell: plain, bold or italic text, or a link to ``href`` (a path relative
    to the report folder, or ``#anchor``). ``short``: what the HTML page shows instead of
    ``text`` (a method's display name; the full ``text`` is its hover title and the legend's),
    while Markdown keeps ``text``."""

    text: str
    bold: bool = False
    italic: bool = False
    href: str | None = None
    short: str | None = None


class Named(str):
    """A method's full label that the HTML page shows by its short name (``short``; the full
    label is the hover title and the legend's). Everything else reads the label: it is the
    ``str`` (table.md, a test comparing a cell with a label)."""

    short: str

    def __new__(cls, label: str, short: str) -> Named:
        named = super().__new__(cls, label)
        named.short = short
        return named


Cell = str | Span | tuple[Span, ...]
"""A table cell: plain text (or :class:`Named`), one span, or spans side by side."""


@dataclass(frozen=True)
class Table:
    """One titled block of the report: paragraphs (``intro``), a table of ``rows`` under
    ``header`` (no table without a header), paragraphs after it (``notes``) and a bullet list.
    ``level``: the heading's level; ``anchor``: the heading's id in the HTML page (and, for
    a titled table, ``<anchor>-table`` the table's, ``<anchor>-list`` the list's)."""

    title: str = ""
    header: Sequence[str] = ()
    rows: Sequence[Sequence[Cell]] = ()
    intro: Sequence[str] = ()
    notes: Sequence[str] = ()
    bullets: Sequence[str] = ()
    level: int = 3
    anchor: str = ""

    def span_rows(self) -> list[list[tuple[Span, ...]]]:
        """The rows with every cell as its spans (what a renderer walks)."""
        return [[spans(cell) for cell in row] for row in self.rows]

    def span_header(self) -> list[tuple[Span, ...]]:
        """The header with every name as its spans (a method names a column: :class:`Named`)."""
        return [spans(cell) for cell in self.header]


def spans(cell: Cell) -> tuple[Span, ...]:
    """A cell as its spans."""
    if isinstance(cell, Named):
        return (Span(str(cell), short=cell.short),)
    if isinstance(cell, str):
        return (Span(cell),)
    return (cell,) if isinstance(cell, Span) else cell


def render_markdown(tables: Iterable[Table]) -> str:
    """The tables as Markdown, one after another, each block followed by a blank line."""
    lines: list[str] = []
    for table in tables:
        if table.title:
            lines += ["#" * table.level + " " + table.title, ""]
        for text in table.intro:
            lines += [text, ""]
        if table.header:
            lines.append(
                _markdown_row("".join(map(_markdown_span, c)) for c in table.span_header())
            )
            lines.append("|" + "---|" * len(table.header))
            for row in table.span_rows():
                lines.append(_markdown_row("".join(map(_markdown_span, c)) for c in row))
            lines.append("")
        for text in table.notes:
            lines += [text, ""]
        if table.bullets:
            lines += [*(f"- {text}" for text in table.bullets), ""]
    return "\n".join(lines)


def _markdown_row(cells: Iterable[str]) -> str:
    # A bare | inside a cell would end the cell: a label may hold one.
    escaped = (c.replace("|", r"\|") for c in cells)
    return "|" + "|".join(f" {c} " if c else " " for c in escaped) + "|"


def _markdown_span(span: Span) -> str:
    text = span.text
    if text and span.bold:
        text = f"**{text}**"
    elif text and span.italic:
        text = f"*{text}*"
    if span.href is None:
        return text
    # A destination with a space or a bracket (a file name may have one) needs <...>.
    href = f"<{span.href}>" if re.search(r"[\s()]", span.href) else span.href
    return f"[{text}]({href})"


__all__ = ["Cell", "Named", "Span", "Table", "render_markdown", "spans"]
