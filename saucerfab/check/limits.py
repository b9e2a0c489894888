"""The checker's own limits: what it will read, and how much work it will do.

A print bureau runs ``saucerfab check`` on files from strangers, so every
reader bounds sizes and counts *before* it allocates or decodes anything,
and every geometric check bounds its work. These limits are the checker's,
not the printer's: a printer profile's polygon and file-size limits are
checked separately and give "not printable" findings, while a file over a
checker limit is refused as unreadable (exit 2) with the limit's name in
the message, so the user knows which knob to turn.

The defaults hold every single file to at most 10 s and 1 GiB on the
2-core development machine (issue 16): the worst file within all of them
together - 500,000 triangles as a triangle soup of 1.5 million vertices
with one 8192 x 8192 texture, or padded to 256 MiB, 10,000 parts - took at
most 7.4 s and 823 MiB there with the machine otherwise idle
(``benchmarks/bench_check_hostile.py --large``; the table per limit is in
the check README). An honest mesh costs about 1 GB and 7-15 s per million
triangles on that machine, so a bigger file is refused from its header
(``over_check_limit``, naming ``Limits.max_triangles``), and ``saucerfab
check --max-triangles N`` (``Limits().for_triangles(N)``) raises the caps
for a file one trusts, at that price. A printer profile's own
``max_triangles`` (20 M for the J55) is what the printer takes, judged
separately.

saucerfab's own exports are not a stranger's files: ``saucerfab export``,
``batch``, ``verify`` and the print's report read them with these limits
raised to what the export wrote (:func:`saucerfab.workflow.export_limits`,
:meth:`Limits.raised_to`), so a design at the largest grid is never refused
by a hostile-file budget.

Budgets against amplification (issue 16): what a file *makes* the checker
do is bounded, not only what it holds - bytes inflated from an archive
(absolutely and relative to the archive's size), node visits and instanced
triangles of shared glTF nodes, bytes of glTF buffers, texture pixels
decoded per file, XML elements and JSON values parsed into trees, VRML
tokens, triangle pairs tested for self-intersections. Each is priced before
the work it bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from collections.abc import Sequence
from pathlib import Path
from typing import Any

GIB = 1 << 30
MIB = 1 << 20


@dataclass(frozen=True)
class Limits:
    """Bounds on input size and on checking work.

    Attributes:
        max_file_bytes: largest input file read at all (the mesh file
            itself; it is held in memory while read, and ASCII formats make
            a copy or two of it). 256 MiB is an ASCII STL of 1 million
            triangles; the mesh limits bind first for every format.
        max_triangles: most triangles (after fan-triangulating polygons and
            instancing) the checker processes; above this the file is refused
            before its triangles are allocated, naming this limit and
            ``--max-triangles``. Checking costs about 1 GB and 15 s per
            million triangles on a 2-core machine, so the default (500,000)
            keeps the worst file within it under 10 s and 1 GiB.
        max_vertices: most vertices a file may declare (or instance): three
            per triangle, so that an STL or a glTF triangle soup (three
            vertices of its own per triangle) of ``max_triangles`` is read;
            ``--max-triangles N`` raises it to ``3 N`` too.
        max_zip_entries: most entries a 3MF archive may list.
        max_uncompressed_bytes: most bytes extracted from one archive (zip)
            or gzip file in total, counted as they stream out (zip bombs are
            cut off here, whatever the headers claim).
        max_inflation_ratio: past the first ``free_inflation_bytes``, an
            archive or gzip file may inflate to at most this many times its
            own size (0: no ratio bound). Model XML and OBJ text deflate
            4-10:1 (the checker's own exports: 7:1); a bomb of spaces or
            zeros 1000:1. So a tiny file cannot hand the checker hundreds of
            megabytes of content to parse.
        free_inflation_bytes: bytes any archive may inflate to whatever its
            ratio (small files with padding or repetitive metadata).
        max_xml_bytes: largest single XML part read from an archive.
        max_xml_tree_bytes: largest XML parsed element by element into a
            tree (memory grows ~10x); the bulk vertex/triangle blocks of
            usual 3MF files take a streaming fast path and do not count.
        max_xml_elements: most elements (counted as ``<`` characters, an
            upper bound) an XML part parsed into a tree may hold; each costs
            ~100-400 bytes and a few microseconds, so 4-byte ``<a/>``
            elements would otherwise make 25x their size in memory.
        max_json_bytes: largest glTF JSON document parsed.
        max_json_values: most JSON values (counted as ``{``, ``[`` and ``,``
            characters, an upper bound) a glTF document may hold; each becomes
            a Python object of ~50-100 bytes.
        max_buffer_bytes: most bytes of glTF buffers read for one file in
            total: external ``.bin`` files and ``data:`` URIs (each URI is
            read once however many buffers name it; the GLB's own binary
            chunk is part of the file and counts under ``max_file_bytes``).
        max_texture_bytes: largest texture file read (an 8192 x 8192 PNG
            of a photograph is ~60-120 MB; the bytes and the decoded image
            are in memory together).
        max_texture_pixels: most pixels a texture may have; checked from the
            image header before any pixel is decoded (decompression bombs).
        max_total_texture_pixels: most pixels decoded over all of one file's
            textures: one 8192 x 8192 image (0.5-1 s and 256 MiB to decode
            on a 2-core machine), or 64 of 1024 x 1024; the header is checked
            against what is left before decoding, and a texture past it is
            reported ``texture_too_large``, not decoded.
        max_total_texture_bytes: most bytes read over all of one file's
            textures.
        max_textures: most distinct textures one file may reference.
        max_parts: most mesh parts (3MF objects/components/build items, glTF
            primitive instances, VRML shapes) instanced in total; a 3MF
            model part may also hold at most three bulk blocks (vertices,
            triangles, texture coordinates) per part. Each part costs its
            reader time of its own (a 3MF object ~0.3-0.5 ms, lib3mf's
            read included), so 10,000 parts sharing 500,000 triangles stay
            within the 10 s.
        max_node_visits: most scene-graph node visits (glTF nodes, VRML
            nodes) instancing may take; nodes shared between parents are
            priced before the walk, so a tree whose every node lists the
            next twice is refused by its count, not walked.
        max_nesting: deepest component/node/VRML nesting followed.
        max_xml_depth: deepest element nesting of a 3MF model part, found
            by a scan before the XML is parsed (a model nests about 6 deep;
            extensions add a few levels).
        max_vrml_tokens: most VRML tokens outside number arrays (node and
            field names, braces, strings; a few microseconds each).
        thin_wall_samples: surface points whose wall thickness is measured
            by an inward ray.
        max_ray_tests: cap on box and triangle tests of the thin-wall rays
            (the checks also scale it to the mesh); past it the estimate is
            marked partial rather than taking longer.
        max_pair_tests: cap on node-pair tests of the self-intersection
            search (the checks also scale it to the mesh: ~100 per triangle,
            twice what a sound mesh needs); past it the search samples and
            the check is marked partial. The candidate pairs given the exact
            test are capped at a quarter of the scaled budget (~25 per
            triangle; a sound mesh has ~8), so a pile of overlapping
            triangles ends in seconds.
        min_wall_mm: wall thickness to warn under when no printer is given
            (``None``: only report the estimate).
        thin_wall_error_fraction: the share of the sampled surface (by area)
            that may lie on walls under a printer profile's ``min_wall_mm``:
            over it, ``thin_walls`` is an error (not printable) whatever the
            profile's ``thin_policy``; at or under it, a warning with the
            place (isolated spots - a sharp edge, a spike the relief test did
            not clear - that a printer blunts). 0.5 %: a good export
            measures 0 and a plate under the minimum 90-100 %; 0.5 % is
            about 20 of the ~3,000-4,000 samples that measure a wall, so one
            or two stray samples never decide it (the measurements: the
            check README, "How much thin wall a part may have"). A minimum
            asked for without a printer (``min_wall_mm`` above, ``check
            --min-wall``) only warns.
        texture_dpi_fraction: warn when the texture's resolution on the
            model is below this fraction of the printer's dpi.
        solid_colour_density: faces whose texels per mm are below this
            fraction of the best-resolved faces' (95th percentile by area)
            are taken as solid-colour faces (an exporter maps plain walls to
            a tiny patch on purpose) and left out of the dpi median.
        plausible_size_mm: (smallest, largest) plausible largest extent of a
            model in millimetres; outside it a unit warning is given.
        uv_tolerance: how far outside [0, 1] a texture coordinate may stray
            (rounding in exporters) before it counts as outside.
        manifold3d_crosscheck: also build a manifold3d ``Manifold`` from a
            mesh the checker found closed and report its status (an
            independent second opinion on manifoldness; about 0.1 s per
            100,000 triangles, so off by default - the tests hold the
            checker's own topology to manifold3d's verdict instead).
        keep_texture_pixels: keep each decoded texture's pixels on its
            :class:`~saucerfab.check.meshdata.TextureInfo` (``pixels``), for
            callers that render the file (``saucerfab verify``); the checks
            themselves only need the sizes, so it is off by default.
    """

    max_file_bytes: int = 256 * MIB
    max_triangles: int = 500_000
    max_vertices: int = 1_500_000
    max_zip_entries: int = 10_000
    max_uncompressed_bytes: int = 256 * MIB
    max_inflation_ratio: float = 50.0
    free_inflation_bytes: int = 16 * MIB
    max_xml_bytes: int = 1 * GIB
    max_xml_tree_bytes: int = 128 * MIB
    max_xml_elements: int = 1_000_000
    max_json_bytes: int = 64 * MIB
    max_json_values: int = 2_000_000
    max_buffer_bytes: int = 256 * MIB
    max_texture_bytes: int = 128 * MIB
    max_texture_pixels: int = 8192 * 8192
    max_total_texture_pixels: int = 8192 * 8192
    max_total_texture_bytes: int = 256 * MIB
    max_textures: int = 64
    max_parts: int = 10_000
    max_node_visits: int = 400_000
    max_nesting: int = 32
    max_xml_depth: int = 64
    max_vrml_tokens: int = 1_000_000
    thin_wall_samples: int = 4096
    max_ray_tests: int = 20_000_000
    max_pair_tests: int = 500_000_000
    min_wall_mm: float | None = None
    thin_wall_error_fraction: float = 0.005
    texture_dpi_fraction: float = 0.5
    solid_colour_density: float = 0.1
    plausible_size_mm: tuple[float, float] = (5.0, 5000.0)
    uv_tolerance: float = 1e-4
    manifold3d_crosscheck: bool = False
    keep_texture_pixels: bool = False

    def with_(self, **changes: Any) -> Limits:
        """A copy with some limits changed (unknown names raise ``TypeError``)."""
        names = {f.name for f in fields(self)}
        bad = set(changes) - names
        if bad:
            raise TypeError(f"unknown limit(s) {sorted(bad)}; known: {sorted(names)}")
        return replace(self, **changes)

    def for_triangles(self, n: int) -> Limits:
        """A copy that reads meshes of up to ``n`` triangles (``saucerfab check --max-triangles N``).

        ``max_triangles`` becomes ``n``; the limits that grow with a mesh
        (``max_vertices`` to ``3 n``; the parts and the file, archive and
        buffer bytes in proportion) are raised to match, never lowered, so a
        file of ``n`` triangles in any format is read. It costs what such a mesh costs
        (:data:`COST_PER_MILLION_TRIANGLES`).
        """
        if n <= 0:
            raise ValueError(f"max_triangles must be positive, got {n}")
        scale = max(1.0, n / self.max_triangles)
        return replace(
            self,
            max_triangles=n,
            max_vertices=max(self.max_vertices, 3 * n),
            max_file_bytes=max(self.max_file_bytes, math.ceil(self.max_file_bytes * scale)),
            max_uncompressed_bytes=max(self.max_uncompressed_bytes, math.ceil(self.max_uncompressed_bytes * scale)),
            max_xml_bytes=max(self.max_xml_bytes, math.ceil(self.max_uncompressed_bytes * scale)),
            max_buffer_bytes=max(self.max_buffer_bytes, math.ceil(self.max_buffer_bytes * scale)),
            max_parts=max(self.max_parts, math.ceil(self.max_parts * scale)),
        )

    def raised_to(self, *, triangles: int = 0, texture_px: int = 0, file_bytes: int = 0,
                  inflated_bytes: int = 0) -> Limits:
        """A copy whose size limits hold files of these sizes; never lower than this one's.

        For files whose sizes are known from a source one trusts (saucerfab's
        own exports: :func:`saucerfab.workflow.export_limits`): ``triangles``
        raises the triangle, vertex and byte caps as :meth:`for_triangles`
        does; ``texture_px`` (a square texture's edge) the pixel caps;
        ``file_bytes`` (the largest file, mesh or texture) the file and
        texture byte caps; ``inflated_bytes`` (the most an archive inflates
        to) the archive caps, and the file caps too (a zipped OBJ's entries
        are checked as files).
        """
        lim = self.for_triangles(triangles) if triangles > self.max_triangles else self
        px = int(texture_px) ** 2
        biggest = max(file_bytes, inflated_bytes)
        return replace(
            lim,
            max_file_bytes=max(lim.max_file_bytes, biggest),
            max_texture_bytes=max(lim.max_texture_bytes, biggest),
            max_total_texture_bytes=max(lim.max_total_texture_bytes, biggest),
            max_texture_pixels=max(lim.max_texture_pixels, px),
            max_total_texture_pixels=max(lim.max_total_texture_pixels, px),
            max_uncompressed_bytes=max(lim.max_uncompressed_bytes, inflated_bytes),
            max_xml_bytes=max(lim.max_xml_bytes, inflated_bytes),
        )


DEFAULT_LIMITS = Limits()

#: what checking a mesh costs on the 2-core development machine (issue 16, ``benchmarks/RESULTS.md``, Checker budgets)
COST_PER_MILLION_TRIANGLES = "about 1 GB of memory and 15 s per million triangles"


def raise_hint(triangles: int | None = None) -> str:
    """What an ``over_check_limit`` refusal for size adds: the option that raises the cap, and its price.

    ``triangles``: the file's own count where the reader knows it (a sensible
    one is repeated as the option's value).
    """
    if triangles is not None and 0 < triangles <= 100_000_000:
        m = triangles / 1e6
        return (f"'saucerfab check --max-triangles {triangles}' checks it anyway, at {COST_PER_MILLION_TRIANGLES} "
                f"(here ~{max(m, 0.1):.1f} GB and ~{max(15 * m, 1):.0f} s)")
    return (f"'saucerfab check --max-triangles N' raises the mesh-size caps (triangles; vertices, parts and bytes "
            f"in proportion), at {COST_PER_MILLION_TRIANGLES}")


def inflated_bytes(paths: Sequence[Path]) -> int:
    """The most any of ``paths`` that is a zip (3MF, zipped OBJ) inflates to, by its own directory; 0 if none."""
    import zipfile

    most = 0
    for p in paths:
        try:
            if zipfile.is_zipfile(p):
                with zipfile.ZipFile(p) as zf:
                    most = max(most, sum(i.file_size for i in zf.infolist()))
        except (OSError, zipfile.BadZipFile):
            continue  # the check itself will say what is wrong with it
    return most
