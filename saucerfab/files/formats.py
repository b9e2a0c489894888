"""The mesh file formats saucerfab writes and checks: one row each.

Each format is named once here (meshio-style): its key (what ``--formats``,
printer profiles and check reports say), the other names it answers to, its
file suffixes, a one-line description, and its writer and its checker
reader as lazy ``"module:function"`` references, loaded only when used.
This module imports nothing heavy (no numpy, no torch, no fabricate code):
``saucerfab check`` and ``saucerfab --help`` read it and must start fast.

The contracts the references point to:

* writer ``(mesh: TexturedMesh, options: FabOptions | None = None) -> {file name: bytes}``:
  the files of the format, in memory, named after ``mesh.name``;
  :mod:`saucerfab.fabricate.registry` writes them.
* reader ``(path: Path, data: bytes, limits: Limits, res: Resources | None) -> MeshData``:
  ``data`` is the whole file, ``res`` finds side files (textures, material
  libraries) when the file was read from an archive; the result's
  ``format`` is the row's key. Raises ``ReadError`` for anything it cannot read.
* path reader (optional) ``(path: Path, head: bytes, size: int, limits: Limits) -> MeshData``:
  reads a file on disk itself, for formats whose large files are cheaper
  read in pieces (a binary STL's body goes straight into its array).
* magic: prefixes of the file's first bytes that identify the format
  whatever its name (:func:`saucerfab.check.readers.sniff`).

Adding a format: one row in :data:`TABLE`, its writer module
(``saucerfab/fabricate/export_<key>.py``) and, for the checker, its reader
module (``saucerfab/check/readers/<key>.py``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any


def _load(ref: str) -> Callable[..., Any]:
    """The function a ``"package.module:function"`` reference names (imported now)."""
    module, _, function = ref.partition(":")
    return getattr(importlib.import_module(module), function)  # type: ignore[no-any-return]


@dataclass(frozen=True)
class Format:
    """One mesh file format.

    Attributes:
        key: short name used on the command line, in printer profiles and in
            check reports (``3mf``, ``obj``, ...).
        label: how help texts name it (``3MF``, ``glTF``).
        description: one line for help texts.
        suffixes: file name suffixes (lower case, with the dot); the first is
            that of the file holding the mesh (what the checker reads).
        aliases: other names ``--formats`` accepts for it (``vrml``).
        writer: ``"module:function"`` of its writer, or None (read only).
        reader: ``"module:function"`` of the checker's reader, or None (not checked).
        path_reader: ``"module:function"`` of a reader that reads the file
            on disk itself, or None.
        magic: leading bytes that identify it.
    """

    key: str
    label: str
    description: str
    suffixes: tuple[str, ...]
    aliases: tuple[str, ...] = ()
    writer: str | None = None
    reader: str | None = None
    path_reader: str | None = None
    magic: tuple[bytes, ...] = ()

    @property
    def mesh_suffix(self) -> str:
        """Suffix of the file that holds the mesh (``.wrl``)."""
        return self.suffixes[0]

    def load_writer(self) -> Callable[..., dict[str, bytes]]:
        """The writer function (imports its module)."""
        if self.writer is None:
            raise KeyError(f"saucerfab does not write {self.key!r}")
        return _load(self.writer)

    def load_reader(self) -> Callable[..., Any]:
        """The checker's reader function (imports its module)."""
        if self.reader is None:
            raise KeyError(f"the checker does not read {self.key!r}")
        return _load(self.reader)

    def load_path_reader(self) -> Callable[..., Any] | None:
        """The reader that reads the file on disk itself, or None."""
        return None if self.path_reader is None else _load(self.path_reader)


_FAB = "saucerfab.fabricate"
_READ = "saucerfab.check.readers"

#: every format, by key, in the order help texts and ``known:`` lists show them
TABLE: dict[str, Format] = {f.key: f for f in (
    Format("3mf", "3MF", "3MF with texture (Materials extension)", (".3mf",),
           writer=f"{_FAB}.export_3mf:write_3mf",
           # a 3MF is a zip: the zip reader takes a 3MF package, or one mesh zipped with its side files
           reader=f"{_READ}:read_zip", magic=(b"PK\x03\x04", b"PK\x05\x06")),
    Format("obj", "OBJ", "OBJ + MTL + PNG (or one zip)", (".obj",),
           writer=f"{_FAB}.export_obj:write_obj", reader=f"{_READ}.obj:read_obj"),
    Format("glb", "GLB", "binary glTF 2.0, metres, PBR", (".glb",),
           writer=f"{_FAB}.export_glb:write_glb", reader=f"{_READ}.gltf:read_glb", magic=(b"glTF",)),
    Format("gltf", "glTF", "glTF 2.0 JSON with its buffers and images (checked, not written)", (".gltf",),
           reader=f"{_READ}:read_gltf_json"),
    Format("ply", "PLY", "PLY, per-vertex colour", (".ply",),
           writer=f"{_FAB}.export_ply:write_ply", reader=f"{_READ}.ply:read_ply", magic=(b"ply\n", b"ply\r")),
    Format("wrl", "VRML", "VRML 2.0 + PNG", (".wrl", ".vrml", ".wrz"), aliases=("vrml",),
           writer=f"{_FAB}.export_vrml:write_vrml", reader=f"{_READ}.vrml:read_vrml", magic=(b"#VRML",)),
    Format("stl", "STL", "binary STL, no colour", (".stl",),
           writer=f"{_FAB}.export_stl:write_stl", reader=f"{_READ}:read_stl_bytes",
           path_reader=f"{_READ}.stl:read_stl"),
)}

#: the formats saucerfab writes, by key (what ``--formats`` and printer profiles choose from)
WRITERS: dict[str, Format] = {k: f for k, f in TABLE.items() if f.writer is not None}
#: the formats the checker reads, by key
READERS: dict[str, Format] = {k: f for k, f in TABLE.items() if f.reader is not None}
#: keys of the written formats, in order
FORMATS: tuple[str, ...] = tuple(WRITERS)
#: file suffix -> key, for every format the checker reads
SUFFIXES: dict[str, str] = {s: f.key for f in READERS.values() for s in f.suffixes}

_NAMES: dict[str, str] = {n: f.key for f in TABLE.values() for n in (f.key, *f.aliases)}


def lookup(name: str) -> Format | None:
    """The format ``name`` names (any case, a leading dot, an alias such as ``vrml``), or None."""
    key = _NAMES.get(str(name).strip().lower().lstrip("."))
    return None if key is None else TABLE[key]


def labels(formats: Iterable[Format]) -> str:
    """``"3MF, OBJ, GLB"``: the formats as help texts list them."""
    return ", ".join(f.label for f in formats)


def files_to_check(fmt: str, names: Sequence[str]) -> list[str]:
    """Of the files one format's writer returned, those the checker reads.

    The file with the format's mesh suffix; failing that, a ``.zip`` (the
    OBJ written as one archive with its MTL and PNG, ``FabOptions.obj_zip``),
    whose mesh entry is checked as what a bureau unpacks.
    """
    suffix = TABLE[fmt].mesh_suffix
    return [n for n in names if n.lower().endswith(suffix)] or [n for n in names if n.lower().endswith(".zip")]
