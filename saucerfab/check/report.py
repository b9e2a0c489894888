"""Check results: findings, the report, its JSON schema, JUnit XML and the text table.

JSON schema ``saucerfab.check/1``
---------------------------------
``Report.to_dict()`` gives one file's result; ``reports_to_dict`` (what
``saucerfab check --json`` prints) wraps many::

    {"schema": "saucerfab.check/1", "saucerfab_version": "0.1.0",
     "strict": false, "printer": "j55" | null,
     "files": [REPORT, ...],
     "summary": {"files": 3, "printable": 1, "not_printable": 1,
                 "unreadable": 1, "exit_code": 2}}

    REPORT = {"schema": "saucerfab.check/1", "path": "...",
              "format": "3mf"|"obj"|"stl"|"ply"|"glb"|"gltf"|"wrl"|null,
              "verdict": "printable"|"not printable"|"unreadable",
              "exit_code": 0|1|2, "printer": str|null, "strict": bool,
              "elapsed_s": float,
              "findings": [{"severity": "error"|"warning"|"info",
                            "code": "not_watertight", "message": "...",
                            "where": null | {"point_mm": [x, y, z],
                                             "faces": [i, ...],
                                             "vertices": [i, ...],
                                             "count": n, "entry": "..."}}],
              "stats": {... see STATS_SCHEMA ...}}

``JSON_SCHEMA`` below is the machine-readable form (JSON Schema 2020-12;
``saucerfab check --schema`` prints it). Within ``/1`` fields are only ever
added, never renamed or removed; codes in ``CODES`` are stable. Face and
vertex indices in ``where`` count from 0 in the order the file lists them
(polygons fan-triangulated in order; 3MF build items and glTF/VRML instances
one after another). Every message is one line.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

SCHEMA_ID = "saucerfab.check/1"

Severity = Literal["error", "warning", "info"]
Verdict = Literal["printable", "not printable", "unreadable"]

#: verdict -> exit code
EXIT_CODES: dict[str, int] = {"printable": 0, "not printable": 1, "unreadable": 2}

#: Every finding code, its usual severity and what it means. "unreadable"
#: codes make the verdict unreadable (exit 2); the others are findings on a
#: mesh that was read. Severity can differ from the usual one where noted.
CODES: dict[str, tuple[str, str]] = {
    # -- the file could not be read as a mesh (exit 2)
    "file_not_found": ("unreadable", "the path does not exist or is not a file"),
    "empty_file": ("unreadable", "the file has no bytes"),
    "not_a_mesh": ("unreadable", "the content is not a mesh format (an image, a PDF, garbage...)"),
    "unsupported_format": ("unreadable", "a mesh format or variant the checker does not read"),
    "truncated": ("unreadable", "the file ends before its own header says it should"),
    "malformed": ("unreadable", "the file breaks its format's syntax"),
    "index_out_of_range": ("unreadable", "a face refers to a vertex (or UV, colour) that does not exist"),
    "xml_forbidden": ("unreadable", "XML with a DTD, entity declarations or external entities"),
    "archive_unsafe_path": ("unreadable", "an archive entry or reference escapes the archive (absolute or '..')"),
    "archive_too_large": ("unreadable", "an archive over the entry-count or uncompressed-size limit (zip bomb)"),
    "over_check_limit": ("unreadable", "over one of the checker's limits (Limits); the message names it"),
    "no_triangles": ("unreadable", "the file holds no triangles"),
    "internal_error": ("unreadable", "an unexpected failure inside the checker (a bug: please report it with the file)"),
    # -- geometry (errors)
    "non_finite": ("error", "NaN, infinite or absurd (beyond 1e9 mm) coordinates"),
    "degenerate_faces": ("error", "faces with a repeated vertex or zero area"),
    "duplicate_faces": ("error", "faces using the same three vertices as another face"),
    "not_watertight": ("error", "open edges: edges used by only one face"),
    "non_manifold_edges": ("error", "edges shared by more than two faces"),
    "non_manifold_vertices": ("error", "vertices where separate fans of faces meet (pinched)"),
    "inconsistent_orientation": ("error", "neighbouring faces wound in opposite directions (flipped faces)"),
    "inverted_normals": ("error", "a closed shell with negative volume: normals point inward"),
    "self_intersections": ("error", "faces that cross other faces of the mesh"),
    "not_manifold": ("error", "manifold3d rejects the mesh as not an oriented 2-manifold"),
    # -- printer profile (errors unless noted)
    "exceeds_build_volume": ("error", "the bounding box does not fit the printer's build volume in any axis order"),
    "too_many_triangles": ("error", "over the printer's or bureau's polygon limit"),
    "file_too_large": ("error", "over the printer's or bureau's file-size limit"),
    "format_not_accepted": ("error", "the printer's software or the bureau does not take this format"),
    "thin_walls": ("error", "walls thinner than the printer's minimum over more than a set share of the surface (Limits.thin_wall_error_fraction, 0.5 %; a warning under it)"),
    # -- colour
    "texture_missing": ("error", "a referenced texture is not there"),
    "texture_unreadable": ("error", "a texture that cannot be decoded, or of a format printers do not take"),
    "texture_too_large": ("error", "a texture over the printer's edge limit or the checker's pixel limit"),
    "texture_path_unsafe": ("error", "a texture path that is absolute or leaves the model's folder"),
    "uv_out_of_range": ("error", "texture coordinates outside [0, 1]: the colour would wrap or clamp"),
    "texture_low_dpi": ("warning", "the texture is coarser on the model than the printer's dpi"),
    "partly_coloured": ("warning", "only part of the surface carries colour"),
    "no_colour": ("info", "the file carries no colour at all"),
    # -- 3MF conformance: the specs' own rules, and lib3mf (the 3MF Consortium's reader) as a second opinion
    "spec_violation": ("error", "the 3MF breaks a MUST of the 3MF core or Materials specification (section and fix named)"),
    "lib3mf_rejects": ("error", "lib3mf, the 3MF Consortium's reader, refuses the file (info when a spec_violation says why)"),
    "lib3mf_warning": ("warning", "lib3mf reads the file but warns; in its strict mode it would refuse it"),
    "lib3mf_reads": ("info", "lib3mf, the 3MF Consortium's reader, reads the file in strict mode"),
    "lib3mf_not_run": ("info", "lib3mf did not judge the file: not installed (info), or it crashed or ran out of time or memory (warning)"),
    # -- other warnings / information
    "unreferenced_vertices": ("warning", "vertices no face uses"),
    "multiple_shells": ("warning", "more than one separate shell (several parts, or stray pieces)"),
    "units_suspect": ("warning", "an implausible size for the stated or assumed units"),
    "extension_mismatch": ("warning", "the file's content is a different format than its name says"),
    "ignored_content": ("warning", "parts of the file the checker skipped (points, lines, unknown nodes)"),
    "texcoords_missing": ("warning", "OBJ faces naming texture coordinates the file does not have (read uncoloured)"),
    "units": ("info", "the units the file states or that were assumed"),
    "continued_lines": ("info", "OBJ statements continued on the next line with a trailing backslash, joined"),
    "from_archive": ("info", "the mesh was read from inside a zip (an OBJ + MTL + PNG upload bundle, say)"),
    "fits_rotated": ("info", "fits the build volume only with its axes swapped"),
    "check_partial": ("info", "a check stopped at a work limit; its result covers part of the mesh"),
    "check_skipped": ("info", "a check that could not run on this mesh (the reason is given)"),
}

UNREADABLE_CODES = frozenset(c for c, (kind, _) in CODES.items() if kind == "unreadable")

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\ud800-\udfff\ufffe\uffff]")


def clean_text(text: object, limit: int = 500) -> str:
    """One printable line: control characters escaped, length capped.

    Messages carry pieces of hostile files (names, tokens); escaping keeps a
    message on one line and keeps JUnit XML well-formed.
    """
    s = str(text)
    s = _CONTROL.sub(lambda m: "\\x%02x" % ord(m.group()) if ord(m.group()) < 0x100 else "?", s)
    if len(s) > limit:
        s = s[: limit - 3] + "..."
    return s


@dataclass(frozen=True)
class Finding:
    """One thing the checker found.

    Attributes:
        severity: ``error`` (not printable), ``warning`` (fails only with
            strict) or ``info``.
        code: stable identifier from :data:`CODES`.
        message: one line saying what is wrong, with numbers, and what to do.
        where: optional location: ``point_mm`` (x, y, z), ``faces`` and
            ``vertices`` (file indices, at most 10), ``count`` (how many in
            all), ``entry`` (an archive entry, texture or line).
    """

    severity: Severity
    code: str
    message: str
    where: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        if self.severity not in ("error", "warning", "info"):
            raise ValueError(f"bad severity {self.severity!r}")
        if self.code not in CODES:
            raise ValueError(f"finding code {self.code!r} is not in CODES")
        object.__setattr__(self, "message", clean_text(self.message))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (see the module docstring)."""
        return {"severity": self.severity, "code": self.code, "message": self.message, "where": _jsonable(self.where)}


