"""The 3MF reader's fast path: bulk blocks read with numpy before the XML parser sees the rest.

``<vertices>``, ``<triangles>`` and ``<m:texture2dgroup>`` contents - the
bulk of any real model - are cut out of a model part when they match the
strict grammar of :mod:`.threemf_grammar`; their numbers are read with
numpy (or, for large blocks, by the numba parser :mod:`.threemf_fast`), and
each block is replaced by a marker element before defusedxml parses the
rest. A block that matches the grammar means exactly what an XML parser
would read from it, so this changes speed, not meaning; anything else is
left in place for the ordinary element-by-element path.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from saucerfab.check.jit import have_numba
from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.meshdata import ReadError
from saucerfab.check.readers.threemf_grammar import ATTR, END, TRI_ATTR_ORDER, WS, element_res

_BLOCK_START = re.compile(
    rb"<(vertices|triangles)>|<([A-Za-z_][A-Za-z0-9_.-]*:)?texture2dgroup(" + WS + rb'[^<>]*)?(?<!/)>'
)


def _split_elements(content: bytes, tag: bytes) -> tuple[list[bytes], list[bytes]] | None:
    """Attribute values and names of a block made only of ``<tag a="..." b="..."/>`` elements.

    Every element must carry the same attributes in the same order, with
    double quotes and XML whitespace; then splitting at the quotes gives
    separators and values, and the separators take only a handful of
    distinct forms, each checked against the grammar once. Anything else
    (comments, CDATA, entities, other elements, varying attributes) returns
    None and the block is left to the XML parser.
    """
    parts = content.split(b'"')
    if len(parts) % 2 == 0:
        return None
    seps, vals = parts[0::2], parts[1::2]
    if not vals:
        return ([], []) if not content.strip(b" \t\r\n") else None
    first_re, next_re = element_res(tag)
    m = first_re.fullmatch(seps[0])
    if m is None:
        return None
    names = [m.group(1)]
    k = 1
    while k < len(seps) - 1:
        a = ATTR.fullmatch(seps[k])
        if a is None:
            break
        names.append(a.group(1))
        k += 1
    n = len(vals) // k
    if n * k != len(vals) or len(set(names)) != k or END.fullmatch(seps[-1]) is None:
        return None
    for sep in set(seps[k : n * k : k]):
        m = next_re.fullmatch(sep)
        if m is None or m.group(1) != names[0]:
            return None
    for j in range(1, k):
        for sep in set(seps[j : n * k : k]):
            a = ATTR.fullmatch(sep)
            if a is None or a.group(1) != names[j]:
                return None
    return vals, names


@dataclass
class Block:
    """One bulk block read on the fast path; a ``<sfblk i=.../>`` marker stands in its place."""

    kind: str  # vertices | triangles | tex2coord
    values: Any  # ndarray, or (ndarray tri, tuple names) for triangles


def fast_blocks(data: bytes, marker_ns: str, limits: Limits) -> tuple[bytes, list[Block]]:
    """Cut strictly-formed bulk blocks out of ``data``; return the skeleton and the parsed blocks.

    Element counts are bounded before any block's numbers are converted: a
    part may define objects it never instances, so the instancing caps alone
    would not bound this allocation.
    """
    pieces: list[bytes] = []
    blocks: list[Block] = []
    pos = 0
    n_vert = n_uv = n_tri = 0
    at = 0
    fast = _use_fast(len(data))
    while (m := _BLOCK_START.search(data, at)) is not None:  # from the last block's end: blocks are not rescanned
        start = at = m.end()
        if m.group(1) is not None:
            kind = m.group(1).decode()
            end = data.find(b"</" + m.group(1) + b">", start)
        else:
            kind = "tex2coord"
            prefix = m.group(2) or b""
            end = data.find(b"</" + prefix + b"texture2dgroup>", start)
        if end < 0:
            continue
        if len(blocks) >= 3 * limits.max_parts:  # each costs its own Python and numpy calls (~0.1 ms)
            raise ReadError(
                "over_check_limit",
                f"the 3MF model holds over {3 * limits.max_parts:,} vertex, triangle and texture-coordinate blocks "
                f"(3 per part, Limits.max_parts); {raise_hint()}",
            )
        content = data[start:end]
        if kind == "vertices":
            n_vert += content.count(b"<vertex")
        elif kind == "triangles":
            n_tri += content.count(b"<triangle")
        else:
            n_uv += content.count(b"tex2coord")
        if max(n_vert, n_uv) > limits.max_vertices or n_tri > limits.max_triangles:
            raise ReadError(
                "over_check_limit",
                f"the 3MF model lists over {limits.max_vertices:,} vertices (or texture coordinates) or "
                f"{limits.max_triangles:,} triangles, the checker's limits (Limits.max_vertices, "
                f"Limits.max_triangles); {raise_hint(max(n_tri, -(-max(n_vert, n_uv) // 3)))}",
            )
        parsed = _parse_block(kind, content, m.group(2) or b"", fast)
        if parsed is None:
            continue
        pieces.append(data[pos:start])
        pieces.append(b'<sfblk xmlns="%s" i="%d"/>' % (marker_ns.encode(), len(blocks)))
        blocks.append(Block(kind, parsed))
        pos = at = end
    if not blocks:
        return data, []
    pieces.append(data[pos:])
    return b"".join(pieces), blocks


def _uniform_spans(content: bytes, tag: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[bytes]] | None:
    """Value spans of a block of identically formatted ``<tag a="..." .../>`` elements, checked with numpy.

    The common case of one writer's output: every separator between values
    at the same attribute slot is the same bytes. Each distinct separator is
    checked once against the grammar, and all others are compared to it as
    byte arrays, with no Python object per value. Returns (bytes, value
    starts, value ends, attribute names), or None to use the general path.
    """
    buf = np.frombuffer(content, np.uint8)
    q = np.flatnonzero(buf == 34)  # '"'
    if len(q) == 0 or len(q) % 2:
        return None
    st, en = q[0::2] + 1, q[1::2]
    nv = len(st)
    sep_st = np.concatenate([[0], en[:-1] + 1])  # separator before value i: [sep_st[i], st[i] - 1)
    sep_en = st - 1
    first_re, next_re = element_res(tag)
    m = first_re.fullmatch(content[: q[0]])
    if m is None:
        return None
    names = [m.group(1)]
    k = 1
    while k < nv:
        a = ATTR.fullmatch(content[sep_st[k] : sep_en[k]])
        if a is None:
            break
        names.append(a.group(1))
        k += 1
    n = nv // k
    if n * k != nv or len(set(names)) != k or END.fullmatch(content[int(en[-1]) + 1 :]) is None:
        return None
    for j in range(k):
        idx = np.arange(j, nv, k)[1:] if j == 0 else np.arange(j, nv, k)
        if not len(idx):
            continue
        s0, ln = sep_st[idx], sep_en[idx] - sep_st[idx]
        width = int(ln[0])
        if (ln != width).any():
            return None  # formatting varies: the general path checks each distinct separator
        rep = content[int(s0[0]) : int(s0[0]) + width]
        mm = (next_re if j == 0 else ATTR).fullmatch(rep)
        if mm is None or mm.group(1) != names[j]:
            return None
        for c in range(width):  # column by column: O(values) memory
            if (buf[s0 + c] != rep[c]).any():
                return None
    return buf, st, en, names


def _span_ints(buf: np.ndarray, st: np.ndarray, en: np.ndarray) -> np.ndarray | None:
    """Non-negative decimal integers in the spans (Horner's rule column by column), or None."""
    ln = en - st
    if len(ln) and (ln.min() < 1 or ln.max() > 18):
        return None
    acc = np.zeros(len(st), dtype=np.int64)
    for c in range(int(ln.max()) if len(ln) else 0):
        live = c < ln
        d = buf[np.where(live, st + c, 0)].astype(np.int64) - 48
        if ((d < 0) | (d > 9))[live].any():
            return None
        acc = np.where(live, acc * 10 + d, acc)
    return acc


#: a model part at least this long has its blocks of FAST_3MF_BLOCK_BYTES or more offered to the numba
#: parser (threemf_fast) first: importing numba and its first call cost ~1.1 s, what the code below spends
#: on ~25 MB of blocks (and check_mesh loads numba itself from ~200k triangles). Once that parser is loaded
#: in the process, any part's blocks are offered to it.
FAST_3MF_PART_BYTES = 24 << 20
FAST_3MF_BLOCK_BYTES = 256 << 10


def _use_fast(part_bytes: int) -> bool:
    loaded = sys.modules.get("saucerfab.check.readers.threemf_fast")
    return (part_bytes >= FAST_3MF_PART_BYTES and have_numba()) or (loaded is not None and loaded.ready())


def _parse_block(kind: str, content: bytes, prefix: bytes, fast: bool = False) -> Any:
    """The numbers of one bulk block, or None to leave it to the XML parser (``fast``: try threemf_fast first)."""
    if fast and len(content) >= FAST_3MF_BLOCK_BYTES:
        from saucerfab.check.readers.threemf_fast import parse_block as parse_fast

        got = parse_fast(kind, content, prefix)  # None where it leaves the block to the code below
        if got is not None:
            return got
    if b"&" in content or b"<!" in content or b"<?" in content:
        return None
    tag = {"vertices": b"vertex", "triangles": b"triangle", "tex2coord": prefix + b"tex2coord"}[kind]
    fast = _uniform_spans(content, tag)
    if fast is not None:
        buf, st, en, names = fast
        want = {"vertices": [b"x", b"y", b"z"], "tex2coord": [b"u", b"v"]}.get(kind)
        if want is not None:
            if sorted(names) == want:
                try:  # the structure is checked; the values between the quotes are all that is left
                    arr = np.array(content.split(b'"')[1::2], dtype=np.float64).reshape(-1, len(want))
                except ValueError:
                    return None
                return arr[:, [names.index(c) for c in want]]
        elif set(names) <= set(TRI_ATTR_ORDER) and {b"v1", b"v2", b"v3"} <= set(names):
            ints = _span_ints(buf, st, en)
            if ints is not None:
                return ints.reshape(-1, len(names)), tuple(names)
    split = _split_elements(content, tag)
    if split is None:
        return None
    vals, names = split
    try:
        if kind == "vertices":
            if sorted(names) != [b"x", b"y", b"z"] and names:
                return None
            arr = np.array(vals, dtype=np.float64).reshape(-1, 3)
            return arr[:, [names.index(c) for c in (b"x", b"y", b"z")]] if names else arr
        if kind == "tex2coord":
            if sorted(names) != [b"u", b"v"] and names:
                return None
            arr = np.array(vals, dtype=np.float64).reshape(-1, 2)
            return arr[:, [names.index(c) for c in (b"u", b"v")]] if names else arr
        if names and (not set(names) <= set(TRI_ATTR_ORDER) or not {b"v1", b"v2", b"v3"} <= set(names)):
            return None
        if any(c not in b"0123456789" for v in vals[:1] for c in v):
            return None  # integers only (no sign, no spaces); checked on one value, numpy checks the rest
        arr = np.array(vals, dtype=np.int64).reshape(-1, max(len(names), 1))
    except (ValueError, OverflowError):
        return None  # not plain numbers: the XML path reports it properly
    if arr.size and arr.min() < 0:
        return None
    return arr, tuple(names)
