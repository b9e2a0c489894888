"""numba tokenizer/parser for the common large OBJ: the fast path of :func:`saucerfab.check.readers.obj.read_obj`.

The numpy/regex code in :mod:`saucerfab.check.readers.obj` is the
reference and reads small files (importing numba costs about 0.7 s). Past
:data:`saucerfab.check.readers.obj.FAST_OBJ_BYTES` ``read_obj`` tries :func:`parse` first, which reads,
in two passes over the bytes (count, then fill):

- ``v x y z [w | r g b [a]]`` (3 to 7 numbers) and ``vt u v [w]`` (2 or 3),
  numbers separated by blanks, optional trailing blanks;
- ``f`` lines that all have the first face's corner count (3..16) and index
  form (``v``, ``v/t``, ``v/t/n``, ``v//n``), indices positive or relative
  (``-1``: the last defined so far, as streaming writers write them);
- ``usemtl`` and ``mtllib`` payloads (their positions), and whether any
  ``l p curv surf curv2`` statement is present (the ``ignored_content`` note).

Statement lines are recognised exactly as the reference's regexes do
(``^[ \\t]*keyword[ \\t]+`` then up to the first CR or LF). Plain decimal
numbers (``[+-]digits[.digits][e[+-]digits]``) whose significand fits in 2^53
with a power of ten up to 1e22 are computed exactly (Clinger's fast path: one
correctly rounded IEEE multiply or divide, the same bits as ``float()``);
any other token of number-like characters is handed back and converted by
numpy as the reference does. Anything else - a comment or other byte in a
``v``/``vt`` line, a face outside the bulk form, an index of 0 or past the
vertices, a count over the caps - returns ``None`` and the reference reads
the file from the start, so its answers (and its errors) are the reference's.
The caps are checked from the first pass's counts before any large array
is made.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from saucerfab.check.limits import Limits

_POW10 = np.array([10.0**i for i in range(23)], dtype=np.float64)  # all exact doubles

# pass-1 result slots
_NV, _NVT, _NF, _NU, _NM, _OTHER, _FIRST_F = range(7)

# character classes: 1 digit, 2 '.', 3 sign, 4 'e'/'E', 5 other number-like (letters, '_'): a "hard" token
_CLS = np.zeros(256, dtype=np.uint8)
_CLS[ord("0"): ord("9") + 1] = 1
_CLS[ord(".")] = 2
_CLS[ord("+")] = 3
_CLS[ord("-")] = 3
for _c in b"abcdfghijklmnopqrstuvwxyzABCDFGHIJKLMNOPQRSTUVWXYZ_":
    _CLS[_c] = 5
_CLS[ord("e")] = 4
_CLS[ord("E")] = 4


@njit(cache=True, nogil=True, inline="always")
def _is_blank(c: int) -> bool:
    return c == 32 or c == 9


@njit(cache=True, nogil=True)
def _keyword(a: np.ndarray, i: int, n: int) -> tuple[int, int]:
    """At a line's start ``i``: (statement kind, payload start) or (0, i). Kinds: 1 v, 2 vt, 3 f, 4 usemtl, 5 mtllib, 6 other."""
    while i < n and _is_blank(a[i]):
        i += 1
    j = i
    while j < n and 97 <= a[j] <= 122:
        j += 1
    while j < n and 48 <= a[j] <= 57:  # 'curv2'
        j += 1
    if j >= n or not _is_blank(a[j]) or j == i:
        return 0, i
    ln = j - i
    kind = 0
    c0 = a[i]
    if ln == 1:
        if c0 == 118:  # v
            kind = 1
        elif c0 == 102:  # f
            kind = 3
        elif c0 == 108 or c0 == 112:  # l p
            kind = 6
    elif ln == 2:
        if c0 == 118 and a[i + 1] == 116:
            kind = 2
    elif ln == 4:
        if (c0 == 99 and a[i + 1] == 117 and a[i + 2] == 114 and a[i + 3] == 118) or (
                c0 == 115 and a[i + 1] == 117 and a[i + 2] == 114 and a[i + 3] == 102):
            kind = 6  # curv surf
    elif ln == 5:
        if c0 == 99 and a[i + 1] == 117 and a[i + 2] == 114 and a[i + 3] == 118 and a[i + 4] == 50:
            kind = 6  # curv2
    elif ln == 6:
        if a[i + 1] == 115 and a[i + 2] == 101 and a[i + 3] == 109 and a[i + 4] == 116 and a[i + 5] == 108:
            if c0 == 117:
                kind = 4  # usemtl
        elif c0 == 109 and a[i + 1] == 116 and a[i + 2] == 108 and a[i + 3] == 108 and a[i + 4] == 105 and \
                a[i + 5] == 98:
            kind = 5  # mtllib
    if kind == 0:
        return 0, i
    while j < n and _is_blank(a[j]):
        j += 1
    return kind, j