def finding(code: str, message: str, *, severity: Severity | None = None, where: dict[str, Any] | None = None) -> Finding:
    """A finding with the code's usual severity unless one is given."""
    kind = CODES[code][0]
    sev: Severity = severity or ("error" if kind == "unreadable" else kind)  # type: ignore[assignment]
    return Finding(sev, code, message, where)


@dataclass(frozen=True)
class Report:
    """The result of checking one file.

    Build it with :meth:`Report.build`, which derives ``verdict`` and
    ``exit_code`` from the findings: unreadable if any finding has an
    unreadable code; otherwise not printable if any error (or, with
    ``strict``, any warning); otherwise printable.
    """

    path: str
    format: str | None
    verdict: Verdict
    exit_code: int
    findings: list[Finding]
    stats: dict[str, Any]
    printer: str | None = None
    strict: bool = False
    elapsed_s: float = 0.0

    @classmethod
    def build(
        cls,
        path: str,
        format: str | None,
        findings: Sequence[Finding],
        stats: dict[str, Any],
        *,
        printer: str | None = None,
        strict: bool = False,
        elapsed_s: float = 0.0,
    ) -> Report:
        """A report whose verdict and exit code follow from ``findings``."""
        verdict = _verdict(findings, strict)
        return cls(
            path=clean_text(path, 2000),
            format=format,
            verdict=verdict,
            exit_code=EXIT_CODES[verdict],
            findings=list(findings),
            stats=dict(stats),
            printer=printer,
            strict=strict,
            elapsed_s=elapsed_s,
        )

    def with_strict(self, strict: bool = True) -> Report:
        """The same report judged with (or without) ``strict``: warnings fail."""
        verdict = _verdict(self.findings, strict)
        return replace(self, strict=strict, verdict=verdict, exit_code=EXIT_CODES[verdict])

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "error"]

    @property
    def warnings(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "warning"]

    @property
    def codes(self) -> set[str]:
        """The codes of all findings (handy in tests and scripts)."""
        return {f.code for f in self.findings}

    def reason(self) -> str:
        """One line: the verdict and the first reason for it."""
        bad = [f for f in self.findings if f.severity == "error"]
        if self.strict and not bad:
            bad = self.warnings
        if not bad:
            return self.verdict
        more = f" (+{len(bad) - 1} more)" if len(bad) > 1 else ""
        return f"{self.verdict}: {bad[0].code}: {bad[0].message}{more}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form, schema ``saucerfab.check/1`` (see the module docstring)."""
        return {
            "schema": SCHEMA_ID,
            "path": self.path,
            "format": self.format,
            "verdict": self.verdict,
            "exit_code": self.exit_code,
            "printer": self.printer,
            "strict": self.strict,
            "elapsed_s": round(float(self.elapsed_s), 4),
            "findings": [f.to_dict() for f in self.findings],
            "stats": _jsonable(self.stats),
        }


