"""Wavefront OBJ reader, with its MTL material library and textures.

Statement lines are counted before any list of them is made, exactly as the
parser will match them (any run of blanks may lead a line), so a file of a
billion ``v`` lines is refused by its count, not by running out of memory.
The common layouts (every ``f`` with the same ``a/b/c`` form: triangles,
quads or polygons of mixed sizes, positive or relative indices) are read in
bulk with numpy; anything else (mixed forms, comments after faces, an index
out of range) takes a line-by-line path, which range-checks each index as
it reads it (0 is not an OBJ index). Polygons are fan-triangulated in order.

Colour: ``map_Kd`` textures through ``vt`` coordinates, ``Kd`` material
colours, and the common ``v x y z r g b`` vertex-colour extension. The MTL
file and textures are read only from the OBJ's own folder (no absolute
paths, no ``..``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from saucerfab.check.jit import have_numba
from saucerfab.check.limits import Limits, raise_hint
from saucerfab.check.meshdata import MeshBuilder, MeshData, ReadError, TextureInfo
from saucerfab.check.readers.safe import DiskResources, Resources

_V = re.compile(rb"^[ \t]*v[ \t]+([^\r\n]*)", re.M)
_VT = re.compile(rb"^[ \t]*vt[ \t]+([^\r\n]*)", re.M)
_F_OR_MTL = re.compile(rb"^[ \t]*(f|usemtl)[ \t]+([^\r\n]*)", re.M)
_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+([^\r\n]*)", re.M)
_OTHER = re.compile(rb"^[ \t]*(l|p|curv|surf|curv2)[ \t]", re.M)
_FACE_FORMS = {
    "v": rb"-?[0-9]+",
    "v/t": rb"-?[0-9]+/-?[0-9]+",
    "v/t/n": rb"-?[0-9]+/-?[0-9]+/-?[0-9]+",
    "v//n": rb"-?[0-9]+//-?[0-9]+",
}
MAX_MTL_BYTES = 16 << 20
FAST_OBJ_BYTES = 8 << 20
"""OBJ files this large (after joining continued lines) try the numba parser, :mod:`.obj_fast`, first: below
about 8 MB the 1.5 s of importing numba and loading its kernels in a fresh process outweighs the gain."""
FAST_OBJ_BYTES_WARM = 1 << 20
"""The same once numba has started in this process (:func:`saucerfab.check.jit.numba_started`: a design's quick
verify, an export's verify): loading the parser's cached kernel then takes about 40 ms, and the trial export's
2.9 MB OBJ is read in 20 ms instead of 0.2-0.45 s. Below 1 MB the numpy/regex parser takes less than the load."""


def _try_fast_parser(n_bytes: int) -> bool:
    """Whether :func:`read_obj` tries :mod:`.obj_fast` on a file of ``n_bytes`` (the one place that decides)."""
    from saucerfab.check import jit  # looked up at the call, so a test can stand in for it

    if not have_numba():  # the checker's install without the 'design' extra: the numpy/regex parser reads all
        return False
    return n_bytes >= FAST_OBJ_BYTES or (n_bytes >= FAST_OBJ_BYTES_WARM and jit.numba_started())


@dataclass
class _Material:
    kd: bool = False
    map_kd: str | None = None


_COUNT_CHUNK = 4 << 20


def _count_lines(data: bytes, keyword: bytes, stop: int | None = None) -> int:
    """Lines the parser reads as ``keyword`` statements: ``^[ \t]*keyword[ \t]``, exactly."""
    return _count_statements(data, {keyword: stop})[keyword]


def _count_statements(data: bytes, stops: dict[bytes, int | None]) -> dict[bytes, int]:
    """How many lines the parser reads as each keyword's statements (``^[ \t]*keyword[ \t]``), exactly.

    Without indented lines, ``bytes.count`` of the keyword after a newline
    is exact and fast. Otherwise numpy counts in 4 MB slices, each ending
    at a newline: a keyword followed by a blank counts when the last
    non-blank before it is a newline (or nothing, at a slice's start, which
    is a line's start). A regex would make a match object per line, five
    times slower, and the old count of ``\n v`` missed lines led by two
    blanks. Counting stops once a keyword is past its ``stop`` (the file is
    refused then), so endless indented lines cost one limit's worth.
    """
    if b"\n " not in data and b"\n\t" not in data and data[:1] not in (b" ", b"\t"):
        return {kw: sum(data.count(b"\n" + kw + sep) + (1 if data.startswith(kw + sep) else 0) for sep in (b" ", b"\t"))
                for kw in stops}
    counts = dict.fromkeys(stops, 0)
    codes = {kw: np.frombuffer(kw, np.uint8) for kw in stops}
    pos = 0
    while pos < len(data):
        end = data.rfind(b"\n", pos, pos + _COUNT_CHUNK) + 1 if pos + _COUNT_CHUNK < len(data) else len(data)
        if end <= pos:  # one line longer than a slice: take it whole
            nl = data.find(b"\n", pos + _COUNT_CHUNK)
            end = len(data) if nl < 0 else nl + 1
        a = np.frombuffer(data, np.uint8, count=end - pos, offset=pos)
        blank = (a == 32) | (a == 9)
        nonblank: np.ndarray | None = None
        for kw, code in codes.items():
            k = len(code)
            if len(a) <= k:
                continue
            hit = blank[k:].copy()  # the keyword is followed by a blank...
            for j in range(k):
                hit &= a[j : len(a) - k + j] == code[j]
            cand = np.flatnonzero(hit)
            if not len(cand):
                continue
            if nonblank is None:
                nonblank = np.flatnonzero(~blank)
            before = np.searchsorted(nonblank, cand) - 1  # ...and only blanks lie between it and its line's start
            prev = np.where(before >= 0, nonblank[np.maximum(before, 0)], -1)
            counts[kw] += int(np.count_nonzero((prev < 0) | (a[np.maximum(prev, 0)] == 10)))
        if any(stop is not None and counts[kw] > stop for kw, stop in stops.items()):
            break
        pos = end
    return counts


def _floats(payloads: list[bytes], what: str) -> tuple[np.ndarray, np.ndarray]:
    """Rows of numbers, NaN-padded to the widest, and each row's count."""
    counts = np.fromiter((p.count(b" ") + p.count(b"\t") + 1 for p in payloads), dtype=np.int64, count=len(payloads))
    joined = b" ".join(payloads)
    tokens = joined.split()
    try:
        if len(tokens) == int(counts.sum()) and (counts == counts[0]).all():
            return np.array(tokens, dtype=np.float64).reshape(len(payloads), int(counts[0])), counts
        rows = [p.split(b"#")[0].split() for p in payloads]
        width = max((len(r) for r in rows), default=0)
        out = np.full((len(rows), width), np.nan)
        counts = np.array([len(r) for r in rows], dtype=np.int64)
        for i, r in enumerate(rows):
            if r:
                out[i, : len(r)] = np.array(r, dtype=np.float64)
        return out, counts
    except ValueError:
        raise ReadError("malformed", f"an OBJ '{what}' line has something that is not a number") from None


def read_obj(path: Path, data: bytes, limits: Limits, res: Resources | None = None) -> MeshData:
    """Read an OBJ file's bytes; its MTL and textures come from ``res`` (default: beside ``path``)."""
    res = res or DiskResources(path.parent, limits)
    b = MeshBuilder("obj", limits)
    if b"\\\n" in data or b"\\\r\n" in data:
        # a statement continued on the next line with a trailing backslash (the OBJ spec allows it;
        # Rhino writes long faces so): join the lines first, so every count and parse sees one statement
        data = data.replace(b"\\\r\n", b" ").replace(b"\\\n", b" ")
        b.note("continued_lines", "OBJ statements continued with a trailing backslash were joined")
    parsed = None
    if _try_fast_parser(len(data)):  # the numba parser (obj_fast); None where it leaves the file to _parse
        from saucerfab.check.readers.obj_fast import parse as parse_fast

        parsed = parse_fast(data, limits)
    mtllibs = None
    if parsed is None:
        V, vcol, UV, mat_names, fv, ft, fmat, n_no_uv = _parse(data, limits, b)
    else:
        V, has_vcol, UV, mat_names, fv, ft, fmat, n_no_uv, nf, other, mtllibs = parsed
        b.reserve(len(V), nf, "the OBJ")
        if other:
            b.note("ignored_content", "OBJ points, lines and free-form curves/surfaces were ignored")
        vcol = V if has_vcol else None
    b.reserve(len(V), len(fv), "the OBJ")
    if len(fv) == 0:
        raise ReadError("no_triangles", "the OBJ's faces have fewer than 3 corners")
    if n_no_uv > 0:
        b.note("texcoords_missing",
               f"{n_no_uv:,} triangles name texture coordinates the file does not have (it has {len(UV):,} 'vt' "
               "lines); they are read without texture placement and print uncoloured: re-export with UVs")

    # materials and textures
    mats, failed = _read_mtls(data, res, mtllibs)
    for ref, exc in failed:
        # without its material library an OBJ prints uncoloured: as serious as a missing texture
        status = "unsafe_path" if exc.code == "archive_unsafe_path" else "missing"
        b.texture(f"<mtllib {ref}>", lambda: TextureInfo(name=f"{ref} (material library)", status=status,
                                                         message=f"material library {ref!r}: {exc.message}"))
    m = len(fv)
    corner_uv = None
    face_tex = None
    face_col = np.zeros(m, dtype=bool)
    if vcol is not None:
        face_col[:] = True
        b.colour_kinds.add("vertex")
    for mi, name in enumerate(mat_names):
        mat = mats.get(name.decode("utf-8", "replace"))
        if mat is None:
            continue
        sel = fmat == mi
        if mat.map_kd is not None:
            has_uv = sel & (ft >= 0).all(axis=1)
            if has_uv.any():
                if corner_uv is None:
                    corner_uv = np.full((m, 3, 2), np.nan)
                    face_tex = np.full(m, -1, dtype=np.int32)
                ref = mat.map_kd
                ti = b.texture(ref, lambda: res.texture(ref))
                corner_uv[has_uv] = UV[ft[has_uv]]
                face_tex[has_uv] = ti  # type: ignore[index]
                b.colour_kinds.add("texture")
        elif mat.kd:
            face_col[sel] = True
            b.colour_kinds.add("material")
    b.add(V[:, :3], fv, corner_uv=corner_uv, face_texture=face_tex,
          face_colour=face_col if face_col.any() else None, what="OBJ")
    return b.build(units="millimeter (assumed; OBJ has no units)")


def _parse(data: bytes, limits: Limits, b: MeshBuilder
           ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, list[bytes], np.ndarray, np.ndarray, np.ndarray, int]:
    """The reference parse: (V, vertex colours or None, UV, material names, fv, ft, fmat, triangles missing UVs)."""
    counts = _count_statements(data, {b"v": limits.max_vertices, b"vt": limits.max_vertices, b"f": limits.max_triangles})
    nv, nvt, nf = counts[b"v"], counts[b"vt"], counts[b"f"]
    b.reserve(nv, nf, "the OBJ", at_least=True)  # the counts stop once past a cap
    if nvt > limits.max_vertices:
        raise ReadError("over_check_limit", f"the OBJ has over {limits.max_vertices:,} 'vt' lines "
                                            f"(Limits.max_vertices); {raise_hint()}")
    v_pay = _V.findall(data)
    vt_pay = _VT.findall(data)
    fm = _F_OR_MTL.findall(data)
    if not v_pay and not fm:
        raise ReadError("not_a_mesh", "no OBJ vertex ('v') or face ('f') statements: not an OBJ mesh")
    if _OTHER.search(data):
        b.note("ignored_content", "OBJ points, lines and free-form curves/surfaces were ignored")
    V, vcounts = _floats(v_pay, "v") if v_pay else (np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
    if V.shape[1] < 3 or (vcounts < 3).any():
        raise ReadError("malformed", "an OBJ 'v' line has fewer than 3 coordinates")
    vcol = None
    if V.shape[1] >= 6 and (vcounts == 6).all():
        vcol = V[:, 3:6]
    UV = _floats(vt_pay, "vt")[0][:, :2] if vt_pay else np.zeros((0, 2))
    if UV.shape[1] < 2 and len(UV):
        raise ReadError("malformed", "an OBJ 'vt' line has fewer than 2 coordinates")

    # faces and the material in force for each
    mat_names: list[bytes] = []
    face_pay: list[bytes] = []
    face_mat: list[int] = []
    cur = -1
    for tag, pay in fm:
        if tag == b"usemtl":
            name = pay.strip()
            if name not in mat_names:
                mat_names.append(name)
            cur = mat_names.index(name)
        else:
            face_pay.append(pay)
            face_mat.append(cur)
    if not face_pay:
        raise ReadError("no_triangles", f"the OBJ has {len(V):,} vertices but no faces")
    fv, ft, fmat, n_no_uv = _faces(face_pay, np.array(face_mat, dtype=np.int64), len(V), len(UV), data, limits)
    return V, vcol, UV, mat_names, fv, ft, fmat, n_no_uv


def _faces(
    pay: list[bytes], mat: np.ndarray, nv: int, nvt: int, data: bytes, limits: Limits
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(triangles (m,3) vertex indices, (m,3) uv indices or -1, (m,) material, triangles whose UVs are missing).

    Bulk path: every face has the first face's corner count k (triangles,
    quads...) and index form, and no index is negative; then k-gons are
    fan-triangulated with numpy. Otherwise line by line.
    """
    first = pay[0].split()
    form = None
    if first:
        t = first[0]
        form = "v//n" if b"//" in t else {0: "v", 1: "v/t", 2: "v/t/n"}.get(t.count(b"/"))
    k = len(first)
    if form is not None and 3 <= k <= 16:
        tok = _FACE_FORMS[form]
        one = rb"[ \t]*" + rb"[ \t]+".join([tok] * k) + rb"[ \t]*"
        joined = b"\n".join(pay)
        if b"-" not in joined and re.fullmatch(rb"(?:" + one + rb"\n)*" + one, joined) is not None:
            per = {"v": 1, "v/t": 2, "v/t/n": 3, "v//n": 2}[form]
            try:
                nums = np.array(joined.replace(b"//", b" ").replace(b"/", b" ").split(), dtype=np.int64)
            except (OverflowError, ValueError):
                # an index too large for int64 cannot be in range; the line-by-line path says which face
                return _faces_slow(data, nv, nvt, limits)
            nums = nums.reshape(len(pay), k, per)
            j = np.arange(1, k - 1)
            corners = np.stack([np.zeros_like(j), j, j + 1], axis=1)  # fan: (0, j, j+1)
            fv = (nums[:, :, 0] - 1)[:, corners].reshape(-1, 3)
            if form in ("v/t", "v/t/n"):
                ft = (nums[:, :, 1] - 1)[:, corners].reshape(-1, 3)
            else:
                ft = np.full(fv.shape, -1, dtype=np.int64)
            _check_range(fv, nv, "vertex")
            if form in ("v/t", "v/t/n"):
                _check_range(ft, 1 << 62, "texture coordinate")  # only an index of 0 (-1 here): no OBJ index
            ft, dropped = _drop_missing_uv(ft, nvt)
            return fv, ft, np.repeat(mat, k - 2), dropped
    if form is not None and (got := _faces_mixed(pay, mat, nv, nvt, data, limits, form)) is not None:
        return got
    return _faces_slow(data, nv, nvt, limits)


def _faces_mixed(pay: list[bytes], mat: np.ndarray, nv: int, nvt: int, data: bytes, limits: Limits, form: str
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
    """The bulk path for polygons of mixed sizes and relative (negative) indices; None: the line-by-line path.

    Every face must use ``form`` (the first face's index form) for every
    corner. The result is :func:`_faces_slow`'s, in numpy: Blender writes
    triangles and quads mixed, streaming writers write ``f -3 -2 -1``, and
    the line-by-line path takes ~3 us a corner (a 500,000-triangle soup
    with relative indices: 11 s). Anything the line-by-line path would
    refuse (index 0, out of range, too large) goes back to it, so its
    messages stay the file's.
    """
    tok = _FACE_FORMS[form]
    # line by line: one pattern over all the lines, with a repeat inside a repeat, keeps a backtracking
    # record per corner (~500 MB for 1.5 million corners)
    line = re.compile(rb"[ \t]*" + tok + rb"(?:[ \t]+" + tok + rb")*[ \t]*")
    if not all(line.fullmatch(p) for p in pay):
        return None
    joined = b"\n".join(pay)
    per = {"v": 1, "v/t": 2, "v/t/n": 3, "v//n": 2}[form]
    a = np.frombuffer(joined, np.uint8)
    solid = (a != 32) & (a != 9) & (a != 10)
    word = np.flatnonzero(solid & ~np.concatenate([[False], solid[:-1]]))  # where each corner starts
    k = np.bincount(np.cumsum(a == 10)[word], minlength=len(pay))  # corners per face (line)
    try:
        # parsed in C, no Python object per number (the grammar above admits only integers; one too large for
        # an int64 saturates, and is then out of range: the line-by-line path refuses it by name)
        nums = np.fromstring(joined.replace(b"//", b" ").replace(b"/", b" "), dtype=np.int64, sep=" ")
        nums = nums.reshape(-1, per)
    except ValueError:
        return None
    textured = form in ("v/t", "v/t/n")
    used = nums[:, :2] if textured else nums[:, :1]  # normals are not read (the line-by-line path ignores them)
    if len(nums) != int(k.sum()) or (used == 0).any():
        return None
    vi = nums[:, 0]
    ti = nums[:, 1] if textured else None
    if (used < 0).any():  # relative: counted back from the last v (vt) defined before the face's line
        before = _defined_before_faces(data, len(pay), 4 * (nv + nvt + len(pay)) + 16)
        if before is None:
            return None
        corner_face = np.repeat(np.arange(len(pay)), k)
        vj = np.where(vi > 0, vi - 1, before[0][corner_face] + vi)
        tj = None if ti is None else np.where(ti > 0, ti - 1, before[1][corner_face] + ti)
    else:
        vj = vi - 1
        tj = None if ti is None else ti - 1
    if ((vj < 0) | (vj >= nv)).any():
        return None
    ntri = np.maximum(k - 2, 0)
    total = int(ntri.sum())
    if total > limits.max_triangles:
        raise ReadError("over_check_limit", f"the OBJ's polygons make over {limits.max_triangles:,} triangles "
                                            f"(Limits.max_triangles); {raise_hint(total)}")
    first = np.cumsum(k) - k  # each face's first corner
    tri_face = np.repeat(np.arange(len(pay)), ntri)
    j = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    c0 = first[tri_face]
    fan = (c0, c0 + j, c0 + j + 1)  # (0, j, j+1) of each face
    fv = np.stack([vj[c] for c in fan], axis=1)
    if tj is None:
        ft = np.full(fv.shape, -1, dtype=np.int64)
    else:
        tj = np.where((tj >= 0) & (tj < nvt), tj, nvt)  # nvt: a coordinate the file lacks ("missing")
        ft = np.stack([tj[c] for c in fan], axis=1)
    ft, dropped = _drop_missing_uv(ft, nvt)
    return fv, ft, np.repeat(mat, ntri), dropped


def _defined_before_faces(data: bytes, n_faces: int, max_lines: int) -> tuple[np.ndarray, np.ndarray] | None:
    """For each ``f`` line in order, how many ``v`` and ``vt`` lines precede it; None where it cannot say cheaply.

    Lines are told apart by their first bytes, as the parser's patterns
    match them when no line starts with a blank (otherwise None), and only
    for files of at most ``max_lines`` lines (each costs 8 bytes here).
    """
    if b"\n " in data or b"\n\t" in data or data[:1] in (b" ", b"\t") or data.count(b"\n") > max_lines:
        return None
    a = np.frombuffer(data, np.uint8)
    n = len(a)
    starts = np.concatenate([[0], np.flatnonzero(a == 10) + 1])
    starts = starts[starts < n]

    def at(off: int) -> np.ndarray:
        i = starts + off
        return np.where(i < n, a[np.minimum(i, n - 1)], 10)

    c0, c1, c2 = at(0), at(1), at(2)
    blank1 = (c1 == 32) | (c1 == 9)
    is_v = (c0 == ord("v")) & blank1
    is_vt = (c0 == ord("v")) & (c1 == ord("t")) & ((c2 == 32) | (c2 == 9))
    is_f = (c0 == ord("f")) & blank1
    if int(is_f.sum()) != n_faces:
        return None
    return (np.cumsum(is_v) - is_v)[is_f], (np.cumsum(is_vt) - is_vt)[is_f]


def _drop_missing_uv(ft: np.ndarray, nvt: int) -> tuple[np.ndarray, int]:
    """``ft`` (m, 3) with the rows naming a texture coordinate the file lacks set to -1 (no UVs), and their count.

    Some exporters write ``f 1/1 2/2 3/3`` with no (or too few) ``vt``
    lines. The geometry is whole; only those faces' texture placement is
    missing, which the colour checks report (the faces print uncoloured), so
    it is not a reason to refuse the file.
    """
    bad = ((ft < 0) | (ft >= nvt)).any(axis=1) & (ft != -1).any(axis=1)
    if bad.any():
        ft = ft.copy()
        ft[bad] = -1
    return ft, int(bad.sum())


def _check_range(idx: np.ndarray, n: int, what: str) -> None:
    bad = (idx < 0) | (idx >= n)
    if bad.any():
        f = int(np.flatnonzero(bad.any(axis=1))[0])
        raise ReadError(
            "index_out_of_range",
            f"OBJ face {f} refers to {what} {int(idx[f][bad[f]][0]) + 1} (1-based) but there are {n:,}",
            where={"faces": [f]},
        )


_SEQ = re.compile(rb"^[ \t]*(v|vt|f|usemtl)[ \t]+([^\r\n]*)", re.M)


def _corner_index(text: bytes, seen: int, total: int, nface: int, what: str) -> int:
    """The 0-based index an OBJ corner's ``text`` names, or raise ``index_out_of_range``.

    OBJ counts from 1, and a negative index counts back from the last
    ``what`` defined so far (``seen``); 0 is neither, and must not become
    ``seen + 0`` - the next one, defined later. Indices beyond ``total`` (or
    too large for an int64) are refused here, where the face is known,
    instead of overflowing the array they would go into.
    """
    i = int(text)
    j = i - 1 if i > 0 else seen + i
    if i == 0 or not 0 <= j < total:
        raise ReadError(
            "index_out_of_range",
            f"OBJ face {nface} refers to {what} {str(i)[:40]} but there are {total:,} "
            "(OBJ indices count from 1; negative ones back from the last defined so far)",
        )
    return j


def _faces_slow(data: bytes, nv_total: int, nvt_total: int, limits: Limits
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Sequential parse: mixed polygons, negative (relative) indices, comments, mixed forms.

    Fan triangulation can turn one long line into many triangles, so the
    triangle cap is checked as the list grows, not after.
    """
    fv: list[tuple[int, int, int]] = []
    ft: list[tuple[int, int, int]] = []
    fmat: list[int] = []
    mats: list[bytes] = []
    cur = -1
    nv = nvt = 0
    nface = 0
    for m in _SEQ.finditer(data):
        tag, pay = m.group(1), m.group(2)
        if tag == b"v":
            nv += 1
            continue
        if tag == b"vt":
            nvt += 1
            continue
        if tag == b"usemtl":
            name = pay.strip()
            if name not in mats:
                mats.append(name)
            cur = mats.index(name)
            continue
        corners = pay.split(b"#")[0].split()
        vi: list[int] = []
        ti: list[int] = []
        try:
            for c in corners:
                parts = c.split(b"/")
                vi.append(_corner_index(parts[0], nv, nv_total, nface, "vertex"))
                if len(parts) > 1 and parts[1]:
                    t = int(parts[1])  # a texture coordinate the file lacks is dropped below, not refused
                    if t == 0:  # but 0 is no OBJ index at all
                        _corner_index(parts[1], nvt, nvt_total, nface, "texture coordinate")
                    j = t - 1 if t > 0 else nvt + t
                    ti.append(j if 0 <= j < nvt_total else nvt_total)  # nvt_total: "missing", and fits int64
                else:
                    ti.append(-1)
        except ValueError:
            raise ReadError("malformed", f"OBJ face {nface} has a corner that is not an index: {pay[:60]!r}") from None
        for k in range(1, len(vi) - 1):
            fv.append((vi[0], vi[k], vi[k + 1]))
            ft.append((ti[0], ti[k], ti[k + 1]))
            fmat.append(cur)
        nface += 1
        if len(fv) > limits.max_triangles:
            raise ReadError("over_check_limit", f"the OBJ's polygons make over {limits.max_triangles:,} triangles "
                                                f"(Limits.max_triangles); {raise_hint()}")
    fva = np.array(fv, dtype=np.int64).reshape(-1, 3)
    fta = np.array(ft, dtype=np.int64).reshape(-1, 3)
    _check_range(fva, nv_total, "vertex")
    fta, dropped = _drop_missing_uv(fta, nvt_total)
    fta[~(fta != -1).all(axis=1)] = -1
    return fva, fta, np.array(fmat, dtype=np.int64), dropped


def _read_mtls(data: bytes, res: Resources, refs: list[bytes] | None = None
               ) -> tuple[dict[str, _Material], list[tuple[str, ReadError]]]:
    """Materials from every ``mtllib`` (``refs``: their payloads, if known; read only from beside the OBJ), and the libraries that failed."""
    mats: dict[str, _Material] = {}
    failed: list[tuple[str, ReadError]] = []
    for raw in (_MTLLIB.findall(data) if refs is None else refs)[:16]:
        ref = raw.decode("utf-8", "replace").strip()
        try:
            text = res.read(ref, MAX_MTL_BYTES, "material library").decode("utf-8", "replace")
        except ReadError as exc:
            failed.append((ref, exc))
            continue
        cur: _Material | None = None
        for line in text.splitlines():
            tok = line.split()
            if not tok:
                continue
            key = tok[0].lower()
            if key == "newmtl" and len(tok) > 1:
                cur = mats.setdefault(" ".join(tok[1:]), _Material())
            elif cur is not None and key == "kd" and len(tok) >= 4:
                cur.kd = True
            elif cur is not None and key == "map_kd" and len(tok) > 1:
                cur.map_kd = tok[-1]  # options (-s, -o...) come first; the file name last
    return mats, failed
