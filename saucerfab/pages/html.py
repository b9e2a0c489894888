"""A small self-contained HTML page of sections: headings, text, pictures, tables (:func:`html_report`).

The design's and the print's ``report.html`` (:mod:`saucerfab.pages.folder_pages`)
and the batch report are built from it; the pictures come from
:mod:`saucerfab.imaging.panels`.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Section:
    """One section of an HTML report.

    Attributes:
        title: heading.
        text: paragraph text (plain text; escaped).
        images: (caption, image) pairs; image is PNG bytes (embedded as a
            data URI) or a relative path/URL string (linked as is).
        table: key -> value rows (values shown with ``str``), or None.
        grid: (column headings, rows) of a table with columns, or None.
        html: markup inserted as is after the images (trusted: made by
            saucerfab, e.g. the 3D viewer), or "".
    """

    title: str
    text: str = ""
    images: list[tuple[str, bytes | str]] = field(default_factory=list)
    table: Mapping[str, Any] | None = None
    grid: tuple[Sequence[str], Sequence[Sequence[Any]]] | None = None
    html: str = ""


_CSS = (
    "body{font-family:system-ui,sans-serif;margin:2em;max-width:72em;color:#222}"
    "h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em}"
    "figure{display:inline-block;margin:.5em 1em .5em 0;vertical-align:top}"
    "figure img{max-width:32em;border:1px solid #ddd}figcaption{font-size:.9em;color:#555}"
    "table{border-collapse:collapse}td,th{border:1px solid #ddd;padding:.2em .6em;text-align:left}"
)


def html_report(sections: Sequence[Section | Mapping[str, Any]], *, title: str = "saucerfab report") -> str:
    """A small self-contained HTML page: headings, text, images, key-value tables.

    Args:
        sections: :class:`Section` objects or mappings with the same keys.
        title: page title and top heading.
    Returns:
        The HTML document as a string (UTF-8 when written). PNG bytes are
        embedded as base64 data URIs, so the page works on its own; string
        image references are kept as relative links.
    """
    esc = html.escape
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{esc(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{esc(title)}</h1>",
    ]
    for raw in sections:
        sec = raw if isinstance(raw, Section) else Section(**dict(raw))
        parts.append(f"<section><h2>{esc(sec.title)}</h2>")
        if sec.text:
            parts.append(f"<p>{esc(sec.text)}</p>")
        for caption, img in sec.images:
            if isinstance(img, (bytes, bytearray)):
                src = "data:image/png;base64," + base64.b64encode(bytes(img)).decode("ascii")
            else:
                src = esc(str(img), quote=True)
            parts.append(
                f'<figure><img src="{src}" alt="{esc(caption, quote=True)}">'
                f"<figcaption>{esc(caption)}</figcaption></figure>"
            )
        if sec.html:
            parts.append(sec.html)
        if sec.table:
            rows = "".join(
                f"<tr><th>{esc(str(k))}</th><td>{esc(str(v))}</td></tr>" for k, v in sec.table.items()
            )
            parts.append(f"<table>{rows}</table>")
        if sec.grid:
            heads, body = sec.grid
            head = "".join(f"<th>{esc(str(h))}</th>" for h in heads)
            rows = "".join("<tr>" + "".join(f"<td>{esc(str(c))}</td>" for c in r) + "</tr>" for r in body)
            parts.append(f"<table><tr>{head}</tr>{rows}</table>")
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
