"""Tests of saucerfab.files.formats: the one table of mesh formats, its lookups, and what its rows point to.

What each writer writes is ``tests/fabricate/test_export_writers.py``'s, what
each reader reads ``tests/check/``'s; here the table itself: names and
suffixes that identify one format each, :func:`lookup`, :func:`files_to_check`,
every lazy reference loading a function of the documented shape, and the
module staying light to import.
"""

from __future__ import annotations

import inspect
import subprocess
import sys

import pytest

from saucerfab.files.formats import (
    FORMATS,
    READERS,
    SUFFIXES,
    TABLE,
    WRITERS,
    files_to_check,
    labels,
    lookup,
)


@pytest.mark.parametrize(
    "name, key",
    [
        ("obj", "obj"),
        ("OBJ", "obj"),
        (".obj", "obj"),
        (" .3MF ", "3mf"),
        ("Glb", "glb"),
        ("vrml", "wrl"),  # the alias
        ("VRML", "wrl"),
        (".vrml", "wrl"),
        (".wrl", "wrl"),
        ("gltf", "gltf"),  # read, not written: lookup still knows it
        ("fbx", None),
        ("zip", None),
        ("", None),
        (".", None),
    ],
)
def test_lookup_by_key_alias_suffix_and_any_case(name: str, key: str | None) -> None:
    found = lookup(name)
    assert (found.key if found else None) == key
    if key is not None:
        assert found is TABLE[key]


def test_every_name_and_suffix_names_one_format() -> None:
    names = [n for f in TABLE.values() for n in (f.key, *f.aliases)]
    assert len(names) == len(set(names))
    for f in TABLE.values():
        for n in (f.key, *f.aliases, f.key.upper(), "." + f.key):
            assert lookup(n) is f, n
    suffixes = [s for f in TABLE.values() for s in f.suffixes]
    assert len(suffixes) == len(set(suffixes)), "a suffix claimed by two formats"
    assert all(s.startswith(".") and s == s.lower() for s in suffixes)
    # SUFFIXES holds every suffix of every read format, each to its own format (nothing overwritten)
    assert SUFFIXES == {s: f.key for f in READERS.values() for s in f.suffixes}
    assert len(SUFFIXES) == sum(len(f.suffixes) for f in READERS.values())
    assert SUFFIXES[".wrz"] == SUFFIXES[".vrml"] == "wrl"
    for f in TABLE.values():
        assert f.key == f.key.lower() and f.mesh_suffix == f.suffixes[0]


def test_no_format_s_magic_is_taken_for_another_s() -> None:
    """The checker sniffs the first bytes format by format: no magic may start with another format's."""
    magic = [(f.key, m) for f in TABLE.values() for m in f.magic]
    for key, m in magic:
        assert m, key
        for other, n in magic:
            if other != key:
                assert not m.startswith(n) and not n.startswith(m), (key, other)


def test_the_derived_tables_follow_the_table_order() -> None:
    # a new row joins these by itself: no list of keys here to keep up to date
    assert FORMATS == tuple(WRITERS) == tuple(k for k, f in TABLE.items() if f.writer is not None)
    assert "gltf" in TABLE and "gltf" not in FORMATS and {"3mf", "obj", "stl"} <= set(FORMATS)  # gltf is read only
    assert list(READERS) == [k for k, f in TABLE.items() if f.reader is not None]
    assert labels([TABLE["3mf"], TABLE["wrl"], TABLE["gltf"]]) == "3MF, VRML, glTF"


@pytest.mark.parametrize("key", list(WRITERS))
def test_every_writer_loads_with_the_writer_signature(key: str) -> None:
    writer = TABLE[key].load_writer()
    assert callable(writer) and writer.__name__.startswith("write_")
    params = list(inspect.signature(writer).parameters.values())
    assert [p.name for p in params] == ["mesh", "options"] and params[1].default is None


@pytest.mark.parametrize("key", list(READERS))
def test_every_reader_loads_with_the_reader_signature(key: str) -> None:
    fmt = TABLE[key]
    # called positionally as (path, data, limits, res=None): four parameters, the side files optional
    params = list(inspect.signature(fmt.load_reader()).parameters.values())
    assert len(params) == 4 and [p.default for p in params[:3]] == [inspect.Parameter.empty] * 3
    assert params[3].default is None
    path_reader = fmt.load_path_reader()
    if fmt.path_reader is None:
        assert path_reader is None
    else:  # (path, head, size, limits), any more optional
        params = list(inspect.signature(path_reader).parameters.values())
        assert [p.default is inspect.Parameter.empty for p in params] == [True] * 4 + [False] * (len(params) - 4)


def test_a_read_only_format_has_no_writer_to_load() -> None:
    with pytest.raises(KeyError, match="saucerfab does not write 'gltf'"):
        TABLE["gltf"].load_writer()


@pytest.mark.parametrize(
    "fmt, names, want",
    [
        ("obj", ["saucer.obj", "saucer.mtl", "saucer.png"], ["saucer.obj"]),
        ("obj", ["saucer.zip"], ["saucer.zip"]),  # FabOptions.obj_zip: the archive is checked
        ("obj", ["saucer.mtl", "saucer.png", "saucer.OBJ", "saucer.zip"], ["saucer.OBJ"]),  # the mesh file wins
        ("wrl", ["saucer.WRL", "saucer.png"], ["saucer.WRL"]),
        ("3mf", ["saucer.3mf"], ["saucer.3mf"]),
        ("stl", ["saucer.png"], []),
        ("glb", ["a.glb", "b.glb"], ["a.glb", "b.glb"]),
    ],
)
def test_files_to_check(fmt: str, names: list[str], want: list[str]) -> None:
    assert files_to_check(fmt, names) == want


def test_importing_the_table_imports_nothing_heavy() -> None:
    """``saucerfab check`` and ``--help`` read it and must start fast: no numpy, no writer or reader code."""
    code = (
        "import sys, saucerfab.files.formats\n"
        "print(sorted(m for m in sys.modules if m in ('numpy', 'torch', 'PIL') "
        "or m.startswith(('saucerfab.fabricate', 'saucerfab.check'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.strip() == "[]"
