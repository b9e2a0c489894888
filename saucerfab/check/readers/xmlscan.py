"""Cheap scans of XML bytes before parsing: nesting depth, the root's namespaces, the declared encoding.

They read the bytes with numpy or a regex, never an XML parser, so a part
that would be costly to parse (200,000 nested elements) is judged in
milliseconds first. Used by the 3MF reader on every model part.
"""

from __future__ import annotations

import re

import numpy as np

_START_TAG = re.compile(rb"<(?![?!])[^\s/>]+((?:\s+[^\s=/>]+\s*=\s*(?:\"[^\"]*\"|'[^']*'))*)\s*/?>")
_XMLNS = re.compile(rb"""\sxmlns(?::([^\s=]+))?\s*=\s*(?:"([^"]*)"|'([^']*)')""")
_ENCODING = re.compile(rb"""^<\?xml[^>]*?\sencoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")
_COMMENT_OR_CDATA = re.compile(rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>", re.S)


def xml_too_deep(data: bytes, limit: int) -> int | None:
    """The nesting depth of ``data`` if it is over ``limit``, else None, without parsing it.

    A numpy pass over the ``<`` positions: ``</`` closes, ``<?``/``<!``
    neither, ``<name .../>`` neither, any other ``<`` opens (comments and
    CDATA sections are cut out first). An attribute value holding ``>``
    can only make the estimate deeper, never shallower, and no real 3MF
    comes near the limit. Cost: a few milliseconds per megabyte.
    """
    if data.count(b"<") <= limit:
        return None
    if b"<!--" in data or b"<![CDATA[" in data:
        data = _COMMENT_OR_CDATA.sub(b"", data)
    buf = np.frombuffer(data, np.uint8)
    lt = np.flatnonzero(buf == 60)
    if len(lt) <= limit:
        return None
    gt = np.flatnonzero(buf == 62)
    nxt = buf[np.minimum(lt + 1, len(buf) - 1)]
    close = np.searchsorted(gt, lt)
    before_gt = np.where(close < len(gt), buf[gt[np.minimum(close, len(gt) - 1)] - 1], 0)
    step = np.where(nxt == 47, -1, np.where((nxt == 63) | (nxt == 33) | (before_gt == 47), 0, 1)).astype(np.int32)
    depth = int(np.cumsum(step).max())
    return depth if depth > limit else None


def root_namespaces(data: bytes) -> dict[str, str]:
    """Prefix -> namespace URI declared on the root element's start tag ('' for the default namespace).

    ElementTree keeps no prefixes, and ``requiredextensions`` and metadata
    names are written with them; the root's start tag is read with a regex
    after skipping the XML declaration, comments and processing instructions.
    """
    head = data[: 1 << 16]
    pos = 0
    while True:
        pos = head.find(b"<", pos)
        if pos < 0:
            return {}
        if head.startswith(b"<!--", pos):
            end = head.find(b"-->", pos)
        elif head.startswith(b"<?", pos):
            end = head.find(b"?>", pos)
        elif head.startswith(b"<!", pos):
            end = head.find(b">", pos)
        else:
            break
        if end < 0:
            return {}
        pos = end + 1
    m = _START_TAG.match(head, pos)
    if m is None:
        return {}
    out: dict[str, str] = {}
    for x in _XMLNS.finditer(m.group(0)):
        prefix = (x.group(1) or b"").decode("utf-8", "replace")
        uri = (x.group(2) if x.group(2) is not None else x.group(3) or b"").decode("utf-8", "replace")
        out[prefix] = uri
    return out


def declared_encoding(data: bytes) -> str | None:
    """The encoding an XML declaration names (None: none named); a BOM other than UTF-8's counts as its encoding."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    elif data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "UTF-16"
    elif data[:4] in (b"\x00\x00\xfe\xff", b"\xff\xfe\x00\x00"):
        return "UTF-32"
    m = _ENCODING.match(data[:512])
    return m.group(1).decode("ascii") if m else None