def _verdict(findings: Iterable[Finding], strict: bool) -> Verdict:
    fs = list(findings)
    if any(f.code in UNREADABLE_CODES for f in fs):
        return "unreadable"
    if any(f.severity == "error" for f in fs) or (strict and any(f.severity == "warning" for f in fs)):
        return "not printable"
    return "printable"


def _jsonable(x: Any) -> Any:
    """Plain JSON types: numpy scalars/arrays become numbers/lists; NaN/Inf become null."""
    if x is None or isinstance(x, (bool, str)):
        return x
    if isinstance(x, int):
        return int(x)
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    tolist = getattr(x, "tolist", None)  # numpy scalars and arrays, without importing numpy
    if tolist is not None:
        return _jsonable(tolist())
    return clean_text(x)


def summary_counts(reports: Sequence[Report]) -> dict[str, int]:
    """Counts per verdict and the overall exit code (the largest)."""
    return {
        "files": len(reports),
        "printable": sum(r.verdict == "printable" for r in reports),
        "not_printable": sum(r.verdict == "not printable" for r in reports),
        "unreadable": sum(r.verdict == "unreadable" for r in reports),
        "exit_code": max((r.exit_code for r in reports), default=0),
    }


def summary_line(reports: Sequence[Report]) -> str:
    """``3 files: 1 printable, 1 not printable, 1 unreadable (exit 2)``."""
    c = summary_counts(reports)
    noun = "file" if c["files"] == 1 else "files"
    return (
        f"{c['files']} {noun}: {c['printable']} printable, {c['not_printable']} not printable, "
        f"{c['unreadable']} unreadable (exit {c['exit_code']})"
    )


