"""numba parser for large 3MF bulk blocks: the fast path of :func:`saucerfab.check.readers.threemf_blocks._parse_block`.

The numpy code in :mod:`saucerfab.check.readers.threemf_blocks` (``_uniform_spans``,
``_span_ints``, ``_split_elements``) is the reference and reads small blocks
(importing numba costs about 0.7 s). A ``<vertices>``, ``<triangles>`` or
``<m:texture2dgroup>`` block of at least
:data:`saucerfab.check.readers.threemf_blocks.FAST_3MF_BLOCK_BYTES` is offered to
:func:`parse_block` first, which reads it in one pass over the bytes if it is
exactly the reference's grammar, element after element::

    WS* '<' tag (WS+ name '="' value '"'){k} WS* '/>'   ... then WS* at the end

with ``tag`` ``vertex``, ``triangle`` or ``<prefix>tex2coord``, WS one of
space, tab, CR, LF, and every element carrying the first element's
attribute names in the first element's order (the names as the reference
accepts them: ``x y z`` / ``u v`` in any order, or ``v1 v2 v3`` plus any of
``pid p1 p2 p3``, each once). Triangle values are 1 to 18 decimal digits.
Coordinates go through obj_fast's number parser: plain decimals are computed
exactly (the same bits as ``float()``); other tokens made only of
number-like characters (``inf``, ``1_0``, 25 digits ...) are converted by
numpy as the reference converts them. Anything else - a comment, an entity,
CDATA, single quotes, a blank inside a value, a missing or extra attribute,
a value numpy cannot read - returns ``None``, and the reference reads the
block, so its answers (and its verdicts) are the reference's.

The element count is bounded before this is called (``fast_blocks`` checks
it against ``Limits``); the arrays made here are sized by the count of
``<tag`` in the block, which that check bounds.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from saucerfab.check.readers.obj_fast import _CLS, _POW10, _grow, _number
from saucerfab.check.readers.threemf_grammar import ATTR, TRI_ATTR_ORDER, element_res

_WANT = {"vertices": (b"x", b"y", b"z"), "tex2coord": (b"u", b"v")}


@njit(cache=True, nogil=True, inline="always")
def _is_ws(c: int) -> bool:
    return c == 32 or c == 9 or c == 13 or c == 10


@njit(cache=True, nogil=True)
def scan(a: np.ndarray, tag: np.ndarray, names: np.ndarray, name_off: np.ndarray, col: np.ndarray, ints: bool,
         cls: np.ndarray, pow10: np.ndarray, out_f: np.ndarray, out_i: np.ndarray):
    """Read the block ``a`` into ``out_f`` (coordinates) or ``out_i`` (``ints``: triangle values).

    Returns (status, elements read, hard tokens): status 0 when the whole
    block is in the grammar and fits in the arrays' rows, else 1.
    Hard tokens: rows of (start, end, ``out_f.ravel()`` index) for numpy.
    """
    n = len(a)
    cap = out_i.shape[0] if ints else out_f.shape[0]
    nt = len(tag)
    k = len(name_off) - 1
    hard = np.empty((256, 3), dtype=np.int64)
    nh = 0
    e = 0
    p = 0
    while True:
        while p < n and _is_ws(a[p]):
            p += 1
        if p >= n:
            break
        if e >= cap or a[p] != 60 or p + 1 + nt > n:  # '<'
            return 1, e, hard[:nh]
        p += 1
        for t in range(nt):
            if a[p + t] != tag[t]:
                return 1, e, hard[:nh]
        p += nt
        for j in range(k):
            if p >= n or not _is_ws(a[p]):
                return 1, e, hard[:nh]
            while p < n and _is_ws(a[p]):
                p += 1
            s0 = name_off[j]
            ln = name_off[j + 1] - s0
            if p + ln + 2 > n:
                return 1, e, hard[:nh]
            for t in range(ln):
                if a[p + t] != names[s0 + t]:
                    return 1, e, hard[:nh]
            p += ln
            if a[p] != 61 or a[p + 1] != 34:  # '="'
                return 1, e, hard[:nh]
            p += 2
            s = p
            while p < n and a[p] != 34:
                p += 1
            if p >= n:
                return 1, e, hard[:nh]
            c = col[j]
            if ints:
                if p - s < 1 or p - s > 18:
                    return 1, e, hard[:nh]
                x = 0
                for t in range(s, p):
                    d = a[t] - 48
                    if d < 0 or d > 9:
                        return 1, e, hard[:nh]
                    x = x * 10 + d
                out_i[e, c] = x
            else:
                st, val = _number(a, cls, s, p, pow10)
                if st == 0:
                    return 1, e, hard[:nh]
                if st == 1:
                    out_f[e, c] = val
                else:
                    hard = _grow(hard, nh)
                    hard[nh, 0] = s
                    hard[nh, 1] = p
                    hard[nh, 2] = e * out_f.shape[1] + c
                    nh += 1
            p += 1  # the closing quote
        while p < n and _is_ws(a[p]):
            p += 1
        if p + 1 >= n or a[p] != 47 or a[p + 1] != 62:  # '/>'
            return 1, e, hard[:nh]
        p += 2
        e += 1
    return 0, e, hard[:nh]


def _names(content: bytes, tag: bytes) -> list[bytes] | None:
    """The first element's attribute names, found as the reference finds them (its regexes), or None."""
    first_re, _ = element_res(tag)
    q = content.find(b'"')
    if q < 0:
        return None
    m = first_re.fullmatch(content, 0, q)
    if m is None:
        return None
    names = [m.group(1)]
    close = content.find(b'"', q + 1)
    while close >= 0 and len(names) <= len(TRI_ATTR_ORDER):
        q = content.find(b'"', close + 1)
        if q < 0:
            break
        a = ATTR.fullmatch(content, close + 1, q)
        if a is None:
            break
        names.append(a.group(1))
        close = content.find(b'"', q + 1)
    return names if close >= 0 else None