@njit(cache=True, nogil=True)
def _line_end(a: np.ndarray, i: int, n: int) -> tuple[int, int]:
    """(end of the payload at the first CR/LF, start of the next line)."""
    while i < n and a[i] != 10 and a[i] != 13:
        i += 1
    p = i
    while i < n and a[i] != 10:
        i += 1
    return p, i + 1


@njit(cache=True, nogil=True)
def count_statements(a: np.ndarray) -> np.ndarray:
    """Pass 1: [v, vt, f, usemtl, mtllib lines, any l/p/curv/surf/curv2, first f payload (or -1)]."""
    out = np.zeros(7, dtype=np.int64)
    out[_FIRST_F] = -1
    n = len(a)
    i = 0
    while i < n:
        kind, j = _keyword(a, i, n)
        if kind == 1:
            out[_NV] += 1
        elif kind == 2:
            out[_NVT] += 1
        elif kind == 3:
            if out[_NF] == 0:
                out[_FIRST_F] = j
            out[_NF] += 1
        elif kind == 4:
            out[_NU] += 1
        elif kind == 5:
            out[_NM] += 1
        elif kind == 6:
            out[_OTHER] = 1
        while j < n and a[j] != 10:
            j += 1
        i = j + 1
    return out


@njit(cache=True, nogil=True, inline="always")
def _digits(a: np.ndarray, cls: np.ndarray, i: int, e: int, m: np.uint64, nd: int,
            ndig: int) -> tuple[int, np.uint64, int, int]:
    """The decimal digits from a[i] (before e) appended to the significand ``m``, leading zeros skipped.

    Returns (the position after them, m, significant digits in m, digits read in all); ``nd`` and
    ``ndig`` are the counts so far.
    """
    while i < e and cls[a[i]] == 1:
        d = a[i] - 48
        if nd > 0 or d != 0:
            m = m * np.uint64(10) + np.uint64(d)
            nd += 1
        ndig += 1
        i += 1
    return i, m, nd, ndig


@njit(cache=True, nogil=True, inline="always")
def _number(a: np.ndarray, cls: np.ndarray, s: int, e: int, pow10: np.ndarray) -> tuple[int, float]:
    """Token a[s:e]: (1, value) exactly as float() reads it, (2, 0) for numpy to convert, or (0, 0): bail out."""
    hard = False
    for t in range(s, e):
        c = cls[a[t]]
        if c == 0:
            return 0, 0.0
        if c == 5:
            hard = True
    if hard:
        return 2, 0.0
    i = s
    neg = False
    if cls[a[i]] == 3:
        neg = a[i] == 45
        i += 1
    # m: the significand; nd: its significant digits; ndig: digits in all
    i, m, nd, ndig = _digits(a, cls, i, e, np.uint64(0), 0, 0)
    scale = 0
    if i < e and cls[a[i]] == 2:
        i, m, nd, ndig_all = _digits(a, cls, i + 1, e, m, nd, ndig)
        scale = ndig - ndig_all  # one decimal place down per digit after the point
        ndig = ndig_all
    if ndig == 0 or nd > 19:
        return 2, 0.0
    if i < e:
        if cls[a[i]] != 4:
            return 2, 0.0
        i += 1
        eneg = False
        if i < e and cls[a[i]] == 3:
            eneg = a[i] == 45
            i += 1
        if i >= e:
            return 2, 0.0
        x = 0
        while i < e:
            if cls[a[i]] != 1:
                return 2, 0.0
            if x < 100000:
                x = x * 10 + (a[i] - 48)
            i += 1
        scale += -x if eneg else x
    if m == 0:
        v = 0.0
    elif m <= np.uint64(1 << 53) and -22 <= scale <= 22:
        v = float(m)
        if scale < 0:
            v = v / pow10[-scale]
        elif scale > 0:
            v = v * pow10[scale]
    else:
        return 2, 0.0
    return 1, -v if neg else v


@njit(cache=True, nogil=True)
def _grow(h: np.ndarray, nh: int) -> np.ndarray:
    if nh < h.shape[0]:
        return h
    g = np.empty((2 * h.shape[0], 3), dtype=np.int64)
    g[:nh] = h[:nh]
    return g


