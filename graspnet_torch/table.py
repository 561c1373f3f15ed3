"""Tables: plain text for terminal summaries, markdown for reports."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["format_table", "markdown_table"]


def format_table(headers: Sequence[str], rows: Sequence[Sequence[object]], floatfmt: str = ".3g") -> str:
    """Align ``rows`` under ``headers``; numbers right-aligned, floats formatted with ``floatfmt``."""

    def cell(v: object) -> str:
        return format(v, floatfmt) if isinstance(v, float) else str(v)

    cells = [[cell(v) for v in row] for row in rows]
    widths = [max(len(h), *(len(r[k]) for r in cells)) if cells else len(h) for k, h in enumerate(headers)]
    numeric = [all(isinstance(row[k], int | float) for row in rows) if rows else False for k in range(len(headers))]

    def line(values: Sequence[str]) -> str:
        return "  ".join(v.rjust(w) if num else v.ljust(w)
                         for v, w, num in zip(values, widths, numeric, strict=True)).rstrip()

    sep = "  ".join("-" * w for w in widths)
    return "\n".join([line(list(headers)), sep, *(line(r) for r in cells)])


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[object]], floatfmt: str = ".3g") -> str:
    """A GitHub markdown table (``| a | b |``); floats formatted with ``floatfmt``, ``|`` in a cell escaped."""

    def cell(v: object) -> str:
        return (format(v, floatfmt) if isinstance(v, float) else str(v)).replace("|", "\\|").replace("\n", " ")

    numeric = [bool(rows) and all(isinstance(row[k], int | float) for row in rows) for k in range(len(headers))]
    lines = ["| " + " | ".join(cell(h) for h in headers) + " |",
             "|" + "|".join("---:" if num else "---" for num in numeric) + "|"]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)
