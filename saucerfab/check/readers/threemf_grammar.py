"""The strict grammar of 3MF bulk blocks that both bulk parsers accept.

A ``<vertices>``, ``<triangles>`` or ``<m:texture2dgroup>`` block made only
of elements ``<tag name="value" .../>`` (double quotes, XML whitespace, every
element with the same attribute names in the same order, no comments,
entities or CDATA) means exactly what an XML parser would read from it. The
numpy reader (:mod:`.threemf_blocks`) and the numba reader
(:mod:`.threemf_fast`) both check blocks against these patterns, so they
accept the same blocks.
"""

from __future__ import annotations

import re

#: XML whitespace
WS = rb"[ \t\r\n]"
#: an attribute name and its '=' (group 1: the name)
NAME = rb"([A-Za-z][A-Za-z0-9]*)="
#: a triangle's attributes, in the order of the reader's (m, 7) triangle rows
TRI_ATTR_ORDER = (b"v1", b"v2", b"v3", b"pid", b"p1", b"p2", b"p3")
#: the separator between two attribute values of one element: whitespace, then the next name
ATTR = re.compile(WS + rb"+" + NAME)
#: the end of the last element (and the block)
END = re.compile(WS + rb"*/>" + WS + rb"*")
_ELEMENT_RES: dict[bytes, tuple[re.Pattern[bytes], re.Pattern[bytes]]] = {}


def element_res(tag: bytes) -> tuple[re.Pattern[bytes], re.Pattern[bytes]]:
    """(first element's opening up to its first attribute name, the same after a previous element's '/>')."""
    res = _ELEMENT_RES.get(tag)
    if res is None:
        t = re.escape(tag)
        res = (re.compile(WS + rb"*<" + t + WS + rb"+" + NAME),
               re.compile(WS + rb"*/>" + WS + rb"*<" + t + WS + rb"+" + NAME))
        _ELEMENT_RES[tag] = res
    return res