@njit(cache=True, nogil=True)
def fill(a: np.ndarray, cls: np.ndarray, pow10: np.ndarray, V: np.ndarray, UV: np.ndarray, k: int, per: int,
         slash2: bool, fv: np.ndarray, ft: np.ndarray, fu: np.ndarray, upos: np.ndarray, mpos: np.ndarray):
    """Pass 2. Returns (status, all v lines have 6 numbers, triangles missing their UVs, hard tokens).

    status 0: read; otherwise the reference must read the file (the code
    says why: 1 v/vt line, 2 face form, 3 index range). Hard tokens: rows of
    (start, end, destination): V.ravel() index, -1 - UV.ravel() index, or
    ``-(1 << 62)`` for a number that is only checked.
    """
    n = len(a)
    nv = V.shape[0]
    nvt = UV.shape[0]
    hard = np.empty((1024, 3), dtype=np.int64)
    nh = 0
    iv = 0
    ivt = 0
    itri = 0
    iu = 0
    im = 0
    all6 = True
    dropped = 0
    cur = -1
    idx = np.zeros(48, dtype=np.int64)
    rv = np.zeros(16, dtype=np.int64)
    rt = np.zeros(16, dtype=np.int64)
    i = 0
    while i < n:
        kind, j = _keyword(a, i, n)
        if kind == 1 or kind == 2:
            cnt = 0
            lim = 7 if kind == 1 else 3
            p = j
            while True:
                while p < n and _is_blank(a[p]):
                    p += 1
                if p >= n or a[p] == 10 or a[p] == 13:
                    break
                s = p
                while p < n and not _is_blank(a[p]) and a[p] != 10 and a[p] != 13:
                    p += 1
                if cnt >= lim:
                    return 1, all6, dropped, hard[:nh]
                st, val = _number(a, cls, s, p, pow10)
                if st == 0:
                    return 1, all6, dropped, hard[:nh]
                if kind == 1:
                    dest = iv * 3 + cnt if cnt < 3 else -(1 << 62)
                    if st == 1 and cnt < 3:
                        V[iv, cnt] = val
                else:
                    dest = -1 - (ivt * 2 + cnt) if cnt < 2 else -(1 << 62)
                    if st == 1 and cnt < 2:
                        UV[ivt, cnt] = val
                if st == 2:
                    hard = _grow(hard, nh)
                    hard[nh, 0] = s
                    hard[nh, 1] = p
                    hard[nh, 2] = dest
                    nh += 1
                cnt += 1
            if kind == 1:
                if cnt < 3:
                    return 1, all6, dropped, hard[:nh]
                if cnt != 6:
                    all6 = False
                iv += 1
            else:
                if cnt < 2:
                    return 1, all6, dropped, hard[:nh]
                ivt += 1
            j = p
        elif kind == 3:
            p = j
            for c in range(k):
                if c > 0:
                    if p >= n or not _is_blank(a[p]):
                        return 2, all6, dropped, hard[:nh]
                    while p < n and _is_blank(a[p]):
                        p += 1
                for q in range(per):
                    if q > 0:
                        if p >= n or a[p] != 47:
                            return 2, all6, dropped, hard[:nh]
                        p += 1
                        if q == 1 and slash2:
                            if p >= n or a[p] != 47:
                                return 2, all6, dropped, hard[:nh]
                            p += 1
                    neg = p < n and a[p] == 45  # a relative index: counted back from the last defined
                    if neg:
                        p += 1
                    x = 0
                    s = p
                    while p < n and 48 <= a[p] <= 57:
                        if x < (1 << 56):
                            x = x * 10 + (a[p] - 48)
                        p += 1
                    if p == s:
                        return 2, all6, dropped, hard[:nh]
                    if x >= (1 << 56):  # the reference's int64 may overflow: its line-by-line path decides
                        return 3, all6, dropped, hard[:nh]
                    idx[c * per + q] = -x if neg else x
            while p < n and _is_blank(a[p]):
                p += 1
            if p < n and a[p] != 10 and a[p] != 13:
                return 2, all6, dropped, hard[:nh]
            for c in range(k):  # 0-based: vertices in rv, texture coordinates in rt (-1: one the file lacks)
                x = idx[c * per]
                r = x - 1 if x > 0 else iv + x
                if x == 0 or x > nv or r < 0:
                    return 3, all6, dropped, hard[:nh]
                rv[c] = r
                if per >= 2 and not slash2:
                    t = idx[c * per + 1]
                    if t == 0:
                        return 3, all6, dropped, hard[:nh]
                    r = t - 1 if t > 0 else ivt + t
                    rt[c] = r if 0 <= r < nvt else -1
            for c in range(1, k - 1):
                fv[itri, 0] = rv[0]
                fv[itri, 1] = rv[c]
                fv[itri, 2] = rv[c + 1]
                if per >= 2 and not slash2:
                    t0 = rt[0]
                    t1 = rt[c]
                    t2 = rt[c + 1]
                    if t0 < 0 or t1 < 0 or t2 < 0:
                        ft[itri, 0] = -1
                        ft[itri, 1] = -1
                        ft[itri, 2] = -1
                        dropped += 1
                    else:
                        ft[itri, 0] = t0
                        ft[itri, 1] = t1
                        ft[itri, 2] = t2
                else:
                    ft[itri, 0] = -1
                    ft[itri, 1] = -1
                    ft[itri, 2] = -1
                fu[itri] = cur
                itri += 1
            j = p
        elif kind == 4:
            e, _ = _line_end(a, j, n)
            upos[iu, 0] = j
            upos[iu, 1] = e
            cur = iu
            iu += 1
        elif kind == 5:
            if im < mpos.shape[0]:
                e, _ = _line_end(a, j, n)
                mpos[im, 0] = j
                mpos[im, 1] = e
            im += 1
        while j < n and a[j] != 10:
            j += 1
        i = j + 1
    return 0, all6, dropped, hard[:nh]