def reports_to_dict(reports: Sequence[Report]) -> dict[str, Any]:
    """The many-file JSON document (what ``--json`` prints)."""
    from saucerfab import __version__

    printers = {r.printer for r in reports}
    return {
        "schema": SCHEMA_ID,
        "saucerfab_version": __version__,
        "strict": any(r.strict for r in reports),
        "printer": printers.pop() if len(printers) == 1 else None,
        "files": [r.to_dict() for r in reports],
        "summary": summary_counts(reports),
    }


def reports_to_json(reports: Sequence[Report], *, indent: int | None = 2) -> str:
    """:func:`reports_to_dict` as JSON text (strict JSON: no NaN)."""
    return json.dumps(reports_to_dict(reports), indent=indent, allow_nan=False)


def reports_to_junit(reports: Sequence[Report], *, suite_name: str = "saucerfab check") -> str:
    """JUnit XML: one ``testcase`` per file.

    A not-printable file gets a ``failure`` (type = first error's code), an
    unreadable one an ``error``; every finding is listed in the element's
    text, one per line, and warnings/info of passing files go to
    ``system-out``. Understood by GitLab, Jenkins, GitHub test reporters.
    """
    import xml.etree.ElementTree as ET  # writing only; parsing untrusted XML uses defusedxml

    c = summary_counts(reports)
    total_t = sum(r.elapsed_s for r in reports)
    attrs = {
        "name": suite_name,
        "tests": str(c["files"]),
        "failures": str(c["not_printable"]),
        "errors": str(c["unreadable"]),
        "skipped": "0",
        "time": f"{total_t:.3f}",
    }
    root = ET.Element("testsuites", attrs)
    suite = ET.SubElement(root, "testsuite", attrs)
    for r in reports:
        case = ET.SubElement(
            suite, "testcase", {"classname": "saucerfab.check", "name": _xml_text(r.path), "time": f"{r.elapsed_s:.3f}"}
        )
        lines = "\n".join(_xml_text(f"{f.severity} {f.code}: {f.message}") for f in r.findings)
        if r.verdict != "printable":
            bad = [f for f in r.findings if f.code in UNREADABLE_CODES] or r.errors or r.warnings
            first = bad[0] if bad else None
            tag = "error" if r.verdict == "unreadable" else "failure"
            el = ET.SubElement(
                case,
                tag,
                {"type": first.code if first else r.verdict, "message": _xml_text(r.reason())},
            )
            el.text = lines
        elif lines:
            ET.SubElement(case, "system-out").text = lines
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _xml_text(s: str) -> str:
    # clean_text already escaped control characters; this guards paths too
    return clean_text(s, 4000)