def parse_block(kind: str, content: bytes, prefix: bytes) -> Any:
    """What the reference's ``_parse_block(kind, content, prefix)`` returns, or None: let the reference read it.

    Only None where the reference would return an array: a None here is never
    an answer, only a hand-over.
    """
    tag = {"vertices": b"vertex", "triangles": b"triangle", "tex2coord": prefix + b"tex2coord"}[kind]
    names = _names(content, tag)
    if names is None or len(set(names)) != len(names):
        return None
    want = _WANT.get(kind)
    if want is not None:
        if sorted(names) != sorted(want):
            return None
        col = np.array([want.index(c) for c in names], dtype=np.int64)
    else:
        if not set(names) <= set(TRI_ATTR_ORDER) or not {b"v1", b"v2", b"v3"} <= set(names):
            return None
        col = np.arange(len(names), dtype=np.int64)
    k = len(names)
    # rows for the most elements the bytes can hold (the shortest element has one-byte values); pages never
    # written are never touched, and the arrays are cut to the elements read (fast_blocks has bounded
    # their count against Limits)
    cap = len(content) // (3 + len(tag) + sum(len(x) + 5 for x in names)) + 1
    ints = want is None
    out_f = np.empty((0 if ints else cap, k), dtype=np.float64)
    out_i = np.empty((cap if ints else 0, k), dtype=np.int64)
    name_off = np.cumsum([0] + [len(x) for x in names]).astype(np.int64)
    status, count, hard = scan(np.frombuffer(content, np.uint8), np.frombuffer(tag, np.uint8),
                           np.frombuffer(b"".join(names), np.uint8), name_off, col, ints, _CLS, _POW10, out_f, out_i)
    if status != 0 or count == 0:
        return None
    if ints:
        out_i.resize((count, k), refcheck=False)  # in place (a realloc): a fresh array, as the reference's
        return out_i, tuple(names)
    out_f.resize((count, k), refcheck=False)
    if len(hard):
        try:
            vals = np.array([content[s:e] for s, e in hard[:, :2].tolist()], dtype=np.float64)
        except (ValueError, OverflowError):
            return None  # the reference decides (and the XML path words the error)
        out_f.reshape(-1)[hard[:, 2]] = vals
    return out_f


def ready() -> bool:
    """Whether the scanner is loaded in this process (then even a small block is worth it)."""
    return bool(scan.signatures)


def warm_up() -> list[str]:
    """Compile (or load from numba's cache) the scanner on tiny blocks; return its name."""
    parse_block("vertices", b'<vertex x="1" y="2.5" z="inf"/>', b"")
    parse_block("triangles", b'<triangle v1="0" v2="1" v3="2"/>', b"")
    return ["threemf_fast.scan"]