_FORMS = {"v": (1, False), "v/t": (2, False), "v/t/n": (3, False), "v//n": (2, True)}


def parse(data: bytes, limits: Limits):
    """The reference's parse of ``data`` (see module doc), or ``None``: the reference must read it.

    Returns (V (n,3), has vertex colours, UV (m,2), material names in order
    of first use, fv, ft, fmat, triangles missing UVs, ``f`` lines, any
    ignored content, mtllib payloads (at most 16)).
    """
    a = np.frombuffer(data, np.uint8)
    counts = count_statements(a)
    nv, nvt, nf, nu, nm = (int(x) for x in counts[:5])
    if nv > limits.max_vertices or nvt > limits.max_vertices or nf > limits.max_triangles:
        return None  # refused: the reference says so in its words
    if nf == 0 or nv == 0:
        return None  # not_a_mesh / no_triangles / out of range: the reference's errors
    f0 = int(counts[_FIRST_F])
    e0 = f0
    while e0 < len(data) and data[e0] not in (10, 13):
        e0 += 1
        if e0 - f0 > 4096:
            return None
    first = data[f0:e0].split()
    if not first:
        return None
    t = first[0]
    form = "v//n" if b"//" in t else {0: "v", 1: "v/t", 2: "v/t/n"}.get(t.count(b"/"))
    k = len(first)
    if form is None or not 3 <= k <= 16:
        return None
    per, slash2 = _FORMS[form]
    ntri = nf * (k - 2)
    if ntri > limits.max_triangles or nf * k * per > len(data) or (nv + nvt) * 4 > len(data):
        return None  # the reference refuses, or the lines cannot all be in the bulk form
    V = np.empty((nv, 3), dtype=np.float64)
    UV = np.empty((nvt, 2), dtype=np.float64)
    fv = np.empty((ntri, 3), dtype=np.int64)
    ft = np.empty((ntri, 3), dtype=np.int64)
    fu = np.empty(ntri, dtype=np.int64)
    upos = np.empty((nu, 2), dtype=np.int64)
    mpos = np.empty((min(nm, 16), 2), dtype=np.int64)
    status, all6, dropped, hard = fill(a, _CLS, _POW10, V, UV, k, per, slash2, fv, ft, fu, upos, mpos)
    if status != 0:
        return None
    if len(hard):
        try:
            vals = np.array([data[s:e] for s, e in hard[:, :2].tolist()], dtype=np.float64)
        except (ValueError, OverflowError):
            return None  # the reference raises "malformed" in its words
        dest = hard[:, 2]
        sel = dest >= 0
        V.reshape(-1)[dest[sel]] = vals[sel]
        sel = (dest < 0) & (dest > -(1 << 62))
        UV.reshape(-1)[-1 - dest[sel]] = vals[sel]
    mat_names: list[bytes] = []
    lut = np.empty(nu + 1, dtype=np.int64)
    lut[nu] = -1
    for ui, (s, e) in enumerate(upos.tolist()):
        name = data[s:e].strip()
        if name not in mat_names:
            mat_names.append(name)
        lut[ui] = mat_names.index(name)
    fmat = lut[fu]
    mtllibs = [data[s:e] for s, e in mpos.tolist()]
    return V, bool(all6), UV, mat_names, fv, ft, fmat, int(dropped), nf, bool(counts[_OTHER]), mtllibs


def warm_up() -> list[str]:
    """Compile (or load from numba's cache) the parser on a tiny OBJ; return its names."""
    data = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl m\nmtllib a.mtl\nf 1/1 2/1 3/1\n"
    from saucerfab.check.limits import DEFAULT_LIMITS

    parse(data, DEFAULT_LIMITS)
    return ["obj_fast.count_statements", "obj_fast.fill"]