# -- human table ------------------------------------------------------------


def _fmt_size(stats: dict[str, Any]) -> str:
    bb = stats.get("bbox_mm")
    if not bb:
        return "-"
    return "x".join(f"{v:.4g}" for v in bb["size"])


def _fmt_num(v: Any, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


#: the table's columns: header, justification
_TABLE_COLUMNS = (
    ("file", "left"), ("format", "left"), ("verdict", "left"), ("triangles", "right"),
    ("size mm", "right"), ("volume cm3", "right"), ("min wall mm", "right"), ("E/W", "right"),
)


def _file_name(path: str) -> str:
    return re.split(r"[/\\]", path)[-1]


def shorten_middle(path: str, width: int, ellipsis: str = "\u2026") -> str:
    """``path`` in ``width`` characters, cut in the middle: the file name stays whole.

    ``tmp/some/deep/folder/runs/e1/saucer.3mf`` at 24 is ``tmp/some/de…1/saucer.3mf``.
    Where ``width`` cannot hold ``…/`` and the name, the result is that, longer.
    """
    if len(path) <= width:
        return path
    name = _file_name(path)
    keep = max(width - len(ellipsis), 0)
    tail = min(len(path), max(len(name) + 1, keep - keep // 2))  # the name and the separator before it
    head = max(keep - tail, 0)
    return path[:head] + ellipsis + path[len(path) - tail :]


def _table_widths(rows: Sequence[Sequence[str]], total: int, ellipsis: str) -> list[int] | None:
    """Widths of the table's columns (without padding) so it fits ``total`` characters.

    No cell is ever cut but the file's, which shortens its middle
    (:func:`shorten_middle`) down to ``…/name``; headers may wrap at their
    spaces. None when even that does not fit: then one line per file.
    """
    heads = [h for h, _ in _TABLE_COLUMNS]
    cols = list(zip(*rows)) if rows else [() for _ in heads]
    cell = [max((len(c) for c in col), default=0) for col in cols]
    natural = [max(len(h), c) for h, c in zip(heads, cell)]
    least = [max(max(len(w) for w in h.split()), c) for h, c in zip(heads, cell)]
    least[0] = max([len(heads[0])] + [min(len(p), len(_file_name(p)) + 1 + len(ellipsis)) for p in cols[0]])
    avail = total - (3 * len(heads) + 1)  # a space either side of each cell, the rules between and at the edges
    if sum(natural) <= avail:
        return natural
    widths = [natural[0], *least[1:]]
    spare = avail - sum(widths)
    if spare < 0:  # the file column gives way, down to its least
        widths[0] = avail - sum(least[1:])
        return widths if widths[0] >= least[0] else None
    for i in sorted(range(1, len(heads)), key=lambda i: natural[i] - least[i]):  # unwrap what is cheapest first
        grow = min(natural[i] - least[i], spare)
        widths[i] += grow
        spare -= grow
    return widths


def _table_cells(r: Report) -> list[str]:
    s = r.stats
    vol = s.get("volume_mm3")
    return [
        r.path,
        r.format or "?",
        r.verdict,
        _fmt_num(s.get("triangles"), ","),
        _fmt_size(s),
        "-" if vol is None else f"{vol / 1000:.4g}",
        _fmt_num(s.get("min_wall_mm"), ".3g"),
        f"{len(r.errors)}/{len(r.warnings)}",
    ]


def _file_line(r: Report, cells: Sequence[str], verdict_style: str) -> Any:
    """The narrow form of a table row: ``path  format  verdict  triangles  size  min-wall  E/W``."""
    from rich.text import Text

    _, fmt, verdict, tris, size, _, wall, ew = cells
    parts: list[Any] = [r.path, "  ", fmt, "  ", (verdict, verdict_style)]
    for text, shown in ((f"{tris} triangles", tris), (f"{size} mm", size), (f"min wall {wall} mm", wall)):
        if shown != "-":
            parts += ["  ", text]
    parts += ["  ", f"E/W {ew}"]
    return Text.assemble(*parts)


def _where(f: Finding) -> str:
    """``  at (x, y, z) mm`` for a finding with a point its message does not already name, else ``""``."""
    if not (f.where and f.where.get("point_mm") is not None):
        return ""
    x, y, z = f.where["point_mm"]
    point = f"({x:.2f}, {y:.2f}, {z:.2f}) mm"
    return "" if point in f.message else f"  at {point}"  # most messages already name the point


def _shown_findings(r: Report) -> list[Finding]:
    """The findings a person is shown: errors and warnings (and the info ones of an unreadable file)."""
    return [f for f in r.findings if f.severity != "info" or r.verdict == "unreadable"]


def render_plain(reports: Sequence[Report], out: Any = None) -> None:
    """The summary for a pipe or a file: one line per file, then one line per finding; no table, no wrapping.

    Each line starts with the file's path, so ``grep`` finds a file's lines
    and ``cut -d: -f1`` its name::

        out/saucer.3mf: printable  3mf  12,345 triangles  100x195x12 mm  min wall 1.2 mm  E/W 0/0
        out/plate.stl: not printable  stl  ...
        out/plate.stl: error thin_walls: ...
    """
    import sys

    out = out if out is not None else sys.stdout
    for r in reports:
        _, fmt, verdict, tris, size, vol, wall, ew = _table_cells(r)
        parts = [fmt]
        for text, shown in ((f"{tris} triangles", tris), (f"{size} mm", size), (f"{vol} cm3", vol),
                            (f"min wall {wall} mm", wall)):
            if shown != "-":
                parts.append(text)
        print(f"{r.path}: {verdict}  {'  '.join(parts)}  E/W {ew}", file=out)
        for f in _shown_findings(r):
            message = " ".join(f"{f.message}{_where(f)}".split())  # one line, whatever the message holds
            print(f"{r.path}: {f.severity} {f.code}: {message}", file=out)


def render_table(reports: Sequence[Report], *, console: Any = None) -> None:
    """Print the human summary: one row per file, then each file's findings.

    The table fits the console's width (``COLUMNS``): a long path loses its
    middle, never its file name; no other cell is cut. Where it cannot fit,
    each file gets one line instead. Uses rich (imported here, so JSON-only
    runs never load it).
    """
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table
    from rich.text import Text

    con = console or Console(highlight=False, soft_wrap=False)
    style = {"printable": "green", "not printable": "red", "unreadable": "magenta"}
    ellipsis = "\u2026" if "utf" in (con.encoding or "").lower() else "..."
    rows = [_table_cells(r) for r in reports]
    widths = _table_widths(rows, con.width, ellipsis)
    if widths is None:
        con.print(Text("saucerfab check", style="italic"))
        for r, cells in zip(reports, rows):
            con.print(_file_line(r, cells, style[r.verdict]), soft_wrap=True)
    else:
        table = Table(title="saucerfab check", show_lines=False, padding=(0, 1), show_edge=True)
        for (col, just), width in zip(_TABLE_COLUMNS, widths):
            table.add_column(col, justify=just, width=width)  # type: ignore[arg-type]
        for r, cells in zip(reports, rows):
            table.add_row(
                Text(shorten_middle(r.path, widths[0], ellipsis)),
                cells[1],
                Text(r.verdict, style=style[r.verdict]),
                *cells[3:],
            )
        con.print(table)
    sev_style = {"error": "red", "warning": "yellow", "info": "dim"}
    for r in reports:
        shown = _shown_findings(r)
        if not shown:
            continue
        con.print(Text.assemble((r.path, "bold"), "  ", r.verdict), soft_wrap=True)  # the path whole
        for f in shown:
            con.print(f"  [{sev_style[f.severity]}]{f.severity:7s}[/] {f.code}: {escape(f.message)}{escape(_where(f))}")
